"""One polytope proven inside a union of boxes (thesis Alg 6.2 and Alg 6.5)."""

import doctest

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import casadi_cmpc as cm
from casadi_cmpc.control import polytopic

METHODS = ["separating", "scaling"]

L_SHAPE = np.array([[[0, 2], [0, 1]], [[0, 1], [1, 2]]], dtype=float)  # area 3
RING = np.array([[[0, 5], [0, 1]], [[0, 5], [4, 5]], [[0, 1], [1, 4]], [[4, 5], [1, 4]]],
                dtype=float)  # area 16, hole [1, 4]^2
CORNER_3D = np.array([[[0, 2], [0, 1], [0, 1]], [[0, 1], [0, 2], [0, 1]],
                      [[0, 1], [0, 1], [0, 2]]], dtype=float)  # volume 4


def in_union(X, boxes, tol=0.0):
    """Exact (tol=0) membership of the points X (K, n) in the union of the boxes."""
    lo, hi = boxes[None, :, :, 0] - tol, boxes[None, :, :, 1] + tol
    Xe = X[:, None, :]
    return ((Xe >= lo) & (Xe <= hi)).all(axis=-1).any(axis=-1)


def points_of(P, rng, k=2000):
    """Points of P: uniform ones (strictly inside by 1e-12, beyond the rounding of A x)
    and points near the boundary (vertices pulled toward an interior point by 1e-9)."""
    bb = P.bounding_box()
    X = rng.uniform(bb.lo, bb.hi, size=(k, P.dim))
    X = X[P.contains(X, tol=-1e-12)]
    V = P.vertices()
    c = V.mean(axis=0)
    t = rng.uniform(0.0, 1.0 - 1e-9, size=(k, 1))
    W = rng.dirichlet(np.ones(V.shape[0]), size=k) @ V
    near = c + (1.0 - 1e-9) * (V - c)
    return np.vstack([X, c + t * (W - c), near, c[None]])


def check_sound(P, cert, boxes, rng):
    assert cert.label == "proved" and cert.proved is True
    assert P.is_full_dimensional()
    V = P.vertices()  # floating-point vertex enumeration: up to its rounding
    assert in_union(V, boxes, tol=1e-9).all()
    X = points_of(P, rng)
    assert X.shape[0] > 100
    assert in_union(X, boxes).all()
    # the proof is reproducible on the returned rows
    assert P.is_subset(cm.PolytopeUnion([cm.Polytope.from_box(b) for b in boxes]))


# ------------------------------------------------------------- (a) 2-D shapes
@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("name, boxes, area", [("L", L_SHAPE, 3.0), ("ring", RING, 16.0)])
def test_l_and_ring_are_sound(name, boxes, area, method):
    rng = np.random.default_rng(0)
    P, cert = cm.inner_polytope(boxes, method)
    check_sound(P, cert, boxes, rng)
    ratio = P.volume() / area
    assert 0.0 < ratio <= 1.0
    d = cert.details
    assert d["method"] == method and 0.0 < d["alpha"] <= 1.0 and d["n_proofs"] >= 1
    if method == "separating":
        # the best convex subsets: the triangle x + y <= 2 (or a 2x1 bar) in the L,
        # a 5x1 bar in the ring
        assert ratio >= (0.66 if name == "L" else 0.31)


def test_result_unpacks_and_names():
    res = cm.inner_polytope(L_SHAPE)
    assert isinstance(res, cm.InnerPolytope)
    P, cert = res
    assert P is res.polytope and cert is res.certificate
    assert isinstance(cert, cm.Certificate)
    import casadi_cmpc.control as control

    assert "inner_polytope" in control.__all__ and "inner_polytope" in cm.__all__


def test_given_center_and_thesis_order():
    rng = np.random.default_rng(1)
    for method in METHODS:
        P, cert = cm.inner_polytope(L_SHAPE, method, center=[1.5, 0.5], order="given")
        check_sound(P, cert, L_SHAPE, rng)
        assert np.allclose(cert.details["center"], [1.5, 0.5])
        assert cert.details["center_rule"] == "given"


