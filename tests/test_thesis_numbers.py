"""The numbers ``benchmarks/reproduce_thesis.py`` prints, checked at coarse settings.

Each test runs the script's function of one example (its ``--quick`` settings, or coarser)
and checks what it prints against a fact computed another way: known values (the E1
pre-set levels, the E2 box counts, the E5 bound 2.0002 from the vertices of |Vx| <= 1),
sampled states replayed through the model (the controllable sets of E8/E9, the polytopes
P1 of E10/E14, the zonotope of E6, the polytopes of E11/E12), the vertices of T against P1
(E10), Monte Carlo estimates of areas (E4, E11, E12), and the steps of convergence at a
coarse eps (stable there). The E11 closed loop from (-0.5, -0.8) (eps 0.05) is asserted in
notebooks/11_structured.ipynb, the E12 closed loops in tests/mpc/test_quasi_mpc.py.
Algorithms already tested on the same example elsewhere are not tested again here.
"""

from __future__ import annotations

import importlib.util
import itertools
import json
import sys
from pathlib import Path

import numpy as np
import pytest

import casadi_cmpc as cm

_PATH = Path(__file__).resolve().parents[1] / "benchmarks" / "reproduce_thesis.py"


@pytest.fixture(scope="module")
def rt():
    spec = importlib.util.spec_from_file_location("reproduce_thesis", _PATH)
    mod = importlib.util.module_from_spec(spec)
    sys.modules["reproduce_thesis"] = mod
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture(scope="module")
def quick(rt):
    return dict(rt.SETTINGS["quick"])


def _in_boxes(B: np.ndarray, P: np.ndarray) -> np.ndarray:
    """Points of P (k, n) inside some box of B (N, n, 2)."""
    return ((B[None, :, :, 0] <= P[:, None]) & (P[:, None] <= B[None, :, :, 1])).all(
        axis=2).any(axis=1)


def _poly_points(P: cm.Polytope, k: int, rng: np.random.Generator) -> np.ndarray:
    bb = P.bounding_box()
    X = rng.uniform(bb.lo, bb.hi, (20 * k, P.dim))
    return X[np.asarray(P.contains(X, tol=-1e-9), dtype=bool)][:k]


