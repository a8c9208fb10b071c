"""Validated ODE models: exact linear flows, widths, refusals, the examples and the solvers.

The "true" successors here are the exact discretisation of a linear ODE (``mpmath.expm``
with 30 digits) or ``scipy.integrate.solve_ivp`` (DOP853, rtol 1e-12, atol 1e-14), never
the model's own Taylor map.
"""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest
from scipy.integrate import solve_ivp

import casadi_cmpc as cm
from casadi_cmpc.exceptions import ModelError, UnsupportedOperationError


def _ivp(rhs, x0: np.ndarray, u: np.ndarray, w: np.ndarray, dt: float) -> np.ndarray:
    """Successors of the states x0 (N, n) with u (N, m), w (N, l) over dt (one vectorised
    solve_ivp call; rhs(x (n, N), u (m, N), w (l, N)) -> (n, N))."""
    N, n = x0.shape

    def f(t: float, y: np.ndarray) -> np.ndarray:
        return rhs(y.reshape(n, N), u.T, w.T).reshape(-1)

    sol = solve_ivp(f, (0.0, dt), x0.T.reshape(-1), method="DOP853", rtol=1e-12, atol=1e-14)
    assert sol.success
    return sol.y[:, -1].reshape(n, N).T


# ------------------------------------------------------------------- linear ODE
def test_linear_ode_encloses_the_exact_discretisation_tightly() -> None:
    import mpmath

    A = np.array([[0.0, 1.0], [-2.0, -0.3]])
    B = np.array([[0.0], [1.0]])
    x = ca.SX.sym("x", 2)
    u = ca.SX.sym("u")
    dt = 0.05
    model = cm.Model.from_ode(x, u, ca.mtimes(ca.DM(A), x) + ca.DM(B) * u, dt,
                              method="taylor", order=10, X=cm.Box([-1, -1], [1, 1]),
                              U=cm.Box([-1], [1]))
    mpmath.mp.dps = 30
    aug = mpmath.zeros(3, 3)
    for i in range(2):
        for j in range(2):
            aug[i, j] = mpmath.mpf(A[i, j])
        aug[i, 2] = mpmath.mpf(B[i, 0])
    E = mpmath.expm(aug * mpmath.mpf(dt))
    rng = np.random.default_rng(3)
    for backend in ("numpy", "scalar"):
        for kind in ("natural", "centered"):
            F = model.inclusion(kind, backend=backend)
            for _ in range(5):
                xx = rng.uniform(-1, 1, 2)
                uu = rng.uniform(-1, 1, 1)
                exact = [E[i, 0] * mpmath.mpf(xx[0]) + E[i, 1] * mpmath.mpf(xx[1])
                         + E[i, 2] * mpmath.mpf(uu[0]) for i in range(2)]
                box = F(np.stack([xx, xx], -1)[None], np.stack([uu, uu], -1)[None])[0]
                for i in range(2):
                    assert mpmath.mpf(box[i, 0]) <= exact[i] <= mpmath.mpf(box[i, 1])
                    assert box[i, 1] - box[i, 0] <= 1e-12 * (1 + abs(float(exact[i])))


# ------------------------------------------------------------------- widths
def _width_ratio(model: cm.Model, rhs, x_box: np.ndarray, u: np.ndarray,
                 rng: np.random.Generator) -> np.ndarray:
    """Width of the natural enclosure of x_box x {u} x W over the width of the hull of
    10 000 sampled true successors, per state."""
    n, l = model.n, model.l
    N = 10_000
    X = rng.uniform(x_box[:, 0], x_box[:, 1], (N, n))
    X[:2 ** n] = np.array([[x_box[j, (k >> j) & 1] for j in range(n)] for k in range(2 ** n)])
    W = rng.uniform(model.W_box.lo, model.W_box.hi, (N, l)) if l else np.zeros((N, 0))
    Y = _ivp(rhs, X, np.broadcast_to(u, (N, u.size)), W, model.validation["dt"])
    hull = Y.max(axis=0) - Y.min(axis=0)
    enc = model.inclusion("natural")(x_box[None], np.stack([u, u], -1)[None])[0]
    assert ((enc[:, 0] <= Y.min(axis=0)) & (Y.max(axis=0) <= enc[:, 1])).all()
    return (enc[:, 1] - enc[:, 0]) / hull


