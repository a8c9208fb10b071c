"""The model library (casadi_cmpc.models) against the thesis equations, and Polytope."""

from __future__ import annotations

import itertools

import casadi as ca
import numpy as np
import pytest

import casadi_cmpc as cm
from casadi_cmpc.exceptions import DimensionError, InvalidBoundsError

Example = cm.models.Example
load = cm.models.load
names = cm.models.names

RNG_SEED = 20240611
RTOL = 1e-12
ATOL = 1e-12

ALL_NAMES = [
    "linear_sliding", "cannon_001", "cstr", "grimm", "cannon", "cannon_robust",
    "cannon_robust_wide", "khalil_affine_state", "khalil_affine_control", "mirosot",
]
# examples not from the thesis (tests/test_extra_models.py; the validated ODE model
# moore_greitzer: tests/test_validated_ode_models.py)
EXTRA_NAMES = ["cartpole", "three_tank", "moore_greitzer"]

# name -> (n, m, l, X (n, 2), U (m, 2), W (l, 2) or None, E-number)
EXPECTED = {
    "linear_sliding": (2, 1, 0, [[-8, 8], [-8, 8]], [[-2, 2]], None, "E1"),
    "cannon_001": (2, 1, 0, [[-4, 4], [-4, 4]], [[-2, 2]], None, "E5"),
    "cstr": (2, 1, 0, [[-0.5, 0.5], [-0.7, 0.2]], [[-0.2, 0.7]], None, "E6, E14"),
    "grimm": (2, 1, 0, [[-3, 3], [-3, 3]], [[0, 1]], None, "E7"),
    "cannon": (2, 1, 0, [[-2, 2], [-2, 2]], [[-2, 2]], None, "E8"),
    "cannon_robust": (2, 1, 1, [[-2, 2], [-2, 2]], [[-2, 2]], [[0.85, 0.95]], "E9"),
    "cannon_robust_wide": (2, 1, 1, [[-4, 4], [-4, 4]], [[-2, 2]], [[0.75, 0.95]], "E10"),
    "khalil_affine_state": (2, 1, 1, [[-1, 1], [-1, 1]], [[-3, 3]], [[-0.01, 0.01]], "E11"),
    "khalil_affine_control": (2, 1, 2, [[-1, 1], [-1, 1]], [[-3, 3]],
                              [[-0.01, 0.01], [0.9, 1.0]], "E12"),
    "mirosot": (8, 2, 0, [[0, 150], [0, 130], [-2 * np.pi, 2 * np.pi]] * 2 + [[-100, 100]] * 2,
                [[-100, 100]] * 2, None, "E13"),
}

EXPECTED_X0S = {
    "linear_sliding": [[6.8, 7.2], [-7.2, -5.8]],
    "cannon_001": np.zeros((0, 2)),
    "cstr": [[0.4 - 0.5, (326 - 350) / 100]],
    "grimm": [[2, 2]],
    "cannon": [[1.9, -1.5]],
    "cannon_robust": [[1.75, -1.6]],
    "cannon_robust_wide": [[-1.5, 1.1], [0.3, -2.1]],
    "khalil_affine_state": [[-0.5, -0.8]],
    "khalil_affine_control": [[-0.7, -0.9], [0.77, 0.6]],
    "mirosot": [[20, 20, 0, 20, 20, 0, 0, 0]],
}

K_CANNON = np.array([[-1.2131, -1.2128]])


@pytest.fixture(scope="module")
def examples() -> dict[str, Example]:
    return {name: load(name) for name in ALL_NAMES}


def _uniform(rng: np.random.Generator, box: cm.Box, n: int) -> np.ndarray:
    return box.lo + (box.hi - box.lo) * rng.random((n, box.dim))


def _random_args(ex: Example, n: int = 50):
    rng = np.random.default_rng(RNG_SEED)
    model = ex.model
    x = _uniform(rng, model.X, n)
    u = _uniform(rng, model.U, n)
    w = _uniform(rng, model.W, n) if model.W is not None else None
    return x, u, w


# ---------------------------------------------------------------- registry
def test_names_are_the_ten_thesis_examples_then_the_extra_ones():
    assert names() == ALL_NAMES + EXTRA_NAMES
    assert cm.models.names() == ALL_NAMES + EXTRA_NAMES


