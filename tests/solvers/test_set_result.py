"""The set-valued result (``cm.SetResult``), the ``outer`` -> ``outside`` rename and Model
inputs of ``cm.sivia`` / ``cm.quantified_sivia`` (issue 10, item 7)."""

from __future__ import annotations

import copy
import dataclasses
import json
import pickle
import re
import warnings

import casadi as ca
import numpy as np
import pytest

import casadi_cmpc as cm
from casadi_cmpc.solvers.engine import Status
from casadi_cmpc.solvers.quantified import quantified_sivia
from casadi_cmpc.solvers.result import Result, SetResult
from casadi_cmpc.solvers.zonotope_sivia import ZonotopePaving, inner_zonotopes, zonotope_sivia

DISK_X0 = cm.Box([-2, -2], [2, 2])
DISK_Y = cm.Box([0], [1])


def _disk():
    p = ca.SX.sym("p", 2)
    return ca.Function("disk", [p], [p[0] ** 2 + p[1] ** 2])


@pytest.fixture(scope="module")
def disk():
    return cm.sivia(_disk(), DISK_X0, DISK_Y, 0.1, progress=False)


@pytest.fixture(scope="module")
def scalar_model():
    """x+ = x + u + w: Σ = {x : ∀w ∃u : x+ in [-1, 1]} = [-1.5, 1.5]."""
    x, u, w = ca.SX.sym("x"), ca.SX.sym("u"), ca.SX.sym("w")
    return cm.Model(x=x, u=u, w=w, f=x + u + w, X=cm.Box([-4], [4]), U=cm.Box([-1], [1]),
                    W=cm.Box([-0.5], [0.5]), name="scalar")


def _same(P, Q):
    for view in ("inner", "boundary", "outside"):
        np.testing.assert_array_equal(getattr(P, view), getattr(Q, view), err_msg=view)
    assert P.n_discarded == Q.n_discarded and P.domain == Q.domain


# ------------------------------------------------------------------- the result type
def test_set_result_is_exported_and_built_on_result():
    assert cm.SetResult is SetResult and "SetResult" in cm.__all__
    assert "SetResult" in cm.solvers.__all__
    assert issubclass(SetResult, Result) and issubclass(cm.OneStepSet, SetResult)
    names = {f.name for f in dataclasses.fields(SetResult)}
    assert names == {"success", "status", "message", "method", "nit", "n_boxes", "elapsed",
                     "paving", "n_pairs", "history"}


def test_every_set_solver_returns_a_set_result(disk, scalar_model):
    q = quantified_sivia(scalar_model, Y=cm.Box([-1], [1]), eps=0.1, progress=False)
    z = inner_zonotopes(cm.Polytope.from_vertices([[0, 0], [2, 0], [1, 2]]), 0.2)
    for res, paving_type in ((disk, cm.Paving), (q, cm.Paving), (z, ZonotopePaving)):
        assert type(res) is SetResult and type(res.paving) is paving_type
        assert res.status == Status.PROVED and res.success
        assert res.nit == res.levels > 0 and res.n_boxes == res.n_classified > 0
        assert isinstance(res.message, str) and res.elapsed >= 0
        assert len(res.history) == res.nit
    assert disk.method.startswith("sivia") and disk.n_pairs == 0
    assert q.method == "alg5.2" and q.n_pairs > 0
    assert z.method.startswith("inner zonotopes")


def test_fields_are_frozen(disk):
    for name, value in (("status", Status.BUDGET), ("paving", None), ("n_pairs", 3),
                        ("inner", np.zeros((0, 2, 2)))):
        with pytest.raises(dataclasses.FrozenInstanceError):
            setattr(disk, name, value)


