"""Every solver accepts an already compiled InclusionFunction in place of the casadi.Function.

Passing ``cm.interval.inclusion(f)`` (or an InclusionFunction built directly) must give the
same result as passing ``f``, and the compiled object must be the one evaluated (no second
compilation of the same Function).
"""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

import casadi_cmpc as cm
from casadi_cmpc.interval.compiler import InclusionFunction
from casadi_cmpc.interval.modal import SemanticExtension
from casadi_cmpc.solvers.minimax import minimax
from casadi_cmpc.solvers.minimize import minimize
from casadi_cmpc.solvers.quantified import quantified_sivia
from casadi_cmpc.solvers.zonotope_sivia import zonotope_sivia


@pytest.fixture(autouse=True)
def _one_evaluator(monkeypatch):
    """These tests compare runs that pass the same function in different forms, bit for bit.
    A cached inclusion moves to the native kernel after 16 batches (its enclosures differ
    from numpy's in the last bits, both sound), so which evaluator a run meets would depend
    on what ran before: here every run uses numpy (and the scalar evaluator)."""
    monkeypatch.setattr(InclusionFunction, "native_after", 10**9)


def _spy(F):
    """Count the batches F evaluates through evaluate_unchecked."""
    calls = []
    orig = F.evaluate_unchecked

    def ev(boxes, n):
        calls.append(n)
        return orig(boxes, n)

    F.evaluate_unchecked = ev
    return calls


def _same_paving(P, Q):
    for view in ("inner", "boundary", "outside"):
        np.testing.assert_array_equal(getattr(P, view), getattr(Q, view), err_msg=view)
    assert P.n_discarded == Q.n_discarded


# ------------------------------------------------------------------------- sivia
def test_sivia_with_a_compiled_function():
    p = ca.SX.sym("p", 2)
    f = ca.Function("ring", [p], [ca.vertcat(p[0] ** 2 + p[1] ** 2, p[0] * ca.exp(p[1]))])
    X0 = cm.Box([-2, -2], [2, 2])
    Y = cm.Box([0.5, -1.0], [2.0, 1.0])
    ref = cm.sivia(f, X0, Y, 0.05, progress=False)
    for F in (cm.interval.inclusion(f), InclusionFunction(f, backend="numpy"),
              InclusionFunction(f, backend="scalar")):
        _same_paving(ref, cm.sivia(F, X0, Y, 0.05, progress=False))
    # a casadi.Function is compiled once: sivia works with the cached inclusion (whose
    # per-component evaluators it builds and keeps on it)
    g = ca.Function("ring2", [p], [ca.vertcat(p[0] ** 2 + p[1] ** 2, p[0] * ca.exp(p[1]))])
    G = cm.interval.inclusion(g)
    assert not G.__dict__.get("_components") and not G.__dict__.get("_cores")
    _same_paving(ref, cm.sivia(g, X0, Y, 0.05, progress=False))
    assert G.__dict__.get("_components") or G.__dict__.get("_cores")


# ---------------------------------------------------------------------- minimize
X2 = ca.SX.sym("x", 2)
OBJ = ca.Function("obj", [X2], [(X2[0] - 0.5) ** 2 + ca.sin(3 * X2[1]) * X2[0] + X2[1] ** 2])
CON = ca.Function("con", [X2], [ca.vertcat(X2[0] + X2[1] - 0.8, X2[0] * X2[1] - 0.3)])
BOX = np.array([[-1.0, 1.5], [-1.0, 1.0]])


def _same_bracket(r, s):
    assert (r.lower, r.upper) == (s.lower, s.upper)
    np.testing.assert_array_equal(r.candidates, s.candidates)
    np.testing.assert_array_equal(r.x, s.x)
    assert r.status == s.status and r.method == s.method


@pytest.mark.parametrize("kind", ["centered", "natural"])
def test_minimize_with_compiled_functions(kind):
    ref = minimize(OBJ, BOX, 1e-3, constraints=CON, kind=kind, local_solver=None)
    F = InclusionFunction(OBJ, kind)
    G = InclusionFunction(CON, kind)
    fc, gc = _spy(F), _spy(G)
    res = minimize(F, BOX, 1e-3, constraints=G, local_solver=None)  # kind: that of F
    _same_bracket(ref, res)
    assert fc and gc  # the given objects were evaluated
    assert res.lower <= res.upper < np.inf