def test_unknown_name_lists_valid_names():
    with pytest.raises(ValueError) as err:
        load("routh")
    for name in ALL_NAMES:
        assert name in str(err.value)
    with pytest.raises(ValueError):
        load("Cannon")


def test_load_returns_fresh_examples():
    a, b = load("cannon"), load("cannon")
    assert a.model is not b.model


@pytest.mark.parametrize("name", ALL_NAMES)
def test_example_sizes_and_boxes(examples, name):
    ex = examples[name]
    n, m, l, X, U, W, enum = EXPECTED[name]
    assert isinstance(ex, Example)
    assert ex.name == name
    model = ex.model
    assert (model.n, model.m, model.l) == (n, m, l)
    np.testing.assert_allclose(model.X.as_array(), np.array(X, dtype=float), rtol=0, atol=1e-15)
    np.testing.assert_allclose(model.U.as_array(), np.array(U, dtype=float), rtol=0, atol=1e-15)
    if W is None:
        assert model.W is None
    else:
        np.testing.assert_array_equal(model.W.as_array(), np.array(W, dtype=float))
    assert ex.info["example"] == enum
    assert isinstance(ex.info["choices"], dict)
    x0s = np.asarray(EXPECTED_X0S[name], dtype=float).reshape(-1, n)
    assert ex.x0s.shape == x0s.shape
    np.testing.assert_allclose(ex.x0s, x0s, rtol=0, atol=1e-15)
    if len(ex.x0s):
        assert model.X.contains(ex.x0s).all()


@pytest.mark.parametrize("name", ALL_NAMES)
def test_terminal_set_contains_origin_and_lies_in_X(examples, name):
    ex = examples[name]
    if name in ("grimm", "mirosot"):
        assert ex.terminal is None
        return
    assert isinstance(ex.terminal, (cm.Polytope, cm.PolytopeUnion))
    assert ex.terminal.dim == ex.model.n
    assert ex.terminal.contains(np.zeros(ex.model.n))
    pieces = ex.terminal.polytopes if isinstance(ex.terminal, cm.PolytopeUnion) else [
        ex.terminal]
    for P in pieces:  # bounded, inside X: its vertices are
        verts = _polytope_vertices_2d(P)
        assert len(verts) >= 3
        assert ex.model.X.contains(verts).all()
    # no initial state of a closed-loop run starts in the terminal set
    if len(ex.x0s):
        assert not np.any(ex.terminal.contains(ex.x0s))


@pytest.mark.parametrize("name", ALL_NAMES)
def test_local_law_shape(examples, name):
    ex = examples[name]
    if name in ("grimm", "mirosot"):
        assert ex.local_law is None
    elif name == "linear_sliding":
        assert isinstance(ex.local_law, ca.SX)
    else:
        assert ex.local_law.shape == (ex.model.m, ex.model.n)
        ex.model.closed_loop(ex.local_law)  # accepted by the model


def test_example_validates_x0s_and_gain(examples):
    model = examples["cannon"].model
    with pytest.raises(ValueError):
        Example(name="bad", model=model, x0s=np.zeros((1, 3)))
    with pytest.raises(ValueError):
        Example(name="bad", model=model, local_law=np.zeros((2, 2)))
    with pytest.raises(TypeError):
        Example(name="bad", model=model, terminal=cm.Box([-1, -1], [1, 1]))


# ------------------------------------------------------- step vs the thesis
def test_step_linear_sliding(examples):
    ex = examples["linear_sliding"]
    x, u, _ = _random_args(ex)
    x1, x2, uu = x[:, 0], x[:, 1], u[:, 0]
    expected = np.stack([0.9 * x1 + 0.1 * x2, -0.5 * x1 + 0.2 * x2 + uu], axis=1)  # (3.7)
    np.testing.assert_allclose(ex.model.step(x, u), expected, rtol=RTOL, atol=ATOL)


def _cannon(x, u, mu, dt):
    x1, x2, uu = x[:, 0], x[:, 1], u[:, 0]
    return np.stack([
        x1 + dt * x2 + dt * (mu + (1 - mu) * x1) * uu,
        dt * x1 + x2 + dt * (mu - 4 * (1 - mu) * x2) * uu,
    ], axis=1)