def test_forwards_to_its_paving(disk, tmp_path):
    P = disk.paving
    assert disk.inner is P.inner and disk.boundary is P.boundary
    assert disk.outside is P.outside and disk.domain == DISK_X0
    assert disk.n_discarded == P.n_discarded == len(P.outside) > 0
    assert disk.n_inner == P.n_inner and disk.n_boundary == P.n_boundary
    assert disk.volume() == P.volume() and disk.volume("inner") == P.volume("inner")
    assert disk.view_boxes("outside") is P.outside
    assert disk.contains([0.0, 0.0], view="inner") and not disk.contains([1.9, 1.9])
    np.testing.assert_array_equal(disk.contains_box(P.inner), True)
    assert disk.bounding_box() == P.bounding_box()
    assert len(disk) == len(P) == P.n_boxes and bool(disk)
    assert "volume" in dir(disk) and "paving" in dir(disk)
    with pytest.raises(AttributeError, match="nor has its paving, a Paving"):
        disk.no_such_member  # noqa: B018
    assert not hasattr(disk, "__array__")  # protocols are not forwarded
    # saving saves the paving
    Q = cm.Paving.load(disk.save(tmp_path / "disk.npz"))
    _same(P, Q)
    import matplotlib.pyplot as plt

    ax = disk.plot(show_outer=True)
    assert len(ax.collections) == 3
    plt.close("all")


def test_counts_as_its_paving_for_isinstance_and_set_operations(disk):
    assert isinstance(disk, cm.Paving) and isinstance(disk, cm.SetBase)
    assert not isinstance(disk, cm.Box) and not isinstance(disk, ZonotopePaving)
    assert not issubclass(SetResult, cm.Paving)
    z = inner_zonotopes(cm.Polytope.from_vertices([[0, 0], [2, 0], [1, 2]]), 0.2)
    assert isinstance(z, ZonotopePaving) and not isinstance(z, cm.Paving)
    for U in (disk | disk, disk.paving | disk, disk | disk.paving, disk.paving.union(disk)):
        assert type(U) is cm.Paving and U.n_inner == 2 * disk.n_inner
    assert (cm.Box([5, 5], [6, 6]) | disk).n_inner == disk.n_inner + 1
    assert type(cm.SetUnion([disk]).members[0]) is cm.Paving
    # a result as the target of another inversion (a set like any other)
    x = ca.SX.sym("x", 2)
    again = cm.sivia(ca.Function("id", [x], [x]), DISK_X0, disk, 0.5, progress=False)
    assert again.n_inner > 0


def test_repr_names_the_views_and_the_effort(disk, scalar_model):
    pattern = (r"SetResult\(status=PROVED, inner=(\d+), boundary=(\d+), outside=(\d+), "
               r"nit=(\d+), n_boxes=(\d+), elapsed=[0-9.e+-]+\)")
    m = re.fullmatch(pattern, repr(disk))
    assert m, repr(disk)
    assert [int(g) for g in m.groups()] == [disk.n_inner, disk.n_boundary,
                                             len(disk.outside), disk.nit, disk.n_boxes]
    z = zonotope_sivia(None, cm.Box([-1, -1], [1, 1]), cm.Box([-0.4, -2], [0.4, 2]), 0.1)
    assert re.fullmatch(r"SetResult\(status=PROVED, inner=\d+, boundary=\d+, outside=\d+, "
                        r"nit=\d+, n_boxes=\d+, elapsed=.*\)", repr(z))
    assert repr(z.paving).startswith("ZonotopePaving(dim=2, inner=")
    assert "outside=" in repr(disk.paving) and "outer=" not in repr(disk.paving)


def test_construction_is_checked_and_a_result_as_paving_is_unwrapped(disk):
    base = {"status": Status.PROVED, "message": "m", "method": "demo", "nit": 1,
            "n_boxes": 1, "elapsed": 0.0}
    with pytest.raises(TypeError, match="paving must be a Paving or ZonotopePaving"):
        SetResult(paving=np.zeros((1, 2, 2)), **base)
    with pytest.raises(ValueError, match="n_pairs must be >= 0"):
        SetResult(paving=disk.paving, n_pairs=-1, **base)
    with pytest.raises(TypeError, match="n_pairs must be an integer"):
        SetResult(paving=disk.paving, n_pairs=1.5, **base)
    r = SetResult(paving=disk, **base)
    assert r.paving is disk.paving and r.n_pairs == 0 and r.history == []


def test_copies_and_pickles(disk):
    for r in (copy.copy(disk), copy.deepcopy(disk), pickle.loads(pickle.dumps(disk))):
        assert type(r) is SetResult and r.status == disk.status
        _same(r.paving, disk.paving)


