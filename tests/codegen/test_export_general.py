"""C export beyond the thesis examples: 3 and 4 states, two inputs, a non-zero equilibrium
(x_e, u_e), polytopic sequences, and the IPOPT variant.

Each test compares the compiled controller with the Python one that was exported: the same
level, the same control to 1e-6, and closed loops that match step by step under the same
random disturbance.
"""

from __future__ import annotations

import casadi as ca
import control
import numpy as np
import pytest

import casadi_cmpc as cm
from casadi_cmpc.codegen import load
from casadi_cmpc.codegen.export import can_build
from casadi_cmpc.mpc.sequence import SetSequenceMPC

pytestmark = pytest.mark.skipif(not can_build(),
                                reason="building the export needs make and a C compiler")

XE = np.array([0.5, -0.3, 0.2])
UE = np.array([0.1, -0.2])
A3 = np.array([[0.2, 1.0, 0.0], [0.0, 0.1, 1.0], [0.3, 0.0, -0.4]])


def three_state_model(w_form: str = "affine") -> cm.Model:
    """x+ = x + 0.1 (A dx + g(dx) + B(dx) du + e w), dx = x - x_e, du = u - u_e: a
    nonlinear model with its equilibrium at (x_e, u_e) != 0, affine in w. Other forms of
    the disturbance, whose range over W is not spanned by its vertices: ``"square"``
    (w + 20 w^2) and ``"jump"`` (w plus a step of 0.05 inside W, zero at both vertices)."""
    x = ca.SX.sym("x", 3)
    u = ca.SX.sym("u", 2)
    w = ca.SX.sym("w")
    if w_form == "square":
        w = w + 20 * w ** 2
    elif w_form == "jump":
        w = w + ca.if_else(ca.fabs(w) < 0.04, 0.05, 0.0)
    dx, du = x - ca.DM(XE), u - ca.DM(UE)
    g = ca.vertcat(0.3 * dx[1] ** 2, -0.2 * ca.sin(dx[0]) * dx[2], 0.1 * dx[0] * dx[1])
    B = ca.vertcat(ca.horzcat(1 + 0.2 * ca.cos(dx[1]), 0), ca.horzcat(0.1 * dx[0], 1),
                   ca.horzcat(0, 0.8 + 0.1 * dx[2] ** 2))
    f = x + 0.1 * (ca.mtimes(ca.DM(A3), dx) + g + ca.mtimes(B, du)
                   + ca.DM([0.5, 0.3, -0.2]) * w)
    return cm.Model(x=x, u=u, w=ca.symvar(w)[0], f=f, X=cm.Box(XE - 0.6, XE + 0.6),
                    U=cm.Box(UE - 1.0, UE + 1.0), W=cm.Box([-0.05], [0.05]),
                    name="three_state_export")


def lqr_law(model: cm.Model, A: np.ndarray, B: np.ndarray, xe: np.ndarray,
            ue: np.ndarray) -> ca.SX:
    """u = u_e + K (x - x_e), K the discrete LQR gain (Q = I, R = I) of (A, B)."""
    K, _, _ = control.dlqr(A, B, np.eye(A.shape[0]), np.eye(B.shape[1]))
    return ca.DM(ue) - ca.mtimes(ca.DM(np.asarray(K)), model.x - ca.DM(xe))


@pytest.fixture(scope="module")
def tri(tmp_path_factory):
    model = three_state_model()
    Ad = np.eye(3) + 0.1 * A3
    Bd = 0.1 * np.array([[1.2, 0.0], [0.0, 1.0], [0.0, 0.8]])
    law = lqr_law(model, Ad, Bd, XE, UE)
    T = cm.Polytope.from_box(cm.Box(XE - 0.15, XE + 0.15))
    cert = cm.certify_invariant(model, T, law, 0.02, progress=False)
    assert cert.label == "proved"
    seq = cm.controllable_sets(model, T, 0.1, robust=True, certificate=cert, law=law,
                               max_steps=2, progress=False)
    ctrl = SetSequenceMPC(model, seq, Q=np.eye(3), R=0.1 * np.eye(2), x_ref=XE,
                          local_law=law, solver="sqp", robust=True)
    info = ctrl.export_c(tmp_path_factory.mktemp("tri") / "c", steps=10)
    return model, seq, ctrl, load(info.directory)