@pytest.mark.parametrize("name, dt", [("cannon_001", 0.01), ("cannon", 0.1)])
def test_step_cannon_fixed_mu(examples, name, dt):
    ex = examples[name]
    x, u, _ = _random_args(ex)
    np.testing.assert_allclose(ex.model.step(x, u), _cannon(x, u, 0.9, dt), rtol=RTOL, atol=ATOL)
    assert ex.info["dt"] == dt and ex.info["mu"] == 0.9


@pytest.mark.parametrize("name", ["cannon_robust", "cannon_robust_wide"])
def test_step_cannon_uncertain_mu(examples, name):
    ex = examples[name]
    x, u, w = _random_args(ex)
    expected = _cannon(x, u, w[:, 0], 0.1)
    np.testing.assert_allclose(ex.model.step(x, u, w), expected, rtol=RTOL, atol=ATOL)
    # the disturbance really is mu: changing it changes the successor
    assert not np.allclose(ex.model.step(x, u, w), ex.model.step(x, u, w + 0.05))


def test_step_cstr_matches_equation_7_9(examples):
    ex = examples["cstr"]
    x, u, _ = _random_args(ex)
    x1, x2, uu = x[:, 0], x[:, 1], u[:, 0]
    q, V, CAf, Tf, rho, Cp, dH, ER, k0, UA = (100.0, 100.0, 1.0, 350.0, 1000.0, 0.239,
                                              -5e4, 8750.0, 7.2e10, 5e4)
    CAeq, Teq, Tceq = 0.5, 350.0, 300.0
    arr = k0 * np.exp(-ER / (100 * x2 + Teq))
    expected = np.stack([
        x1 + 0.03 * (q / V * (CAf - (x1 + CAeq)) - arr * (x1 + CAeq)),
        x2 + 0.0003 * (q / V * (Tf - (100 * x2 + Teq)) + (-dH) / (rho * Cp) * arr * (x1 + CAeq)
                       + UA / (V * rho * Cp) * (100 * uu + Tceq - (100 * x2 + Teq))),
    ], axis=1)
    np.testing.assert_allclose(ex.model.step(x, u), expected, rtol=RTOL, atol=ATOL)


def test_cstr_coordinates_and_equilibrium(examples):
    from casadi_cmpc.models import cstr

    ex = examples["cstr"]
    # physical constraints 0 <= C_A <= 1, 280 <= T <= 370, 280 <= Tc <= 370
    np.testing.assert_allclose(cstr.to_physical(ex.model.X.lo), [0.0, 280.0])
    np.testing.assert_allclose(cstr.to_physical(ex.model.X.hi), [1.0, 370.0])
    np.testing.assert_allclose(cstr.input_to_physical(ex.model.U.as_array()[0]), [280.0, 370.0])
    np.testing.assert_allclose(cstr.to_physical(ex.x0s), [[0.4, 326.0]])
    np.testing.assert_allclose(cstr.from_physical(0.4, 326.0), [-0.1, -0.24])
    # the origin is the (approximate, rounded data) equilibrium with u = 0
    assert np.abs(ex.model.step([0.0, 0.0], [0.0])).max() < 1e-5


def test_cstr_local_law_stabilises_the_linearisation(examples):
    ex = examples["cstr"]
    A = np.asarray(ex.model.jacobian_function("x")(np.zeros(2), 0.0, np.zeros(0)))
    B = np.asarray(ex.model.jacobian_function("u")(np.zeros(2), 0.0, np.zeros(0)))
    rho = np.abs(np.linalg.eigvals(A + B @ ex.local_law)).max()
    assert rho < 1.0
    np.testing.assert_array_equal(ex.local_law, [[-0.0690, -4.3387]])


def test_cstr_terminal_is_the_zonotope_of_e6(examples):
    ex = examples["cstr"]
    M = ex.info["zonotope_generators"]
    P = ex.terminal
    # support of Z = M B^4 in the direction of every row equals b (7.10), to print precision
    support = np.abs(P.A @ M).sum(axis=1)
    np.testing.assert_allclose(support, P.b, rtol=0, atol=2e-6)
    # all 16 extreme points of the zonotope lie in the polytope
    corners = np.array([M @ np.array(s) for s in itertools.product([-1, 1], repeat=4)])
    assert P.contains(corners, tol=1e-5).all()