def test_bool_and_len_follow_the_paving():
    x = ca.SX.sym("x")
    none = cm.sivia(ca.Function("sq", [x], [x ** 2]), cm.Box([-1], [1]), cm.Box([5], [6]),
                    0.1, progress=False)
    assert len(none) == 0 and not none and none.success and none.n_discarded > 0


def test_one_step_set_is_a_set_result_holding_a_paving(scalar_model):
    T = cm.Box([-1], [1])
    for method in ("general", "modal"):
        res = cm.one_step_set(scalar_model, T, 0.1, robust=True, method=method,
                              progress=False)
        assert isinstance(res, SetResult) and type(res.paving) is cm.Paving
        assert res.outside is res.paving.outside and res.inner is res.paving.inner
        assert res.levels == res.nit and res.n_classified == res.n_boxes
        I = res.paving.inner
        assert I[:, 0, 0].min() >= -1.5 and I[:, 0, 1].max() <= 1.5 and len(I)


# -------------------------------------------------------------- outer -> outside
def test_paving_outer_is_a_deprecated_alias():
    box = cm.Box([2, 0], [3, 1])
    with pytest.warns(DeprecationWarning, match="outside") as rec:
        old = cm.Paving(inner=[cm.Box([0, 0], [1, 1])], outer=[box])
    assert rec[0].filename == __file__  # points at the caller
    new = cm.Paving(inner=[cm.Box([0, 0], [1, 1])], outside=[box])
    _same(old, new)
    with pytest.warns(DeprecationWarning, match="Paving.outer is deprecated") as rec:
        arr = new.outer
    assert rec[0].filename == __file__
    assert arr is new.outside
    with pytest.warns(DeprecationWarning, match="n_outer"):
        assert new.n_outer == new.n_outside == 1
    with pytest.raises(TypeError, match="both outside= and"), \
            pytest.warns(DeprecationWarning):
        cm.Paving(outside=[box], outer=[box])
    # positional order unchanged: (inner, boundary, outside, domain)
    _same(cm.Paving([cm.Box([0, 0], [1, 1])], None, [box]), new)


def test_views_keep_their_names():
    P = cm.Paving(inner=[cm.Box([0, 0], [1, 1])], boundary=[cm.Box([1, 0], [2, 1])],
                  outside=[cm.Box([2, 0], [4, 1])])
    with warnings.catch_warnings():
        warnings.simplefilter("error", DeprecationWarning)
        assert P.view_boxes("outer") is P.boxes and P.view_boxes("outside") is P.outside
        assert (P.volume("outer"), P.volume("outside"), P.volume("inner")) == (2.0, 2.0, 1.0)
        assert P.contains([3.0, 0.5], view="outside") and not P.contains([3.0, 0.5])


def test_set_result_outer_is_a_deprecated_alias(disk):
    with pytest.warns(DeprecationWarning, match="SetResult.outer is deprecated") as rec:
        arr = disk.outer
    assert len(rec) == 1 and rec[0].filename == __file__
    assert arr is disk.outside is disk.paving.outside


def test_zonotope_paving_outer_is_a_deprecated_alias():
    res = zonotope_sivia(None, cm.Box([-1, -1], [1, 1]), cm.Box([-0.4, -2], [0.4, 2]), 0.1)
    assert len(res.outside) > 0
    with pytest.warns(DeprecationWarning, match="outside"):
        assert res.outer is res.outside
    with pytest.warns(DeprecationWarning, match="ZonotopePaving.outer"):
        assert res.paving.outer is res.paving.outside
    with pytest.warns(DeprecationWarning, match="view 'outer'"):
        assert res.volume("outer") == res.volume("outside") > 0
    with pytest.warns(DeprecationWarning, match="keyword outer="):
        Z = ZonotopePaving(res.inner, res.boundary, domain=res.domain, outer=res.outside)
    assert Z.outside is res.outside and Z.n_discarded == len(res.outside)


def test_plot_key_outer_is_a_deprecated_alias():
    import matplotlib.pyplot as plt

    P = cm.Paving(inner=[cm.Box([0, 0], [1, 1])], outside=[cm.Box([2, 0], [4, 1])])
    with pytest.warns(DeprecationWarning, match="key 'outer'"):
        ax = P.plot(show_outer=True, colors={"outer": "red"}, labels={"outer": "excluded"})
    assert "excluded" in [t.get_text() for t in ax.get_legend().get_texts()]
    plt.close("all")