# ---------------------------------------------- (b) a union that is a box
PINWHEEL = np.array([[[0, 2], [0, 1]], [[2, 3], [0, 2]], [[1, 3], [2, 3]], [[0, 1], [1, 3]],
                     [[1, 2], [1, 2]]], dtype=float)  # [0, 3]^2, no two boxes mergeable


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("name", ["grid", "pinwheel"])
def test_union_that_is_a_box_is_nearly_recovered(name, method):
    if name == "grid":  # [0, 3] x [0, 2] as a 3 x 2 grid of cells (merged to one box)
        cells = np.array([[[i, i + 1], [j, j + 1]] for i in range(3) for j in range(2)],
                         float)
    else:
        cells = PINWHEEL
    area = np.prod(cells[..., 1].max(axis=0) - cells[..., 0].min(axis=0))
    rng = np.random.default_rng(2)
    P, cert = cm.inner_polytope(cells, method)
    check_sound(P, cert, cells, rng)
    assert P.volume() / area >= 0.9


def test_merging_keeps_the_union():
    rng = np.random.default_rng(7)
    for _ in range(20):
        n = int(rng.integers(1, 4))
        k = 4
        mask = rng.random((k,) * n) < 0.5
        idx = np.argwhere(mask)
        if idx.shape[0] == 0:
            continue
        cells = np.stack([idx * 0.1, idx * 0.1 + 0.1], axis=-1)
        merged = polytopic._merge_boxes(cells.copy())
        assert merged.shape[0] <= cells.shape[0]
        X = rng.uniform(-0.05, 0.45, size=(4000, n))
        X = np.vstack([X, cells[..., 0], cells[..., 1]])  # corners: boundary cases
        assert np.array_equal(in_union(X, cells), in_union(X, merged))


@pytest.mark.parametrize("method", METHODS)
def test_single_box_and_box_objects(method):
    B = cm.Box([-1, 2], [3, 2.5])
    for data in (B, [B], B.as_array(), B.as_array()[None]):
        P, cert = cm.inner_polytope(data, method)
        assert cert.proved
        assert P.volume() / B.volume() >= 0.9


# ----------------------------------------------------------------- (c) n = 3
@pytest.mark.parametrize("method", METHODS)
def test_three_dimensional_union(method):
    rng = np.random.default_rng(3)
    P, cert = cm.inner_polytope(CORNER_3D, method)
    check_sound(P, cert, CORNER_3D, rng)
    assert cert.details["dim"] == 3
    assert P.volume() > 0.05 * 4.0


@pytest.mark.parametrize("method", METHODS)
def test_one_dimensional_union(method):
    boxes = np.array([[[0, 1]], [[1, 3]], [[4, 5]]], dtype=float)
    P, cert = cm.inner_polytope(boxes, method)
    check_sound(P, cert, boxes, np.random.default_rng(6))
    if method == "separating":
        assert P.volume() >= 2.99  # the interval [0, 3]


# ------------------------------------------------- other kinds of union
def test_paving_uses_its_inner_boxes():
    pav = cm.Paving(inner=L_SHAPE, boundary=np.array([[[1, 2], [1, 2]]], float))
    P, cert = cm.inner_polytope(pav)
    # the boundary box would make the union the square [0, 2]^2; the inner boxes are an L
    check_sound(P, cert, L_SHAPE, np.random.default_rng(4))
    assert "Paving" in cert.details["input"]


@pytest.mark.parametrize("method", METHODS)
def test_union_of_polytopes(method):
    # two triangles meeting along an edge (a square) and one further away (a bowtie-free
    # union that is not convex)
    T1 = cm.Polytope.from_vertices([[0, 0], [2, 0], [0, 2]])
    T2 = cm.Polytope.from_vertices([[2, 0], [2, 2], [0, 2]])
    T3 = cm.Polytope.from_vertices([[2, 0], [3, 0], [2, 1]])
    U = cm.PolytopeUnion([T1, T2, T3])
    P, cert = cm.inner_polytope(U, method)
    assert cert.proved
    assert P.is_subset(U)
    rng = np.random.default_rng(5)
    X = points_of(P, rng)
    inside = np.zeros(X.shape[0], dtype=bool)
    for T in (T1, T2, T3):
        inside |= T.contains(X, tol=1e-12)
    assert inside.all()
    assert P.volume() >= 0.9 * 4.0 * (1.0 if method == "separating" else 0.5)
    P2, cert2 = cm.inner_polytope([T1, T2, T3], method)
    assert cert2.proved and np.isclose(P2.volume(), P.volume(), rtol=1e-6)