def test_step_grimm(examples):
    ex = examples["grimm"]
    x, u, _ = _random_args(ex)
    x1, x2, uu = x[:, 0], x[:, 1], u[:, 0]
    expected = np.stack([x1 * (1 - uu), uu * np.sqrt(x1 ** 2 + x2 ** 2)], axis=1)  # (4.24)
    np.testing.assert_allclose(ex.model.step(x, u), expected, rtol=RTOL, atol=ATOL)


def test_step_khalil_affine_state(examples):
    ex = examples["khalil_affine_state"]
    x, u, w = _random_args(ex)
    x1, x2, uu, ww = x[:, 0], x[:, 1], u[:, 0], w[:, 0]
    expected = np.stack([x1 + 0.1 * x1 ** 2 - 0.1 * uu * x1 ** 3 + 0.1 * x2,
                         x2 + 0.1 * uu + ww], axis=1)  # (6.14)
    np.testing.assert_allclose(ex.model.step(x, u, w), expected, rtol=RTOL, atol=ATOL)


def test_step_khalil_affine_control(examples):
    ex = examples["khalil_affine_control"]
    x, u, w = _random_args(ex)
    x1, x2, uu, ww, p = x[:, 0], x[:, 1], u[:, 0], w[:, 0], w[:, 1]
    expected = np.stack([x1 + 0.1 * x2 + ww,
                         x2 + 0.1 * (x1 ** 2 + p * x2 ** 2 + uu)], axis=1)  # (6.24)
    np.testing.assert_allclose(ex.model.step(x, u, w), expected, rtol=RTOL, atol=ATOL)


def _arx_rollout(pose0, inputs, d):
    """(7.5) run directly on histories; the robot is at rest at pose0 before k = 0."""
    steps = len(inputs)
    x = np.zeros(steps + 2)
    y = np.zeros(steps + 2)
    th = np.zeros(steps + 2)
    x[:2], y[:2], th[:2] = pose0[0], pose0[1], pose0[2]  # indices 0, 1 <-> k = -1, 0

    def u_at(k):
        return inputs[k] if k >= 0 else np.zeros(2)

    for k in range(1, steps + 1):  # compute time k from k-1 (index k) and k-2 (index k-1)
        i = k + 1
        u1, u2 = u_at(k - d)
        x[i] = 1.3724 * x[i - 1] - 0.3724 * x[i - 2] + (0.0096 * u1 + 0.0119 * u2) * np.cos(
            th[i - 1])
        y[i] = 1.221 * y[i - 1] - 0.221 * y[i - 2] + (0.0117 * u1 + 0.0121 * u2) * np.sin(
            th[i - 1])
        th[i] = 1.121 * th[i - 1] - 0.121 * th[i - 2] - 0.00396 * u1 + 0.00422 * u2
    return np.stack([x[1:], y[1:], th[1:]], axis=1)  # poses at k = 0..steps


@pytest.mark.parametrize("delay", [1, 2, 3])
def test_mirosot_rollout_matches_arx_7_5(delay):
    from casadi_cmpc.models import mirosot

    ex = mirosot.build(delay=delay)
    assert ex.model.n == 6 + 2 * (delay - 1)
    rng = np.random.default_rng(delay)
    inputs = rng.uniform(-100, 100, size=(15, 2))
    pose0 = np.array([40.0, 30.0, 0.3])
    z = mirosot.rest_state(pose0, delay)
    traj = [mirosot.pose(z)]
    for k in range(len(inputs)):
        z = ex.model.step(z, inputs[k])
        traj.append(mirosot.pose(z))
    expected = _arx_rollout(pose0, inputs, delay)
    np.testing.assert_allclose(np.array(traj), expected, rtol=RTOL, atol=1e-10)
    # the robot does not move before the first input arrives, d samples later
    np.testing.assert_allclose(np.array(traj[:delay]), np.tile(pose0, (delay, 1)), atol=1e-12)
    assert not np.allclose(traj[delay + 1], pose0)