def sample_levels(seq, rng, k):
    """k random states of the proven boxes and of T."""
    B = np.concatenate([s["boxes"] for s in seq.steps])
    P = rng.uniform(B[:, :, 0], B[:, :, 1])[rng.choice(len(B), k)]
    return P


def test_three_states_two_inputs_nonzero_equilibrium_agree(tri):
    model, seq, ctrl, C = tri
    rng = np.random.default_rng(3)
    pts = sample_levels(seq, rng, 300)
    pts[:30] = XE + rng.uniform(-0.15, 0.15, (30, 3))
    levels = set()
    for x in pts:
        r = ctrl.solve(x)
        u, code = C.step(x)
        assert C.decode(code)["level"] == r.horizon == C.level(x) == seq.level(x)
        assert np.abs(u - r.u).max() <= 1e-6, (x, r.u, u, hex(code))
        levels.add(r.horizon)
        # the compiled model is the Python model
        w = rng.uniform(-0.05, 0.05, 1)
        assert np.allclose(C.model(x, u, w), model.step(x, u, w), rtol=0, atol=1e-14)
    assert levels == {0, 1, 2}
    # at the equilibrium the local law gives u_e
    u, code = C.step(XE)
    assert code == 0 and np.allclose(u, UE, atol=1e-14)


def test_three_state_closed_loop_matches_step_by_step(tri):
    model, seq, ctrl, C = tri
    rng = np.random.default_rng(5)
    B = seq.steps[-1]["boxes"]
    c = 0.5 * (B[..., 0] + B[..., 1])
    c = c[np.array([seq.level(q) == 2 for q in c])]
    x = xc = c[np.argmax(np.abs(c - XE).sum(axis=1))]
    seen = []
    for _ in range(30):
        r = ctrl.solve(x)
        u, code = C.step(xc)
        assert np.abs(u - r.u).max() <= 1e-6
        assert C.decode(code)["level"] == r.horizon
        seen.append(r.horizon)
        w = rng.uniform(-0.05, 0.05, 1)
        x, xc = model.step(x, r.u, w), C.model(xc, u, w)
    # the level decreases to 0 (T) and stays there
    assert seen[0] == 2 and seen[-1] == 0 and all(np.diff(seen[:seen.index(0) + 1]) < 0)


def test_polytopic_sequence_agrees(tmp_path):
    """E10's model with polytopic sets: the C level look-up through the exported
    H-representations and the successor test against polytopes."""
    ex = cm.models.load("cannon_robust_wide")
    seq = cm.controllable_sets(ex.model, ex.terminal, 0.05, robust=True, polytopic=True,
                               law=ex.local_law, max_steps=2, progress=False)
    ctrl = SetSequenceMPC(ex.model, seq, local_law=ex.local_law, solver="sqp", robust=True)
    assert ctrl._polytopic
    info = ctrl.export_c(tmp_path / "c")
    assert info.tables["polytopes"] >= 2
    C = load(info.directory)
    rng = np.random.default_rng(8)
    pts = rng.uniform(ex.model.X.lo, ex.model.X.hi, (400, 2))
    lv = np.array([seq.level(p) for p in pts], dtype=object)
    pts = np.vstack([pts[[v is not None for v in lv]][:150], pts[:40]])
    levels = set()
    for x in pts:
        r = ctrl.solve(x)
        u, code = C.step(x)
        assert C.level(x) == (-1 if r.horizon is None else r.horizon)
        if r.horizon is None:
            assert code == -1
            continue
        levels.add(r.horizon)
        assert C.decode(code)["level"] == r.horizon
        assert np.abs(u - r.u).max() <= 1e-6, (x, r.u, u, hex(code))
    assert {0, 1, 2} <= levels