@pytest.mark.parametrize("suffix", [".json", ".npz"])
def test_files_written_before_the_rename_still_load(tmp_path, suffix):
    P = cm.Paving(inner=[cm.Box([0, 0], [1, 1])], outside=[cm.Box([2, 0], [4, 1])],
                  domain=cm.Box([0, 0], [4, 1]))
    path = P.save(tmp_path / f"p{suffix}")
    if suffix == ".json":
        doc = json.loads(path.read_text())
        assert "outside" in doc["state"]
        doc["state"]["outer"] = doc["state"].pop("outside")
        path.write_text(json.dumps(doc))
    else:
        with np.load(path) as data:
            arrays = {k: data[k] for k in data.files}
        arrays["a_outer"] = arrays.pop("a_outside")
        with open(path, "wb") as fh:
            np.savez(fh, **arrays)
    with warnings.catch_warnings():
        warnings.simplefilter("error", DeprecationWarning)
        _same(cm.Paving.load(path), P)


# ------------------------------------------------------------------ Model inputs
def test_sivia_of_a_model_without_disturbance_equals_its_function():
    ex = cm.models.load("cannon_001")
    cl = ex.model.closed_loop(ex.local_law)
    assert cl.m == 0 and cl.l == 0
    f = ca.Function("succ", [cl.x], [cl.f])
    Y = cm.Box([-1, -1], [1, 1])
    ref = cm.sivia(f, cl.X, Y, 0.1, progress=False)
    for res in (cm.sivia(cl, Y=Y, eps=0.1, progress=False),
                cm.sivia(cl, cl.X, Y, 0.1, progress=False),
                cm.sivia(cl, None, Y, 0.1, progress=False)):
        _same(res.paving, ref.paving)
    X0 = cm.Box([0, -1], [1, 1])
    _same(cm.sivia(cl, X0, Y, 0.1, kind="centered", progress=False).paving,
          cm.sivia(f, X0, Y, 0.1, kind="centered", progress=False).paving)
    _same(cm.sivia(cl, Y=Y, eps=0.1, contract=True, progress=False).paving,
          cm.sivia(f, cl.X, Y, 0.1, contract=True, progress=False).paving)


def _additive_model(n=1):
    x, w = ca.SX.sym("x", n), ca.SX.sym("w", n)
    return cm.Model(x=x, u=None, w=w, f=0.5 * x + w, X=cm.Box([-4] * n, [4] * n),
                    W=cm.Box([-0.25] * n, [0.25] * n), name="additive")


def test_sivia_of_a_model_with_disturbance_is_for_every_w():
    """x+ = x/2 + w, w in [-1/4, 1/4], Y = [-1, 1]: every w works iff |x| <= 3/2; no w
    works iff |x| > 5/2; in between W is split and the boxes stay undecided."""
    model = _additive_model()
    Y = cm.Box([-1], [1])
    res = cm.sivia(model, Y=Y, eps=0.05, progress=False)
    I, O, B = res.inner, res.outside, res.boundary
    assert res.domain == model.X and res.paving.dim == 1
    assert I[:, 0, 0].min() >= -1.5 and I[:, 0, 1].max() <= 1.5
    assert res.volume("inner") >= 3.0 - 2 * 0.05
    assert (np.abs(O[:, 0, :]) >= 2.5).all() and res.volume("outside") >= 3.0 - 2 * 0.05
    assert res.volume("inner") + res.volume("boundary") + res.volume("outside") == \
        pytest.approx(8.0, rel=1e-12)  # the x-boxes tile X: W is never bisected
    assert res.contains([2.0], view="boundary") and len(B)
    # a narrower disturbance box proves more
    narrow = cm.sivia(model, Y=Y, eps=0.05, W=cm.Box([-0.05], [0.05]), progress=False)
    assert narrow.volume("inner") > res.volume("inner")
    # relative widths: W does not count
    rel = cm.sivia(model, Y=Y, eps=0.05 / 8, relative=True, progress=False)
    _same(rel.paving, res.paving)