def test_mirosot_step_random_states(examples):
    ex = examples["mirosot"]
    x, u, _ = _random_args(ex)
    th = x[:, 2]
    u1d, u2d = x[:, 6], x[:, 7]  # d = 2: the input applied one sample earlier
    expected = np.column_stack([
        1.3724 * x[:, 0] - 0.3724 * x[:, 3] + (0.0096 * u1d + 0.0119 * u2d) * np.cos(th),
        1.221 * x[:, 1] - 0.221 * x[:, 4] + (0.0117 * u1d + 0.0121 * u2d) * np.sin(th),
        1.121 * th - 0.121 * x[:, 5] - 0.00396 * u1d + 0.00422 * u2d,
        x[:, 0], x[:, 1], x[:, 2], u[:, 0], u[:, 1],
    ])
    np.testing.assert_allclose(ex.model.step(x, u), expected, rtol=RTOL, atol=ATOL)
    info = ex.info
    assert info["delay"] == 2 and info["horizon"] == 12 and info["alpha"] == 0.95
    for key in ("delay", "U", "D", "target", "obstacles"):
        assert key in info["choices"]
    assert ex.model.X.contains(np.concatenate([info["target"], info["target"], [0, 0]]))


def test_mirosot_rejects_bad_delay():
    from casadi_cmpc.models import mirosot

    with pytest.raises(ValueError):
        mirosot.build(delay=0)


# ------------------------------------------------------- structure properties
def test_structure_linear_sliding(examples):
    assert examples["linear_sliding"].model.is_linear


@pytest.mark.parametrize("name", ["cannon_001", "cannon", "cannon_robust", "cannon_robust_wide"])
def test_structure_cannon(examples, name):
    model = examples[name].model
    assert model.is_affine_in_u
    assert not model.is_linear
    assert not model.has_affine_control_part
    assert model.nonlinear_states == (0, 1)


@pytest.mark.parametrize("name", ["cannon_robust", "cannon_robust_wide"])
def test_structure_cannon_affine_in_w(examples, name):
    assert examples[name].model.is_affine_in_w


def test_structure_khalil_affine_state(examples):
    model = examples["khalil_affine_state"].model
    assert model.nonlinear_states == (0,)
    assert model.has_affine_state_part
    np.testing.assert_array_equal(model.affine_state_matrix, [[0.0, 0.1], [0.0, 1.0]])
    assert not model.has_affine_control_part


def test_structure_khalil_affine_control(examples):
    model = examples["khalil_affine_control"].model
    assert model.has_affine_control_part
    np.testing.assert_array_equal(model.input_matrix, [[0.0], [0.1]])
    assert not model.is_linear
    # f is bilinear in (x2, p): df/dw depends on x, not on w, so for fixed x and u it is
    # affine in w = (w, p) (as in the cannon models, where mu multiplies x1 u)
    assert model.is_affine_in_w
    jac_w = model.jacobian_function("w")
    x = np.array([0.3, -0.6])
    np.testing.assert_allclose(np.asarray(jac_w(x, 0.0, [0.0, 0.95])),
                               [[1.0, 0.0], [0.0, 0.1 * 0.36]], rtol=RTOL)


def test_structure_cstr(examples):
    model = examples["cstr"].model
    assert model.is_affine_in_u
    assert model.nonlinear_states == (0, 1)
    assert not model.is_linear


def test_structure_grimm(examples):
    model = examples["grimm"].model
    assert model.is_affine_in_u
    assert not model.has_affine_control_part


# ------------------------------------------------------------ E5 local law
def _low_complexity_vertices(V, level):
    Vi = np.linalg.inv(V)
    return np.array([Vi @ (level * np.array(s)) for s in itertools.product([-1, 1], repeat=2)])


def test_e5_local_law_admissible_on_P_not_on_level_1(examples):
    ex = examples["cannon_001"]
    V = np.array([[0.1638, -0.3931], [0.6066, 0.6066]])
    K = ex.local_law
    np.testing.assert_array_equal(K, K_CANNON)
    np.testing.assert_array_equal(ex.info["V"], V)
    verts = _low_complexity_vertices(V, 0.9)
    assert ex.terminal.contains(verts, tol=1e-12).all()
    assert np.abs(verts @ K.T).max() <= ex.model.U.hi[0]
    verts1 = _low_complexity_vertices(V, 1.0)
    kmax = np.abs(verts1 @ K.T).max()
    assert kmax > 2.0
    assert kmax == pytest.approx(2.0002, abs=1e-4)  # thesis footnote of §4.2.6
    assert ex.info["terminal_not_admissible"].contains(verts1, tol=1e-12).all()