def _mg_rhs(x: np.ndarray, u: np.ndarray, w: np.ndarray) -> np.ndarray:
    from casadi_cmpc.models import moore_greitzer as mg

    return mg.rhs_numpy(x, u, w)


def _cstr_rhs(x: np.ndarray, u: np.ndarray, w: np.ndarray) -> np.ndarray:
    from casadi_cmpc.models import cstr as C

    c_a = x[0] + C.C_A_EQ
    temp = 100 * x[1] + C.T_EQ
    rate = C.K0 * np.exp(-C.E_OVER_R / temp) * c_a
    dc = C.Q_FLOW / C.VOLUME * (C.C_AF - c_a) - rate
    dT = (C.Q_FLOW / C.VOLUME * (C.T_F - temp) + (-C.DELTA_H) / (C.RHO * C.C_P) * rate
          + C.UA / (C.VOLUME * C.RHO * C.C_P) * (100 * u[0] + C.T_C_EQ - temp))
    return np.stack([dc, dT / 100])


@pytest.mark.parametrize("name", ["moore_greitzer", "cstr_validated"])
def test_enclosure_of_a_small_box_is_close_to_the_true_hull(name: str) -> None:
    ex = cm.models.load(name)
    model = ex.model
    assert model.is_validated and "validated Taylor" in model.discretisation
    rhs = _mg_rhs if name == "moore_greitzer" else _cstr_rhs
    rng = np.random.default_rng(7)
    X = model.X.as_array()
    for _ in range(2):
        lo = X[:, 0] + rng.uniform(0, 0.99) * (X[:, 1] - X[:, 0])
        box = np.stack([lo, lo + 0.01 * (X[:, 1] - X[:, 0])], axis=1)
        u = rng.uniform(model.U.lo, model.U.hi)
        ratio = _width_ratio(model, rhs, box, u, rng)
        assert (ratio <= 1.5).all(), ratio


def test_the_sampled_map_is_the_taylor_polynomial_of_the_true_flow() -> None:
    ex = cm.models.load("moore_greitzer")
    model = ex.model
    rng = np.random.default_rng(0)
    X = rng.uniform(model.X.lo, model.X.hi, (50, 2))
    U = rng.uniform(model.U.lo, model.U.hi, (50, 2))
    W = rng.uniform(model.W.lo, model.W.hi, (50, 2))
    true = _ivp(_mg_rhs, X, U, W, 0.1)
    # the Taylor map is within the validated remainder of the flow
    assert np.abs(model.step(X, U, W) - true).max() <= model.validation["remainder_width"]


# ------------------------------------------------------------------- refusals
def _xu() -> tuple[ca.SX, ca.SX]:
    return ca.SX.sym("x", 2), ca.SX.sym("u")


@pytest.mark.parametrize("make, what", [
    (lambda x, u: ca.vertcat(x[1], ca.if_else(x[0] > 0, -1, 1) + u), "if_else"),
    (lambda x, u: ca.vertcat(x[1], ca.floor(x[0]) + u), "floor"),
    (lambda x, u: ca.vertcat(ca.fabs(x[1]), -x[0] + u), "fabs"),
    (lambda x, u: ca.vertcat(ca.fmin(x[1], 0.5), -x[0] + u), "fmin"),
    (lambda x, u: ca.vertcat(x[1], ca.sign(x[0]) * u), "sign"),
])
def test_jumps_are_refused(make, what: str) -> None:
    x, u = _xu()
    with pytest.raises(UnsupportedOperationError, match=what):
        cm.Model.from_ode(x, u, make(x, u), 0.1, method="taylor", X=cm.Box([-1, -1], [1, 1]),
                          U=cm.Box([-1], [1]))


@pytest.mark.parametrize("make", [
    lambda x, u: ca.vertcat(ca.sqrt(x[0]), u),  # sqrt of negative states
    lambda x, u: ca.vertcat(1 / x[0], u),  # pole inside X
    lambda x, u: ca.vertcat(ca.log(x[0] + 1), u),  # log(0) on X's edge
])
def test_undefined_rhs_cannot_be_validated(make) -> None:
    x, u = _xu()
    with pytest.raises(ModelError, match="cannot be validated"):
        cm.Model.from_ode(x, u, make(x, u), 0.1, method="taylor", X=cm.Box([-1, -1], [1, 1]),
                          U=cm.Box([-1], [1]))