def test_minimize_kind_given_explicitly_and_ipopt():
    """An explicit kind wins over the compiled one's; the local solver gets the Function."""
    ref = minimize(OBJ, BOX, 1e-3, constraints=CON, kind="natural")
    res = minimize(cm.interval.inclusion(OBJ, "centered"), BOX, 1e-3,
                   constraints=cm.interval.inclusion(CON, "centered"), kind="natural")
    _same_bracket(ref, res)
    assert res.method == "natural+ipopt" and res.n_local == ref.n_local


def test_restricted_inclusions_are_refused():
    F = InclusionFunction(CON, derived_outputs=(0,))
    with pytest.raises(ValueError, match="derived_outputs"):
        minimize(OBJ, BOX, 1e-2, constraints=F, local_solver=None)
    with pytest.raises(TypeError, match="casadi.Function"):
        minimize("x**2", BOX, 1e-2)


# ------------------------------------------------------------- quantified sivia
def test_quantified_sivia_with_a_compiled_function():
    x, u, w = ca.SX.sym("x"), ca.SX.sym("u"), ca.SX.sym("w")
    f = ca.Function("fq", [x, u, w], [ca.vertcat(x + u * (1 + 0.1 * x * x) + w, x - u)])
    args = (cm.Box([-3], [3]), cm.Box([-1], [1]), cm.Box([-0.2], [0.2]),
            cm.Box([-1, -2], [1, 2]), 0.05)
    ref = quantified_sivia(f, *args, progress=False)
    F = cm.interval.inclusion(f)
    _same_paving(ref, quantified_sivia(F, *args, progress=False))
    _same_paving(ref, quantified_sivia(InclusionFunction(f, backend="numpy"), *args,
                                       progress=False))
    # the semantic extension evaluates the cached natural inclusion of the Function
    assert SemanticExtension(F.fun).F is F
    with pytest.raises(TypeError, match="InclusionFunction"):
        quantified_sivia(None, *args)


# ------------------------------------------------------------------------ minimax
def test_minimax_with_compiled_functions():
    u, w = ca.SX.sym("u"), ca.SX.sym("w")
    f = ca.Function("f", [u, w], [(u - w) ** 2 + 0.1 * ca.sin(u)])
    g = ca.Function("g", [u, w], [0.2 + w - u])
    U, W = cm.Box([-1], [1]), cm.Box([-0.5], [0.5])
    ref = minimax(f, U, W, 1e-3, constraints=g, progress=False)
    res = minimax(cm.interval.inclusion(f), U, W, 1e-3,
                  constraints=InclusionFunction(g, "centered"), progress=False)
    assert (ref.lower, ref.upper) == (res.lower, res.upper)
    np.testing.assert_array_equal(ref.u, res.u)
    np.testing.assert_array_equal(ref.candidates, res.candidates)
    assert ref.lower <= ref.upper < np.inf


# ---------------------------------------------------------------- zonotope sivia
def _same_zonotopes(a, b):
    for view in ("inner", "boundary", "outside"):
        fa, fb = getattr(a, view), getattr(b, view)
        np.testing.assert_array_equal(fa.centers, fb.centers, err_msg=view)
        np.testing.assert_array_equal(fa.generators, fb.generators, err_msg=view)
        np.testing.assert_array_equal(fa.radii, fb.radii, err_msg=view)


@pytest.mark.parametrize("box_form", ["natural", "centered", None])
def test_zonotope_sivia_with_a_compiled_function(box_form):
    x = ca.SX.sym("x", 2)
    f = ca.Function("f", [x], [x + 0.1 * ca.vertcat(x[0] ** 2, x[0] * x[1])])
    Z0 = cm.Zonotope([0.0, 0.0], [[1.0, 0.5], [0.0, 1.0]])
    Y = cm.Box([-1, -1], [1, 1])
    ref = zonotope_sivia(f, Z0, Y, 0.1, box_form=box_form, progress=False)
    F = InclusionFunction(f)
    calls = _spy(F)
    res = zonotope_sivia(F, Z0, Y, 0.1, box_form=box_form, progress=False)
    _same_zonotopes(ref, res)
    assert calls  # the natural point enclosures came from F
    assert len(res.inner) > 0