def test_cannon_terminal_is_scaled_low_complexity_polytope(examples):
    V = examples["cannon_001"].info["V"]
    H = examples["cannon"].terminal.A
    # rows 1, 3, 4 are 5 V / -5 V exactly; row 2 is printed -0.8199 instead of -0.8190
    np.testing.assert_allclose(H[[0, 2]], 5 * V, rtol=1e-12)
    np.testing.assert_allclose(H[3], -5 * V[1], rtol=1e-12)
    assert H[1, 0] == -0.8199
    np.testing.assert_array_equal(examples["cannon"].terminal.b, np.ones(4))
    for name in ("cannon_robust", "cannon_robust_wide"):
        np.testing.assert_array_equal(examples[name].terminal.A, H)


# ---------------------------------------------------------- E1 sliding domain
def _sliding_points(rng, k):
    c = rng.uniform(1.0, 2.0, k)
    x1 = rng.uniform(0.0, 1.0, k) * np.minimum(4.0, 4.0 / c) * rng.choice([-1.0, 1.0], k)
    return np.stack([x1, -c * x1], axis=1), c


def test_e1_terminal_is_the_sliding_domain(examples):
    ex = examples["linear_sliding"]
    S = ex.terminal
    assert isinstance(S, cm.PolytopeUnion) and len(S) == 2
    rng = np.random.default_rng(3)
    pts, _ = _sliding_points(rng, 500)
    assert S.contains(pts, tol=1e-12).all()
    # membership by definition on a grid: some c in [1, 2] with c x1 + x2 = 0, box 4
    g = np.linspace(-5, 5, 81)
    grid = np.array(list(itertools.product(g, g)))
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = -grid[:, 1] / grid[:, 0]
    by_def = ((ratio >= 1) & (ratio <= 2) & (np.abs(grid) <= 4).all(axis=1)) | (
        np.abs(grid).max(axis=1) == 0)
    np.testing.assert_array_equal(S.contains(grid), by_def)
    # convex hull: contains S, its vertices are in S, and it is strictly larger
    hull = ex.info["terminal_hull"]
    assert isinstance(hull, cm.Polytope)
    assert hull.contains(grid[by_def]).all()
    hull_vertices = np.array([[2, -4], [4, -4], [-2, 4], [-4, 4]], dtype=float)
    assert S.contains(hull_vertices).all() and hull.contains(hull_vertices).all()
    assert hull.contains([1.0, 0.0]) and not S.contains([1.0, 0.0])
    assert not hull.contains([[4.1, -4.0], [0.0, 4.1], [1.1, 0.0]]).any()


def test_e1_equivalent_control_keeps_the_sliding_domain(examples):
    ex = examples["linear_sliding"]
    cl = ex.model.closed_loop(ex.local_law)
    law = ca.Function("law", [ex.model.x], [ex.local_law])
    rng = np.random.default_rng(4)
    pts, c = _sliding_points(rng, 400)
    nxt = cl.step(pts)
    assert ex.terminal.contains(nxt, tol=1e-12).all()
    # the same line c x1 + x2 = 0 is kept and x1 contracts by 0.9 - 0.1 c
    np.testing.assert_allclose(c * nxt[:, 0] + nxt[:, 1], 0.0, atol=1e-12)
    np.testing.assert_allclose(nxt[:, 0], (0.9 - 0.1 * c) * pts[:, 0], rtol=1e-12, atol=1e-15)
    u = np.asarray(law.map(len(pts))(pts.T)).ravel()
    assert np.abs(u).max() <= 1.0 + 1e-12  # within |u| <= 2
    # the law equals the fixed-c equivalent control on each line
    from casadi_cmpc.models.linear_sliding import equivalent_control_gain

    for ci, xi, ui in zip(c[:20], pts[:20], u[:20], strict=True):
        assert ui == pytest.approx((equivalent_control_gain(ci) @ xi)[0], abs=1e-12)
    assert float(law([0.0, 0.0])) == 0.0
    # the linear alternative of info also maps S into S
    nxt_lin = ex.model.closed_loop(ex.info["local_gain"]).step(pts)
    assert ex.terminal.contains(nxt_lin, tol=1e-12).all()