def test_finite_escape_cannot_be_validated() -> None:
    x = ca.SX.sym("x")
    with pytest.raises(ModelError, match="cannot be validated"):
        cm.Model.from_ode(x, None, x ** 2, 2.0, method="taylor", X=cm.Box([1.0], [2.0]))


@pytest.mark.parametrize("order, exc", [(0, ValueError), (13, ValueError), (2.5, TypeError),
                                        (True, TypeError)])
def test_bad_order_is_refused(order, exc) -> None:
    x, u = _xu()
    with pytest.raises(exc, match="order"):
        cm.Model.from_ode(x, u, ca.vertcat(x[1], u), 0.1, method="taylor", order=order,
                          X=cm.Box([-1, -1], [1, 1]), U=cm.Box([-1], [1]))


def test_substeps_and_missing_boxes_are_refused() -> None:
    x, u = _xu()
    with pytest.raises(ValueError, match="substeps"):
        cm.Model.from_ode(x, u, ca.vertcat(x[1], u), 0.1, method="taylor", substeps=2,
                          X=cm.Box([-1, -1], [1, 1]), U=cm.Box([-1], [1]))
    with pytest.raises(ModelError, match="U"):
        cm.Model.from_ode(x, u, ca.vertcat(x[1], u), 0.1, method="taylor",
                          X=cm.Box([-1, -1], [1, 1]))
    with pytest.raises(ValueError, match="unknown method"):
        cm.Model.from_ode(x, u, ca.vertcat(x[1], u), 0.1, method="taylr",
                          X=cm.Box([-1, -1], [1, 1]), U=cm.Box([-1], [1]))


def _pendulum(order: int = 4) -> cm.Model:
    x, u = _xu()
    return cm.Model.from_ode(x, u, ca.vertcat(x[1], -ca.sin(x[0]) + u), 0.1, method="taylor",
                             order=order, X=cm.Box([-1, -1], [1, 1]), U=cm.Box([-2], [2]))


def _pendulum_rhs(x: np.ndarray, u: np.ndarray, w: np.ndarray) -> np.ndarray:
    return np.stack([x[1], -np.sin(x[0]) + u[0]])


def test_boxes_leaving_the_validated_domain_give_the_whole_line() -> None:
    model = _pendulum()
    D = model.validation["domain"]
    inside = np.array([[[0.0, 0.1], [0.0, 0.1]]])
    out = np.array([[[0.0, D[0, 1] + 0.01], [0.0, 0.1]]])
    u_out = np.array([[[0.0, D[2, 1] + 0.01]]])
    from casadi_cmpc.interval._native import native_available

    for backend in ("numpy", "scalar") + (("native",) if native_available() else ()):
        for kind in ("natural", "centered"):
            F = model.inclusion(kind, backend=backend)
            assert np.isfinite(F(inside)).all()
            assert (F(out)[..., 0] == -np.inf).all() and (F(out)[..., 1] == np.inf).all()
            assert (F(inside, u_out)[..., 0] == -np.inf).all()
    J = model.jacobian_inclusion("x")
    assert np.isfinite(J(inside)).all()
    assert (J(out)[..., 0] == -np.inf).all()


def test_discretisation_names_what_the_map_is() -> None:
    x, u = _xu()
    rhs = ca.vertcat(x[1], u)
    kw = dict(X=cm.Box([-1, -1], [1, 1]), U=cm.Box([-1], [1]))
    assert cm.Model.from_ode(x, u, rhs, 0.1, **kw).discretisation == \
        "the Euler map of an ODE (no error bound)"
    assert cm.Model.from_ode(x, u, rhs, 0.1, method="rk4", **kw).discretisation == \
        "the RK4 map of an ODE (no error bound)"
    plain = cm.Model(x=x, u=u, f=x + 0.1 * rhs, **kw)
    assert plain.discretisation == "discrete model" and not plain.is_validated
    v = cm.Model.from_ode(x, u, rhs, 0.1, method="taylor", order=3, time_unit=2.0, **kw)
    assert v.discretisation == ("the sampled-data ODE (validated Taylor, order 3, dt = 0.1 "
                                "(= 0.2 s), zero-order hold, w constant over the sample)")
    cl = v.closed_loop(np.array([[-1.0, -1.0]]))
    assert cl.discretisation == v.discretisation and cl.is_validated
    assert "map: the sampled-data ODE" in v.summary() and "validated domain" in v.summary()
    assert cm.models.load("cstr").model.discretisation == \
        "the Euler map of an ODE (no error bound)"


