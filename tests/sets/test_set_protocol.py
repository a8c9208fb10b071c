"""Every set type answers the eight protocol members consistently with random sampling."""

import numpy as np
import pytest

import casadi_cmpc as cm
from casadi_cmpc.sets.base import SetBase


def _box():
    return cm.Box([-1.0, -0.5], [1.5, 1.0])


def _paving():
    inner = np.array([[[-1.0, 0.0], [-1.0, 0.0]], [[0.0, 1.0], [-1.0, 0.5]]])
    boundary = np.array([[[1.0, 1.5], [0.0, 0.5]]])
    return cm.Paving(inner=inner, boundary=boundary)


def _polytope():
    th = np.linspace(0, 2 * np.pi, 8, endpoint=False)
    return cm.Polytope.from_vertices(np.c_[1.3 * np.cos(th), 0.8 * np.sin(th)] + [0.2, 0.1])


def _union():
    return cm.PolytopeUnion([cm.Polytope.from_box(cm.Box([-1, -1], [0.2, 0.3])),
                             cm.Polytope.from_vertices([[0, 0], [1.5, 0.2], [0.3, 1.2]])])


def _zonotope():
    return cm.Zonotope([0.1, -0.2], [[0.6, 0.3, -0.2], [0.1, 0.5, 0.4]])


def _setunion():
    inner = np.array([[[0.5, 1.5], [0.5, 1.0]], [[-1.5, -1.0], [-1.0, 1.0]]])
    return cm.SetUnion([_polytope(), cm.Paving(inner=inner), _zonotope()])


FACTORIES = {"Box": _box, "Paving": _paving, "Polytope": _polytope,
             "PolytopeUnion": _union, "Zonotope": _zonotope, "SetUnion": _setunion}


@pytest.fixture(params=sorted(FACTORIES))
def S(request):
    return FACTORIES[request.param]()


def test_every_set_type_is_covered():
    concrete = {c.__name__ for c in SetBase.__subclasses__()}
    assert concrete <= set(FACTORIES), f"untested set types: {concrete - set(FACTORIES)}"


def test_protocol_against_sampling(S):
    rng = np.random.default_rng(0)
    assert S.dim == 2 and not S.is_empty()
    B = S.bounding_box()
    pts = rng.uniform(-2.5, 2.5, (20000, 2))
    inside = S.contains(pts)
    assert inside.any() and (~inside).any()
    # every member point is in the bounding box and below the support function
    assert B.contains(pts[inside]).all()
    D = rng.normal(size=(16, 2))
    h = S.support(D)
    assert np.all((pts[inside] @ D.T) <= h + 1e-9)
    # the support is attained (up to sampling) by vertices, and vertices lie in the closure
    V = S.vertices()
    assert np.allclose((V @ D.T).max(axis=0), h, atol=1e-9)
    # boxes: "contains" must be a proof, "does not intersect" must be a proof
    c = rng.uniform(-2, 2, (400, 2))
    r = rng.uniform(0.01, 0.4, (400, 2))
    boxes = np.stack([c - r, c + r], axis=-1)
    cb = S.contains_box(boxes)
    ib = S.intersects_box(boxes)
    assert cb.shape == ib.shape == (400,)
    assert not np.any(cb & ~ib)
    for k in range(400):
        samples = c[k] + r[k] * rng.uniform(-1, 1, (200, 2))
        corners = c[k] + r[k] * np.array([[-1, -1], [-1, 1], [1, -1], [1, 1]])
        member = S.contains(np.vstack([samples, corners]))
        if cb[k]:
            assert member.all(), f"box {k} reported inside but has a point outside"
        if not ib[k]:
            assert not member.any(), f"box {k} reported disjoint but has a point inside"


def test_save_load_round_trip(S, tmp_path):
    for suffix in (".npz", ".json"):
        path = S.save(tmp_path / f"s{suffix}")
        T = type(S).load(path)
        assert type(T) is type(S)
        pts = np.random.default_rng(1).uniform(-2.5, 2.5, (3000, 2))
        assert np.array_equal(S.contains(pts), T.contains(pts))
        np.testing.assert_allclose(S.support(np.eye(2)), T.support(np.eye(2)), rtol=1e-12)


def test_plot_draws_something(S):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ax = S.plot()
    assert len(ax.patches) + len(ax.collections) + len(ax.lines) > 0
    plt.close("all")


def test_save_writes_exactly_the_given_name_or_refuses(S, tmp_path):
    for name in ("s.npz", "s.json", "S.NPZ"):
        path = S.save(tmp_path / name)
        assert path == tmp_path / name and path.is_file()
        assert type(S).load(path).dim == S.dim
    for name in ("box.txt", "box", "box.npz.bak"):
        with pytest.raises(ValueError, match=r"\.npz.*\.json"):
            S.save(tmp_path / name)
        assert not any(p.name.startswith(name) for p in tmp_path.iterdir())


def test_load_names_the_file_and_the_expected_format(S, tmp_path):
    txt = tmp_path / "notes.txt"
    txt.write_text("1 2 3\n")
    with pytest.raises(ValueError, match=r"notes\.txt.*\.npz"):
        type(S).load(txt)
    fake = tmp_path / "fake.npz"
    fake.write_text("1 2 3\n")
    with pytest.raises(ValueError, match=r"fake\.npz.*not a set file.*npz archive"):
        type(S).load(fake)
    other = tmp_path / "other.npz"
    np.savez(other, x=np.zeros(3))
    with pytest.raises(ValueError, match=r"other\.npz.*__meta__"):
        type(S).load(other)
    bad_json = tmp_path / "bad.json"
    bad_json.write_text("[1, 2")
    with pytest.raises(ValueError, match=r"bad\.json.*JSON document"):
        type(S).load(bad_json)
    with pytest.raises(FileNotFoundError, match="missing.npz"):
        type(S).load(tmp_path / "missing.npz")


def test_a_truncated_or_damaged_set_file_is_refused_with_a_value_error(tmp_path):
    """Every cut of a saved archive, and bytes flipped inside it, raise the documented
    ValueError (not zipfile's or zlib's own errors)."""
    import casadi_cmpc as cm

    P = cm.Paving(inner=np.random.default_rng(0).uniform(0, 1, (500, 2, 2)).cumsum(-1),
                  domain=cm.Box([0, 0], [3, 3]))
    path = tmp_path / "p.npz"
    P.save(path)
    data = path.read_bytes()
    for cut in sorted({2, 10, 100, len(data) // 3, len(data) // 2, len(data) - 30,
                       len(data) - 1}):
        bad = tmp_path / f"cut{cut}.npz"
        bad.write_bytes(data[:cut])
        with pytest.raises(ValueError, match="not a set file"):
            cm.Paving.load(bad)
    flipped = bytearray(data)
    for k in range(200, len(flipped) - 200, 997):
        flipped[k] ^= 0xFF
    (tmp_path / "flip.npz").write_bytes(bytes(flipped))
    try:
        Q = cm.Paving.load(tmp_path / "flip.npz")
    except ValueError:
        pass
    else:  # a flip in stored bytes that zip does not check must still give a Paving
        assert isinstance(Q, cm.Paving)