# ------------------------------------------- E11 / E12 chosen terminal sets
def _dlqr_gain(A, B, Q, R):
    control = pytest.importorskip("control")
    K, _, _ = control.dlqr(A, B, Q, R)
    return -np.asarray(K)


@pytest.mark.parametrize("name", ["khalil_affine_state", "khalil_affine_control"])
def test_khalil_local_gain_is_the_recorded_lqr(examples, name):
    ex = examples[name]
    A0 = np.asarray(ex.model.jacobian_function("x")(np.zeros(2), 0.0, np.zeros(ex.model.l)))
    B0 = np.asarray(ex.model.jacobian_function("u")(np.zeros(2), 0.0, np.zeros(ex.model.l)))
    np.testing.assert_allclose(A0, [[1.0, 0.1], [0.0, 1.0]])
    np.testing.assert_allclose(B0, [[0.0], [0.1]])
    ch = ex.info["choices"]
    K = _dlqr_gain(A0, B0, ch["lqr_Q"], ch["lqr_R"])
    np.testing.assert_allclose(ex.local_law, K, atol=5e-5)
    assert "proven robustly invariant" in ch["terminal_status"]


def _polytope_vertices_2d(P):
    verts = []
    for i, j in itertools.combinations(range(P.A.shape[0]), 2):
        M = P.A[[i, j]]
        if abs(np.linalg.det(M)) < 1e-12:
            continue
        v = np.linalg.solve(M, P.b[[i, j]])
        if P.contains(v, tol=1e-9):
            verts.append(v)
    return np.array(verts)


@pytest.mark.parametrize("name", ["khalil_affine_state", "khalil_affine_control"])
def test_khalil_terminal_sampled_robust_invariance(examples, name):
    ex = examples[name]
    model, T, K = ex.model, ex.terminal, ex.local_law
    verts = _polytope_vertices_2d(T)
    assert len(verts) == 4
    assert model.X.contains(verts).all()
    assert np.abs(verts @ K.T).max() <= 0.9 * model.U.hi[0]
    # sample T (interior and boundary) and every vertex of W
    rng = np.random.default_rng(5)
    lam = rng.dirichlet(np.ones(4), 3000)
    pts = [lam @ verts, verts]
    for a, b in zip(T.A, T.b, strict=True):  # points on every facet
        ends = verts[np.abs(verts @ a - b) < 1e-9]
        assert len(ends) == 2
        t = rng.random(500)[:, None]
        pts.append(t * ends[[0]] + (1 - t) * ends[[1]])
    pts = np.vstack(pts)
    cl = model.closed_loop(K)
    worst = -np.inf
    for w in cm.Box(model.W.lo, model.W.hi).vertices():
        nxt = cl.step(pts, w=w)
        worst = max(worst, float((nxt @ T.A.T - T.b).max()))
    assert worst < -0.03  # every facet contracts by more than 3 % in the samples


# ------------------------------------------------------------------ Polytope
def test_polytope_basic():
    P = cm.Polytope([[1, 0], [-1, 0], [0, 1], [0, -1]], [1, 2, 3, 4])
    assert P.dim == 2 and P.A.shape == (4, 2) and P.b.shape == (4,)
    assert P.A.dtype == float and P.b.dtype == float
    assert P.contains([0.0, 0.0]) is True
    assert P.contains([1.5, 0.0]) is False
    res = P.contains([[1.0, 3.0], [-2.0, -4.0], [1.0 + 1e-9, 0.0], [0.0, -4.1]])
    assert isinstance(res, np.ndarray) and res.dtype == bool
    np.testing.assert_array_equal(res, [True, True, False, False])
    assert P.contains([1.0 + 1e-9, 0.0], tol=1e-8)
    assert not P.contains([1.0 + 1e-7, 0.0], tol=1e-8)
    assert "Polytope" in repr(P) and "dim=2" in repr(P)
    with pytest.raises(ValueError):
        P.A[0, 0] = 5.0  # read-only


def test_polytope_copies_its_data():
    A = np.array([[1.0, 0.0]])
    b = np.array([1.0])
    P = cm.Polytope(A, b)
    A[0, 0] = -1.0
    b[0] = -5.0
    assert P.contains([0.5, 0.0])