# ------------------------------------------------------------------- the script itself
def test_the_script_prints_one_json_line_and_marks_missing_pipelines(rt, capsys, monkeypatch):
    monkeypatch.setitem(rt.EXAMPLES, "E99", lambda s: rt._not_reproduced(
        {"claim": "x"}, "no pipeline for it"))
    assert rt.main(["--quick", "--only", "e4,E99"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert len(lines) == 1
    d = json.loads(lines[0])
    assert d["mode"] == "quick" and set(d["examples"]) == {"E4", "E99"}
    assert d["examples"]["E99"]["ours"] == "not reproduced: no pipeline for it"
    assert d["examples"]["E99"]["agree"] is None
    assert d["agree"] == ["E4"] and d["not_compared"] == ["E99"]
    assert all(not k.startswith("_") for v in d["examples"].values() for k in v)
    assert not any(v["ours"] == "not reproduced" or str(v["ours"]).startswith("not reproduced")
                   for k, v in d["examples"].items() if k != "E99")
    with pytest.raises(SystemExit):
        rt.main(["--only", "E98"])


# ----------------------------------------------------------------------------- E1-E5
def test_e1_numbers(rt, quick):
    res = rt.e1(quick)
    o = res["ours"]
    assert res["agree"] is True
    # K_4 is the first pre-set holding both thesis states (tests/control/test_linear_sets
    # checks the sets against their definition)
    assert o["pre_sets"] == 4 and o["levels_of_x0s"] == [4, 4]
    for run in o["fig_3_2_contractive_lp"] + o["fig_3_4_one_step_lp"]:
        assert run["unverified"] == 0 and run["violations"] == 0
        assert run["final_abs"] < 1e-2
    # along the pre-sets one set per step: S is entered at step 4 exactly
    assert [r["enters_S_at"] for r in o["fig_3_4_one_step_lp"]] == [4, 4]


def test_e2_counts_and_tiling(rt, quick):
    res = rt.e2(quick)
    o = res["ours"]
    assert (o["inner"], o["boundary"], o["outside"]) == (55, 83, 46)
    assert o["status"] == "PROVED" and res["agree"] is None
    # inner + boundary + outside tile P = [-3, 9]^2 (area 144); inner boxes have area
    # 0.75^2 / 2^k: the inner area is a multiple of 0.75^2 / 4
    assert 0 < o["inner_area"] < 144 - o["boundary_area"]
    assert (o["inner_area"] / (0.75 ** 2 / 4)) % 1 == 0


def test_e3_bracket_holds_the_minimum_and_the_point(rt, quick):
    res = rt.e3(quick)
    o = res["ours"]
    assert res["agree"] is True and o["lower"] <= 0.0 <= o["upper"] < 1e-8
    x, y = o["x"]
    fx = (x - np.sin(2 * x + 3 * y) - np.cos(3 * x - 5 * y)) ** 2 \
        + (y - np.sin(x - 2 * y) + np.cos(x + 3 * y)) ** 2
    assert fx <= o["upper"] + 1e-15


def test_e4_overlap_area_matches_a_monte_carlo_estimate(rt, quick):
    res = rt.e4(quick)
    o = res["ours"]
    assert res["agree"] is True and o["vertices"] == 12
    H = np.array([[0.4414, -0.5855, -0.0484, 0.2570, 0.2293, 0.1498],
                  [-0.0016, -0.3930, 0.3526, -0.2396, 0.4257, -0.3117]])
    Z = cm.Zonotope([2.0, 2.0], H)
    L, R = Z.bisect()
    bb = Z.bounding_box()
    rng = np.random.default_rng(4)
    pts = bb.sample(40000, rng)
    both = np.asarray(L.contains(pts)) & np.asarray(R.contains(pts))
    est = both.mean() * bb.volume()
    assert abs(est - o["redundant_halves_overlap_area"]) < 0.1
    assert abs(Z.volume() - o["area"]) < 1e-6


def test_e5_bound_of_the_input_on_the_larger_level_set(rt, quick):
    res = rt.e5(quick)
    o = res["ours"]
    assert res["agree"] is True
    assert (o["level_0.9"], o["level_1.0"]) == ("proved", "refuted")
    ex = cm.models.load("cannon_001")
    V, K = ex.info["V"], ex.local_law
    corners = np.array(list(itertools.product((-1.0, 1.0), repeat=2)))
    verts = np.linalg.solve(V, corners.T).T  # vertices of |V x|_inf <= 1
    assert o["max_abs_Kx_level_1.0"] == pytest.approx(np.abs(verts @ K.T).max(), abs=1e-5)
    assert o["max_abs_Kx_level_1.0"] > 2.0


# ----------------------------------------------------------------------------- E6, E7
def test_e6_found_zonotope_is_invariant_on_samples(rt, quick):
    res = rt.e6(quick)
    o = res["ours"]
    assert res["agree"] is True and o["certificate"] == "proved"
    assert o["area"] >= res["thesis"]["area"] - 1e-12
    Z = res["_objects"]["result"].zonotope
    ex = cm.models.load("cstr")
    rng = np.random.default_rng(6)
    X = Z.center + rng.uniform(-1, 1, (2000, Z.n_generators)) @ Z.generators.T
    u = X @ ex.local_law.T
    assert ex.model.U.contains(u).all() and Z.contains(ex.model.step(X, u)).all()


def test_e7_and_e13_closed_loops(rt, quick):
    r7 = rt.e7(quick)
    assert r7["agree"] is True and r7["ours"]["final_abs"] < 1e-3
    assert r7["ours"]["horizons"] == [2]
    r13 = rt.e13(quick)
    assert r13["agree"] is True
    assert r13["ours"]["min_obstacle_distance"] >= r13["ours"]["D"]


# ----------------------------------------------------------------------------- E8, E9
def _replay_last_steps(seq, model, ws, rng, last=6):
    """States of the boxes of the last steps, under their stored controls and every w in ws,
    land in a smaller level."""
    for i in range(max(1, len(seq.steps) - last), len(seq.steps) + 1):
        st = seq.steps[i - 1]
        B = st["boxes"]
        if B.shape[0] == 0:
            continue
        k = rng.integers(0, B.shape[0], 200)
        X = rng.uniform(B[k, :, 0], B[k, :, 1])
        for w in ws:
            W = None if w is None else np.broadcast_to(w, (X.shape[0], model.l))
            lv = seq.level(model.step(X, st["witness"][k], W))
            assert ((lv >= 0) & (lv <= i - 1)).all(), i


def test_e8_step_of_convergence_at_eps_0_1(rt, quick):
    assert quick["e8_eps"] == 0.1
    res = rt.e8(quick)
    o = res["ours"]
    seq = res["_objects"]["seq"]
    assert o["converged"] and o["terminal_certificate"] == "proved"
    assert o["last_step_with_new_boxes"] == 32  # thesis (eps 0.05): 41
    assert seq.steps[32]["boxes"].shape[0] == 0 and seq.steps[31]["boxes"].shape[0] > 0
    assert o["boxes_per_step_last_8"] == [int(st["boxes"].shape[0]) for st in seq.steps[24:32]]
    assert res["agree"] is False and "coarser than the thesis' 0.05" in res["why"]
    assert o["closed_loop_ok"] and o["closed_loop_final_abs"] < 1e-2
    ex = cm.models.load("cannon")
    _replay_last_steps(seq, ex.model, [None], np.random.default_rng(8))


def test_e9_step_of_convergence_at_eps_0_1(rt, quick):
    assert quick["e9_eps"] == 0.1
    res = rt.e9(quick)
    o = res["ours"]
    seq = res["_objects"]["seq"]
    assert o["converged"] and o["terminal_certificate"] == "proved"
    assert o["semantics"] == "exists u for all w"
    assert o["last_step_with_new_boxes"] == 30  # thesis (eps 0.05): K48 = K49
    assert all(o["closed_loops_ok"]) and max(o["closed_loop_final_abs"]) < 1e-2
    ex = cm.models.load("cannon_robust")
    rng = np.random.default_rng(9)
    ws = list(np.asarray(ex.model.W.vertices())) + list(ex.model.W.sample(2, rng))
    _replay_last_steps(seq, ex.model, ws, rng)


# ---------------------------------------------------------------------------- E10, E14
def test_e10_terminal_set_in_p1_at_0_025_not_at_0_05(rt, quick):
    assert tuple(quick["e10_eps"]) == (0.025, 0.05)
    res = rt.e10(quick)
    o = res["ours"]
    assert res["agree"] is True
    assert o["eps_0.025"]["T_in_P1"] is True and o["eps_0.05"]["T_in_P1"] is False
    T = cm.models.load("cannon_robust_wide").terminal
    VT = np.asarray(T.vertices())
    rng = np.random.default_rng(10)
    for eps, (r, P1) in res["_objects"].items():
        slack = (P1.b[None] - VT @ P1.A.T).min(axis=1)  # >= 0: the vertex is in P1
        if eps == 0.025:
            assert (slack > -1e-9).all()
        else:
            assert (slack < -1e-6).any()  # a vertex of T clearly outside P1
        X = _poly_points(P1, 500, rng)
        assert len(X) > 100 and _in_boxes(r.paving.inner, X).all()  # P1 ⊆ K1 (inner)
        assert o[f"eps_{eps}"]["P1_area"] <= o[f"eps_{eps}"]["K1_area"] + 1e-12


def test_e14_polytope_and_closed_loop(rt, quick):
    res = rt.e14(quick)
    o = res["ours"]
    obj = res["_objects"]
    assert res["agree"] is True and o["P1_certificate"] == "proved"
    assert o["T_area"] == pytest.approx(0.008, rel=1e-3)  # (7.10): the zonotope of E6
    assert o["P1_area"] <= o["K1_area"] and o["level_of_x0"] >= 1
    rng = np.random.default_rng(14)
    X = _poly_points(obj["P1"], 400, rng)
    assert _in_boxes(obj["K1"].paving.inner, X).all()
    tr = obj["traj"]
    ex = cm.models.load("cstr")
    assert np.abs(tr.x[-1] - ex.info["mpc"]["x_ref"]).max() < 1e-3
    assert o["final_C_A_mol_per_l"] == pytest.approx(0.5, abs=1e-2)


# ---------------------------------------------------------------------------- E11, E12
def _mc_area(inside, box: cm.Box, k: int, rng: np.random.Generator) -> float:
    """Monte Carlo estimate of the area of ``{x in box : inside(x)}``."""
    X = rng.uniform(box.lo, box.hi, (k, box.dim))
    return float(np.asarray(inside(X), dtype=bool).mean() * box.volume())


def test_e11_maximal_set_and_fig_6_7_at_eps_0_1(rt, quick):
    assert quick["e11_eps"] == 0.1 and quick["e11_method"] == "separating"
    res = rt.e11(quick)
    o, obj = res["ours"], res["_objects"]
    seq = obj["seq"]
    assert o["status"] == "converged" and o["terminal_certificate"] == "proved"
    assert o["maximal_set_at"] == 4  # thesis (its eps and T unknown): P39 = P40
    assert res["agree"] is False and "the thesis at P39 = P40" in res["why"]
    vols = [S.volume() for S in seq.sets]
    assert o["areas_last_4"] == [round(v, 4) for v in vols[-4:]]
    assert vols[5] <= vols[4] * (1 + 1e-3) and all(b > a * (1 + 1e-3) for a, b in
                                                    zip(vols[:4], vols[1:5], strict=True))
    rng = np.random.default_rng(11)
    ex = cm.models.load("khalil_affine_state")
    X = ex.model.X
    assert _mc_area(seq.sets[-2].contains, X, 40000, rng) == pytest.approx(vols[-2], abs=0.03)
    assert _mc_area(obj["K1"].contains, X, 40000, rng) == pytest.approx(o["K1_area"], abs=0.03)
    # Fig 6.7: both polytopes lie in the union of the pieces and T, their areas as printed
    for meth, P in obj["fig_6_7"].items():
        assert o["fig_6_7"][meth]["area"] == pytest.approx(P.volume(), abs=1e-6)
        Y = _poly_points(P, 500, rng)
        assert len(Y) > 100
        assert (obj["K1"].contains(Y) | np.asarray(ex.terminal.contains(Y), bool)).all()
    assert o["level_of_x0"] is None and "lies in no set" in o["closed_loops"]


def test_e12_maximal_quasi_set_and_fig_6_13_at_eps_0_1(rt, quick):
    assert quick["e12_eps"] == 0.1
    res = rt.e12(quick)
    o, obj = res["ours"], res["_objects"]
    seq = obj["seq"]
    ex = cm.models.load("khalil_affine_control")
    assert o["status"] == "converged" and o["Omega_invariance"] == "proved"
    assert o["maximal_set_at"] == 1  # thesis (its eps and Omega unknown): P20 = P21
    assert res["agree"] is False and "the thesis at P20 = P21" in res["why"]
    assert o["areas_last_4"][0] == round(ex.terminal.volume(), 4)
    assert o["areas_last_4"] == [round(P.volume(), 4) for P in seq.polytopes[-4:]]
    rng = np.random.default_rng(12)
    # the printed areas, estimated by sampling; each polytope inside its proven boxes
    assert _mc_area(seq.polytopes[1].contains, ex.model.X, 40000, rng) == pytest.approx(
        o["areas_last_4"][1], abs=0.03)
    cmp_ = obj["comparison"]
    for (r, P), key in ((cmp_["one_step"][-1], "two_quasi_1_step_polytope_area"),
                        (cmp_["multi_step"], "quasi_2_step_polytope_area")):
        assert o["fig_6_13"][key] == pytest.approx(P.volume(), abs=1e-6)
        Y = _poly_points(P, 400, rng)
        assert len(Y) > 100 and r.contains(Y).all()
    # Omega's proof: every sampled state of Omega has a cover box whose control keeps it in
    # Omega for the extreme (w, p)
    cover = obj["invariance"].details["cover"]
    for x in _poly_points(ex.terminal, 100, rng):
        k = cover.box_index(x)
        assert k is not None
        for w in np.asarray(ex.model.W.vertices()):
            assert ex.terminal.contains(ex.model.step(x, cover.controls[k, 0], w))
    assert o["levels_of_x0s"] == [None, None] and "no set" in o["closed_loops"]