def contractive_models():
    """A 3-state and a 4-state model with a non-zero equilibrium and two inputs."""
    out = []
    m3 = three_state_model()
    out.append((m3, XE, UE))
    xe4, ue4 = np.array([1.0, -0.5, 0.3, 0.0]), np.array([0.2, 0.4])
    x = ca.SX.sym("x", 4)
    u = ca.SX.sym("u", 2)
    dx, du = x - ca.DM(xe4), u - ca.DM(ue4)
    f = x + 0.1 * ca.vertcat(dx[1] + 0.1 * dx[2] ** 2, -0.3 * ca.sin(dx[0]) + du[0],
                             dx[3] - 0.2 * dx[2], 0.2 * dx[0] * dx[1] - 0.1 * dx[3] + du[1])
    m4 = cm.Model(x=x, u=u, f=f, X=cm.Box(xe4 - 2.0, xe4 + 2.0), U=cm.Box(ue4 - 3, ue4 + 3),
                  name="four_state_export")
    out.append((m4, xe4, ue4))
    return out


@pytest.mark.parametrize("k, shooting, norm", [
    (0, "multiple", 2), (0, "single", 2), (1, "multiple", 2), (0, "multiple", 1),
    (1, "single", 1), (1, "multiple", np.inf)],
    ids=["3-state", "3-state-single-shooting", "4-state", "3-state-norm-1",
         "4-state-single-norm-1", "4-state-norm-inf"])
def test_contractive_nonzero_reference_closed_loop_matches(k, shooting, norm, tmp_path):
    model, xe, ue = contractive_models()[k]
    ctrl = cm.ContractiveMPC(model, horizon=6, alpha=0.9, x_ref=xe, u_ref=ue, solver="sqp",
                             mode="receding",
                             R=0.1 * np.eye(2), shooting=shooting, norm=norm)
    info = ctrl.export_c(tmp_path / "c", x0=xe + 0.3)
    C = load(info.directory)
    rng = np.random.default_rng(k)
    ws = rng.uniform(-0.05, 0.05, 40) if model.l else None
    x = xc = xe + 0.3 * np.sign(rng.standard_normal(model.n))
    ctrl.reset()
    compared = 0
    for i in range(40):
        r = ctrl.solve(x)
        u, code = C.step(xc)
        if "search_time" in r.stats:  # a set inversion (Python only): stop comparing
            break
        assert np.abs(u - r.u).max() <= 1e-6, (i, x, r.u, u, hex(code))
        compared += 1
        w = None if ws is None else ws[i:i + 1]
        x, xc = model.step(x, r.u, w), C.model(xc, u, w)
    assert compared >= 20
    assert np.linalg.norm(x - xe) < 0.5 * np.linalg.norm(0.3 * np.ones(model.n))


def test_ipopt_variant_builds_and_agrees(tri, tmp_path):
    """solver='ipopt': the generated C calls the IPOPT library shipped in the casadi wheel
    (include and link flags from the installed casadi); it agrees with the Python
    controller that uses IPOPT."""
    model, seq, _, _ = tri
    ctrl = SetSequenceMPC(model, seq, Q=np.eye(3), R=0.1 * np.eye(2), x_ref=XE,
                          local_law=tri[2]._law(model.x), solver="ipopt", robust=True)
    info = ctrl.export_c(tmp_path / "c", solver="ipopt")
    mk = (info.directory / "Makefile").read_text()
    assert "-lipopt" in mk and "-I" in mk
    C = load(info.directory)
    rng = np.random.default_rng(9)
    n = 0
    for x in sample_levels(seq, rng, 60):
        r = ctrl.solve(x)
        u, code = C.step(x)
        assert C.decode(code)["level"] == r.horizon
        if r.horizon:
            n += 1
            assert np.abs(u - r.u).max() <= 1e-6, (x, r.u, u, hex(code))
    assert n >= 40