def test_polytope_one_dimensional_points():
    P = cm.Polytope([[1.0], [-1.0]], [1.0, 1.0])
    np.testing.assert_array_equal(P.contains([[0.0], [2.0]]), [True, False])
    np.testing.assert_array_equal(P.contains(np.array([0.0, 2.0, -1.0])), [True, False, True])


def test_polytope_validation():
    with pytest.raises(DimensionError):
        cm.Polytope([1.0, 0.0], [1.0])  # A not 2-D
    with pytest.raises(DimensionError):
        cm.Polytope([[1.0, 0.0]], [[1.0]])  # b not 1-D
    with pytest.raises(DimensionError):
        cm.Polytope([[1.0, 0.0], [0.0, 1.0]], [1.0])  # rows differ
    with pytest.raises(DimensionError):
        cm.Polytope(np.zeros((1, 0)), [1.0])  # no column
    with pytest.raises(InvalidBoundsError):
        cm.Polytope([[np.nan, 0.0]], [1.0])
    with pytest.raises(InvalidBoundsError):
        cm.Polytope([[1.0, 0.0]], [np.nan])
    with pytest.raises(InvalidBoundsError):
        cm.Polytope([[np.inf, 0.0]], [1.0])
    P = cm.Polytope([[1.0, 0.0]], [1.0])
    with pytest.raises(DimensionError):
        P.contains([0.0, 0.0, 0.0])
    with pytest.raises(DimensionError):
        P.contains(np.zeros((3, 3)))
    # exceptions refine ValueError
    with pytest.raises(ValueError):
        cm.Polytope([[1.0, 0.0]], [1.0, 2.0])


def test_polytope_whole_space_and_infinite_rhs():
    P = cm.Polytope(np.zeros((0, 2)), np.zeros(0))
    assert P.dim == 2
    np.testing.assert_array_equal(P.contains([[1e9, -1e9], [0, 0]]), [True, True])
    Q = cm.Polytope([[1.0, 0.0], [0.0, 1.0]], [np.inf, 1.0])
    np.testing.assert_array_equal(Q.contains([[1e300, 0.0], [0.0, 2.0]]), [True, False])


def test_polytope_union():
    P1 = cm.Polytope([[1, 0], [-1, 0], [0, 1], [0, -1]], [1, 1, 1, 1])
    P2 = cm.Polytope([[1, 0], [-1, 0], [0, 1], [0, -1]], [4, -2, 1, 1])  # x1 in [2, 4]
    U = cm.PolytopeUnion([P1, P2])
    assert U.dim == 2 and len(U) == 2 and U.polytopes == (P1, P2)
    assert list(U) == [P1, P2]
    np.testing.assert_array_equal(U.contains([[0, 0], [3, 0], [1.5, 0], [5, 0]]),
                                  [True, True, False, False])
    assert U.contains([3.0, 0.0]) is True
    assert U.contains([1.5, 0.0]) is False
    assert U.contains([1.0 + 1e-9, 0.0], tol=1e-8)
    assert "PolytopeUnion" in repr(U)
    # built from any iterable
    assert len(cm.PolytopeUnion(p for p in (P1, P2))) == 2


def test_polytope_union_validation():
    P = cm.Polytope([[1.0, 0.0]], [1.0])
    with pytest.raises(ValueError):
        cm.PolytopeUnion([])
    with pytest.raises(TypeError):
        cm.PolytopeUnion([P, cm.Box([0, 0], [1, 1])])
    with pytest.raises(DimensionError):
        cm.PolytopeUnion([P, cm.Polytope([[1.0]], [1.0])])
    with pytest.raises(DimensionError):
        cm.PolytopeUnion([P]).contains([0.0, 0.0, 0.0])


def test_sets_are_exported():
    import casadi_cmpc.sets as sets

    assert "Polytope" in sets.__all__ and "PolytopeUnion" in sets.__all__
    assert cm.Polytope is sets.Polytope and cm.PolytopeUnion is sets.PolytopeUnion


@pytest.mark.parametrize("name, expected", [
    ("khalil_affine_state", True),      # w enters as x2+ = ... + w
    ("khalil_affine_control", False),   # p multiplies x2**2
    ("cannon_robust", False),           # mu multiplies x1 * u
    ("cstr", True),                     # no disturbance
])
def test_is_additive_in_w(name, expected):
    assert cm.models.load(name).model.is_additive_in_w is expected