# ------------------------------------------------------- undecided outcomes
def test_nothing_proven_gives_empty_polytope_undecided(monkeypatch):
    monkeypatch.setattr(polytopic._Prover, "__call__", lambda self, P: False)
    for method in METHODS:
        P, cert = cm.inner_polytope(L_SHAPE, method)
        assert P.is_empty()
        assert cert.label == "undecided" and cert.proved is None
        assert "no candidate" in cert.reason


def test_too_many_pieces_is_undecided():
    cells = np.array([[[i, i + 1], [j, j + 1]] for i in range(4) for j in range(4)
                      if (i + j) % 2 == 0], float)  # a chessboard: many pieces
    P, cert = cm.inner_polytope(cells, "separating", max_pieces=1)
    assert P.is_empty() and cert.label == "undecided" and cert.proved is None
    assert "max_pieces" in cert.reason


# --------------------------------------- (d) property test: random grid unions
@settings(max_examples=12)
@given(k=st.integers(2, 4), bits=st.lists(st.booleans(), min_size=16, max_size=16),
       method=st.sampled_from(METHODS), seed=st.integers(0, 2 ** 16))
def test_random_grid_unions_are_sound(k, bits, method, seed):
    mask = np.array(bits[:k * k], dtype=bool).reshape(k, k)
    if not mask.any():
        mask[0, 0] = True
    cells = np.array([[[i, i + 1], [j, j + 1]] for i in range(k) for j in range(k)
                      if mask[i, j]], float)
    cells = 0.5 * cells - 0.3  # not on the integer grid
    P, cert = cm.inner_polytope(cells, method)
    if P.is_empty():
        assert cert.proved is None and cert.label == "undecided"
        return
    check_sound(P, cert, cells, np.random.default_rng(seed))


# ------------------------------------------------------------ (e) bad input
@pytest.mark.parametrize("data, exc", [
    (np.zeros((2, 2, 3)), cm.DimensionError),                     # not (.., 2)
    (np.zeros(4), cm.DimensionError),                             # 1-D
    (np.zeros((0, 2, 2)), cm.EmptySetError),                      # no box
    ([], cm.EmptySetError),                                       # empty list
    (np.array([[[1.0, 0.0], [0, 1]]]), cm.EmptySetError),         # lo > hi
    (np.array([[[0.0, np.nan], [0, 1]]]), cm.InvalidBoundsError),  # NaN
    (np.array([[[0.0, np.inf], [0, 1]]]), cm.UnboundedSetError),   # infinite bound
    (np.array([[[0.0, 0.0], [0, 1]]]), cm.EmptySetError),         # only flat boxes
    (cm.Paving(inner=np.zeros((0, 2, 2))), cm.EmptySetError),     # no inner box
    (cm.PolytopeUnion([], dim=2), cm.EmptySetError),              # empty union
    (cm.PolytopeUnion([cm.Polytope([[1.0, 0.0]], [1.0])]), cm.UnboundedSetError),
])
def test_bad_unions_are_refused(data, exc):
    with pytest.raises(exc):
        cm.inner_polytope(data)


def test_bad_options_are_refused():
    with pytest.raises(ValueError, match="method"):
        cm.inner_polytope(L_SHAPE, "union")
    with pytest.raises(ValueError, match="order"):
        cm.inner_polytope(L_SHAPE, order="random")
    for eps in (0.0, 1.0, -1e-3):
        with pytest.raises(ValueError, match="eps"):
            cm.inner_polytope(L_SHAPE, "scaling", eps=eps)
    with pytest.raises(ValueError, match="margin"):
        cm.inner_polytope(L_SHAPE, margin=0.0)
    with pytest.raises(ValueError, match="interior"):
        cm.inner_polytope(L_SHAPE, center=[1.5, 1.5])  # in the hull, not in the union
    with pytest.raises(ValueError, match="interior"):
        cm.inner_polytope(L_SHAPE, center=[1.0, 1.0 + 1e-3])  # on the boundary
    with pytest.raises(cm.DimensionError, match="center"):
        cm.inner_polytope(L_SHAPE, center=[0.5, 0.5, 0.5])
    with pytest.raises(cm.DimensionError):
        cm.inner_polytope([cm.Polytope.from_box(cm.Box([0, 0], [1, 1])),
                           cm.Polytope.from_box(cm.Box([0], [1]))])


def test_docstring_example():
    result = doctest.testmod(polytopic, optionflags=doctest.NORMALIZE_WHITESPACE)
    assert result.attempted > 0 and result.failed == 0