def test_sivia_model_errors():
    ex = cm.models.load("cannon_001")
    with pytest.raises(cm.ModelError, match=r"closed_loop.*quantified_sivia"):
        cm.sivia(ex.model, Y=cm.Box([-1, -1], [1, 1]), eps=0.1)
    with pytest.raises(cm.ModelError, match="no disturbance"):
        cm.sivia(ex.model.closed_loop(ex.local_law), Y=cm.Box([-1, -1], [1, 1]), eps=0.1,
                 W=cm.Box([0], [1]))
    with pytest.raises(ValueError, match="contract=True"):
        cm.sivia(_additive_model(), Y=cm.Box([-1], [1]), eps=0.1, contract=True)
    with pytest.raises(cm.UnboundedSetError):
        cm.sivia(_additive_model(), Y=cm.Box([-1], [1]), eps=0.1,
                 W=cm.Box([0], [np.inf]))
    f = _disk()
    with pytest.raises(cm.ModelError, match="W is only used with a Model"):
        cm.sivia(f, DISK_X0, DISK_Y, 0.1, W=cm.Box([0], [1]))
    with pytest.raises(TypeError, match="X0"):
        cm.sivia(f, Y=DISK_Y, eps=0.1)
    with pytest.raises(TypeError, match="target Y"):
        cm.sivia(f, DISK_X0)
    with pytest.raises(ValueError, match="eps must be a positive number"):
        cm.sivia(f, DISK_X0, DISK_Y)


def test_quantified_sivia_of_a_model_equals_its_function(scalar_model):
    m = scalar_model
    Y = cm.Box([-1], [1])
    f = ca.Function("f", [m.x, m.u, m.w], [m.f])
    ref = quantified_sivia(f, m.X, m.U, m.W, Y, 0.05, progress=False)
    res = quantified_sivia(m, Y=Y, eps=0.05, progress=False)
    _same(res.paving, ref.paving)
    assert res.n_pairs == ref.n_pairs and res.method == ref.method
    # boxes given explicitly override the model's
    X0, U, W = cm.Box([-2], [3]), cm.Box([-0.5], [0.5]), cm.Box([-0.1], [0.1])
    _same(quantified_sivia(m, X0, U, W, Y, 0.05, progress=False).paving,
          quantified_sivia(f, X0, U, W, Y, 0.05, progress=False).paving)
    _same(quantified_sivia(m, U=U, Y=Y, eps=0.05, progress=False).paving,
          quantified_sivia(f, m.X, U, m.W, Y, 0.05, progress=False).paving)


def test_quantified_sivia_of_a_model_without_disturbance():
    x, u = ca.SX.sym("x", 2), ca.SX.sym("u")
    model = cm.Model(x=x, u=u, f=ca.vertcat(x[0] + u, x[1] - u), X=cm.Box([-3, -3], [3, 3]),
                     U=cm.Box([-1], [1]))
    Y = cm.Box([-1, -1], [1, 1])
    f = ca.Function("f", [x, u], [model.f])
    _same(quantified_sivia(model, Y=Y, eps=0.1, progress=False).paving,
          quantified_sivia(f, model.X, model.U, None, Y, 0.1, progress=False).paving)
    with pytest.raises(cm.ModelError, match="no disturbance"):
        quantified_sivia(model, W=cm.Box([0], [1]), Y=Y, eps=0.1)


def test_quantified_sivia_model_errors(scalar_model):
    with pytest.raises(cm.ModelError, match="no input"):
        quantified_sivia(_additive_model(), Y=cm.Box([-1], [1]), eps=0.1)
    with pytest.raises(TypeError, match="target Y"):
        quantified_sivia(scalar_model, eps=0.1)
    f = ca.Function("f", [scalar_model.x, scalar_model.u, scalar_model.w], [scalar_model.f])
    with pytest.raises(TypeError, match="X0 and U"):
        quantified_sivia(f, Y=cm.Box([-1], [1]), eps=0.1)
    with pytest.raises(cm.DimensionError):
        quantified_sivia(scalar_model, Y=cm.Box([-1, -1], [1, 1]), eps=0.1)