# the controllers below run a sequence computed for another form of the model (on purpose:
# only the export's refusal is under test), which they say in a warning
@pytest.mark.filterwarnings("ignore:the sequence was computed for model")
def test_a_robust_controller_of_a_model_not_affine_in_w_is_refused(tri, tmp_path):
    """The C check evaluates the vertices of W: for a model not affine in w they do not
    bound the image (here the worst w is inside W), so the export is refused whichever
    minimax the controller uses."""
    from casadi_cmpc.codegen.export import ExportError
    from casadi_cmpc.exceptions import UnsupportedOperationError

    seq = tri[1]
    for form in ("square", "jump"):
        model = three_state_model(form)
        assert not model.is_affine_in_w
        for mm in ("vertices", "interval"):
            if form == "jump" and mm == "interval":  # the minimax needs continuity
                with pytest.raises(UnsupportedOperationError, match="jump"):
                    SetSequenceMPC(model, seq, x_ref=XE, local_law=tri[2]._law(model.x),
                                   solver="sqp", robust=True, minimax=mm)
                continue
            ctrl = SetSequenceMPC(model, seq, x_ref=XE, local_law=tri[2]._law(model.x),
                                  solver="sqp", robust=True, minimax=mm)
            with pytest.raises(ExportError, match="affine in w|minimax"):
                ctrl.export_c(tmp_path / (form + mm))
            assert not (tmp_path / (form + mm)).exists()
    model = three_state_model("square")
    # the nominal controller of the same model checks one w: it is exported
    ctrl = SetSequenceMPC(model, seq, x_ref=XE, local_law=tri[2]._law(model.x),
                          solver="sqp", robust=False)
    assert ctrl.export_c(tmp_path / "nominal").kind == "set_sequence"


def test_the_solver_answer_is_the_minimax_point(tri):
    """Where the applied control is the solver's, it minimises the worst vertex cost over U:
    no grid point of U does better. (A start whose multipliers do not match the active
    rows lets sqpmethod stop at once at the minimiser of the mean cost.)"""
    model, seq, ctrl, _ = tri
    rng = np.random.default_rng(12)
    g = np.linspace(-1.0, 1.0, 161)
    G = np.stack(np.meshgrid(g, g, indexing="ij"), -1).reshape(-1, 2) + UE
    wv = np.asarray(model.W.vertices())
    F = model.function.map(G.shape[0])

    def worst(x, U):
        c = [np.einsum("ij,ij->j", (d := np.asarray(F(np.repeat(x[:, None], len(U), 1), U.T,
                                                          np.repeat(w[:, None], len(U), 1)))
                                     - XE[:, None]), d) + 0.1 * (U ** 2).sum(1)
             for w in wv]
        return np.max(c, axis=0)

    n = 0
    for x in sample_levels(seq, rng, 120):
        r = ctrl.solve(x)
        if not r.horizon or r.certificate.details.get("source") != "solver":
            continue
        n += 1
        best = worst(x, G).min()
        assert worst(x, r.u[None])[0] <= best + 1e-9, (x, r.u)
    assert n >= 20


def test_converged_polytopic_sequence_keeps_its_polytopes(tri, tmp_path):
    """A polytopic sequence that converges (its last step proves no new box) has
    K_last = K_{last-1}, still held by polytopes: the controller and its C export use the
    polytopes, and C and Python agree on the levels of 3-state points."""
    model, _, ctrl0, _ = tri
    T = cm.Polytope.from_box(cm.Box(XE - 0.15, XE + 0.15))
    law = ctrl0._law(model.x)
    seq = cm.controllable_sets(model, T, 0.1, robust=True, polytopic=True, law=law,
                               assume_invariant=True, max_steps=6, progress=False)
    assert seq.status == "converged"
    assert seq.sets[-1] is seq.sets[-2]
    ctrl = SetSequenceMPC(model, seq, Q=np.eye(3), R=0.1 * np.eye(2), x_ref=XE,
                          local_law=law, solver="sqp", robust=True)
    assert ctrl._polytopic
    info = ctrl.export_c(tmp_path / "c")
    assert info.tables["polytopes"] >= 1
    C = load(info.directory)
    rng = np.random.default_rng(4)
    pts = np.vstack([rng.uniform(model.X.lo, model.X.hi, (200, 3)),
                     sample_levels(seq, rng, 400)])
    n = 0
    for x in pts:
        lv = seq.level(x)
        assert C.level(x) == (-1 if lv is None else lv), x
        if lv:
            r = ctrl.solve(x)
            u, code = C.step(x)
            assert C.decode(code)["level"] == r.horizon == lv
            assert np.abs(u - r.u).max() <= 1e-6, (x, r.u, u, hex(code))
            n += 1
    assert n >= 50