def test_interval_expr_and_c_export_keep_the_remainder() -> None:
    from casadi_cmpc.interval._cgen import interval_function

    model = _pendulum()
    expr, P, Pb = model.interval_expr()
    assert expr.shape == (2, 1) and Pb.shape == (P.numel(), 2)
    assert (Pb[:, 0] < Pb[:, 1]).sum() >= model.n  # interval-valued remainder parameters
    src = interval_function(model.interval_map("xuw"), "f_iv")
    lo, hi = model.validation["rho"][0]
    assert lo.hex() in src and hi.hex() in src  # rho[0] enters as an interval constant


# ------------------------------------------------------------------- solvers
def test_closed_loop_of_a_validated_model_encloses_the_true_closed_loop() -> None:
    model = _pendulum()
    K = np.array([[-1.0, -1.5]])
    cl = model.closed_loop(K)
    rng = np.random.default_rng(5)
    P = rng.uniform(-0.8, 0.8, (200, 2))
    true = _ivp(_pendulum_rhs, P, P @ K.T, np.zeros((200, 0)), 0.1)
    for kind in ("natural", "centered"):
        enc = cl.inclusion(kind)(np.stack([P, P], -1))
        assert ((enc[..., 0] <= true) & (true <= enc[..., 1])).all()
        # at a point, only the remainder (and rounding) is wide
        assert (enc[..., 1] - enc[..., 0]).max() <= model.validation["remainder_width"] + 1e-12


def test_certify_invariant_on_validated_models() -> None:
    x = ca.SX.sym("x", 2)
    u = ca.SX.sym("u")
    kw = dict(X=cm.Box([-2, -2], [2, 2]), U=cm.Box([-3], [3]))
    stable = cm.Model.from_ode(x, u, ca.vertcat(-x[0] + 0.2 * x[1], -x[1] + u), 0.2,
                               method="taylor", order=4, **kw)
    S = cm.Polytope.from_box(cm.Box([-1, -1], [1, 1]))
    cert = cm.certify_invariant(stable, S, np.array([[0.0, -0.5]]), 0.25)
    assert cert.proved is True
    unstable = cm.Model.from_ode(x, u, ca.vertcat(0.5 * x[0] + 0.2 * x[1], -x[1] + u), 0.2,
                                 method="taylor", order=4, **kw)
    cert = cm.certify_invariant(unstable, S, np.array([[0.0, -0.5]]), 0.25)
    assert cert.proved is not True


def test_one_step_set_of_a_validated_model_is_sound_for_the_true_flow() -> None:
    model = _pendulum()
    T = cm.Polytope.from_box(cm.Box([-0.5, -0.5], [0.5, 0.5]))
    res = cm.one_step_set(model, T, 0.1, method="general", progress=False)
    inner = res.inner
    assert inner.shape[0] > 0
    rng = np.random.default_rng(2)
    k = rng.integers(0, inner.shape[0], 300)
    P = rng.uniform(inner[k, :, 0], inner[k, :, 1])
    U = res.witness[k]
    Y = _ivp(_pendulum_rhs, P, U, np.zeros((300, 0)), 0.1)
    assert T.contains(Y).all()


def test_contractive_mpc_verified_steps_hold_for_the_true_flow() -> None:
    model = _pendulum()
    ctrl = cm.ContractiveMPC(model, horizon=3, alpha=0.95, norm=2, solver="sqp")
    n_ver = 0
    for x0 in ([0.6, 0.0], [-0.4, 0.3]):
        r = ctrl.solve(np.array(x0))
        if r.certificate.label != "verified":
            continue
        n_ver += 1
        xs = [np.array(x0)]
        for uu in r.u_seq:
            xs.append(_ivp(_pendulum_rhs, xs[-1][None], np.atleast_2d(uu),
                           np.zeros((1, 0)), 0.1)[0])
        assert all(model.X.contains(y) for y in xs)
        assert np.linalg.norm(xs[-1]) <= 0.95 * np.linalg.norm(xs[0]) + 1e-6
    assert n_ver >= 1


def test_moore_greitzer_closed_loop_under_the_true_ode_stays_in_x() -> None:
    from casadi_cmpc.models import moore_greitzer as mg

    ex = cm.models.load("moore_greitzer")
    model = ex.model
    x_ref, u_ref = ex.info["x_ref"], ex.info["u_ref"]
    K = cm.local_lqr(model, np.diag([1e3, 1e3]), np.diag([1.0, 1.0]), x_eq=x_ref, u_eq=u_ref)
    Kmat = np.asarray(getattr(K, "K", K), dtype=float).reshape(2, 2)
    rng = np.random.default_rng(11)
    x = np.array([0.47, 0.64])
    for _ in range(40):
        u = np.clip(u_ref + Kmat @ (x - x_ref), model.U.lo, model.U.hi)
        w = rng.uniform(-mg.W_MAX, mg.W_MAX, 2)
        x = _ivp(_mg_rhs, x[None], u[None], w[None], mg.TAU)[0]
        assert model.X.contains(x)


# ------------------------------------------------------- interval-valued parameters
def test_interval_valued_parameters_in_every_evaluator() -> None:
    from casadi_cmpc.interval import InclusionFunction
    from casadi_cmpc.interval._cgen import interval_function
    from casadi_cmpc.interval._derivative import JacobianInclusion, ParamFunction, ParamGraph
    from casadi_cmpc.interval._native import native_available

    x = ca.SX.sym("x")
    p = ca.SX.sym("p", 2)
    g = ca.Function("g", [x, p], [p[0] * x + p[1]])
    pf = ParamFunction(g, 1, np.array([[1.0, 2.0], [0.5, 0.5]]))  # p0 in [1, 2], p1 = 0.5
    assert pf.interval.tolist() == [True, False]
    np.testing.assert_array_equal(pf.bounds, [[1.0, 2.0], [0.5, 0.5]])
    X = np.array([[[1.0, 1.0]], [[-1.0, -1.0]]])
    for backend in ("numpy", "scalar") + (("native",) if native_available() else ()):
        for kind in ("natural", "centered"):
            out = InclusionFunction(pf, kind, backend=backend)(X)[0]
            assert out[0, 0, 0] <= 1.5 and out[0, 0, 1] >= 2.5  # [1, 2] * 1 + 0.5
            assert out[1, 0, 0] <= -1.5 and out[1, 0, 1] >= -0.5
            assert (out[..., 1] - out[..., 0]).max() < 1.0 + 1e-12
    J = JacobianInclusion(pf)(X[:1], 1)[0, 0, 0]
    assert J[0] <= 1.0 and J[1] >= 2.0 and J[1] - J[0] < 1.0 + 1e-12
    pg = ParamGraph(pf)
    assert pg.interval.tolist() == [True, False]
    assert "0x1.0000000000000p+1" in interval_function(pf, "g_iv")  # the upper bound 2


def test_a_contractor_refuses_interval_valued_parameters() -> None:
    from casadi_cmpc.interval.contractor import contractor

    model = _pendulum()
    cl = model.closed_loop(np.array([[-1.0, -1.5]]))
    with pytest.raises(UnsupportedOperationError):
        contractor(cl.interval_map("x"), cm.Box([-1, -1], [1, 1]))


def test_interval_key_tells_validated_models_apart() -> None:
    x, u = _xu()
    rhs = ca.vertcat(x[1], -ca.sin(x[0]) + u)
    a = cm.Model.from_ode(x, u, rhs, 0.1, method="taylor", X=cm.Box([-1, -1], [1, 1]),
                          U=cm.Box([-2], [2]))
    b = cm.Model.from_ode(x, u, rhs, 0.1, method="taylor", X=cm.Box([-2, -2], [2, 2]),
                          U=cm.Box([-2], [2]))
    assert a.function.serialize() == b.function.serialize()  # the same Taylor map
    assert a.interval_key() != b.interval_key()  # different remainders
    assert a.interval_key() == a.interval_key()
