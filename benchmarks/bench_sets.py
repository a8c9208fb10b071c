"""Set-library throughput, with the `polytope` package (pip, benchmark-only) in the same run.

Prints one JSON line:
* box-in-polytope and box-intersects-polytope tests per second at batch 1e5 (2-D polytope with
  8 facets, 8-D polytope with 32 facets); box ⊆ union-of-10-polytopes tests per second;
* E1 (thesis §3.4) pre-set recursion time until both thesis initial states are inside;
* exact projection of the 8-D / 32-facet polytope to 2-D (ours), and `polytope`'s projection of
  the same input (run in a child process with a time limit: FACTS.md reports > 60 s);
* `polytope`'s box ⊆ polytope test (one `is_subset` per box) and point containment, as ratios.

Targets (issue): >= 1e7 box-in-polytope tests/s; our projection faster than `polytope`'s.
"""

from __future__ import annotations

import json
import multiprocessing as mp
import sys
import time

import numpy as np
from _timing import median_time as _timeit

import casadi_cmpc as cm

TIME_LIMIT = 60.0




def random_polytope(n: int, k: int, seed: int) -> cm.Polytope:
    """k facets tangent to the unit sphere in random normal directions (bounded for k >> n)."""
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(k, n))
    A /= np.linalg.norm(A, axis=1, keepdims=True)
    P = cm.Polytope(A, np.ones(k))
    if not P.is_bounded():
        raise RuntimeError("choose another seed: the random polytope is unbounded")
    return P


def random_boxes(n: int, N: int, seed: int, scale: float = 0.2) -> np.ndarray:
    rng = np.random.default_rng(seed)
    c = rng.uniform(-1.0, 1.0, (N, n))
    r = rng.uniform(0, scale, (N, n))
    return np.stack([c - r, c + r], axis=-1)


def _pc_project(A, b, dims, q):
    import polytope as pc

    t0 = time.perf_counter()
    try:
        pc.projection(pc.Polytope(A, b), [d + 1 for d in dims])
        q.put(time.perf_counter() - t0)
    except Exception as exc:  # pragma: no cover - depends on the package
        q.put(f"error: {exc}")


def pc_projection_time(P: cm.Polytope, dims) -> float | str:
    ctx = mp.get_context("spawn")
    q = ctx.Queue()
    proc = ctx.Process(target=_pc_project, args=(np.array(P.A), np.array(P.b), dims, q))
    proc.start()
    proc.join(TIME_LIMIT)
    if proc.is_alive():
        proc.terminate()
        proc.join()
        return f"> {TIME_LIMIT:.0f} s (stopped)"
    return q.get() if not q.empty() else "no result"


def main() -> dict:
    out: dict = {"benchmark": "bench_sets"}
    N = 100_000
    P2 = cm.Polytope.from_vertices(
        np.c_[np.cos(np.arange(8) * np.pi / 4), np.sin(np.arange(8) * np.pi / 4)] * 1.5)
    P8 = random_polytope(8, 32, 0)
    for name, P in (("2d_8facets", P2), ("8d_32facets", P8)):
        B = random_boxes(P.dim, N, 1)
        t_in = _timeit(lambda: P.contains_box(B))  # noqa: B023
        t_x = _timeit(lambda: P.intersects_box(B), reps=3)  # noqa: B023
        out[f"box_in_polytope_per_s[{name}]"] = N / t_in
        out[f"box_intersects_polytope_per_s[{name}]"] = N / t_x
    # union of 10 polytopes (2-D), boxes near the members
    members = [cm.Polytope.from_box(cm.Box([i * 0.3, 0.0], [i * 0.3 + 0.35, 1.0]))
               for i in range(10)]
    U = cm.PolytopeUnion(members)
    Nu = 20_000
    rng = np.random.default_rng(2)
    c = np.c_[rng.uniform(0, 3.2, Nu), rng.uniform(0, 1, Nu)]
    r = rng.uniform(0, 0.1, (Nu, 2))
    BU = np.stack([c - r, c + r], axis=-1)
    t_u = _timeit(lambda: U.contains_box(BU), reps=3)
    out["box_in_union10_per_s"] = Nu / t_u
    # E1 pre-sets (thesis §3.4)
    ex = cm.models.load("linear_sliding")
    t0 = time.perf_counter()
    seq = cm.linear_controllable_sets(ex.model, ex.terminal, max_steps=30, until=ex.x0s)
    out["e1_presets_seconds"] = time.perf_counter() - t0
    out["e1_presets_steps"] = len(seq.sets) - 1
    # projection 8-D -> 2-D
    dims = [0, 1]
    t0 = time.perf_counter()
    Q = P8.project(dims)
    out["projection_8d_to_2d_seconds"] = time.perf_counter() - t0
    out["projection_8d_to_2d_facets"] = int(Q.minimal().n_constraints)
    P3 = random_polytope(3, 10, 5)
    t0 = time.perf_counter()
    P3.project(dims)
    out["projection_3d_to_2d_seconds"] = time.perf_counter() - t0
    try:
        import polytope as pc  # noqa: F401

        out["polytope_package"] = __import__("polytope").__version__
        out["polytope_projection_3d_to_2d_seconds"] = pc_projection_time(P3, dims)
        out["polytope_projection_8d_to_2d_seconds"] = pc_projection_time(P8, dims)
        # containment: one is_subset per box (the package's box-in-polytope test)
        pcP = pc.Polytope(np.array(P2.A), np.array(P2.b))
        B = random_boxes(2, 200, 3)
        t0 = time.perf_counter()
        for b in B:
            pc.is_subset(pc.box2poly(b.tolist()), pcP)
        t_pc = (time.perf_counter() - t0) / len(B)
        out["polytope_box_in_polytope_per_s[2d_8facets]"] = 1.0 / t_pc
        out["ratio_box_in_polytope_ours_over_polytope"] = (
            out["box_in_polytope_per_s[2d_8facets]"] * t_pc)
        pts = np.random.default_rng(4).uniform(-2, 2, (N, 2))
        t_pts_pc = _timeit(lambda: pcP.contains(pts.T), reps=3)
        t_pts = _timeit(lambda: P2.contains(pts), reps=3)
        out["ratio_point_containment_speed_ours_over_polytope"] = t_pts_pc / t_pts
        for key in ("3d", "8d"):
            theirs = out[f"polytope_projection_{key}_to_2d_seconds"]
            ours = out[f"projection_{key}_to_2d_seconds"]
            out[f"ratio_projection_{key}_polytope_over_ours"] = (
                theirs / ours if isinstance(theirs, float) else f"{theirs} vs {ours:.3g} s")
    except ImportError:
        out["polytope_package"] = "not installed (pip install polytope)"
    out["targets"] = {"box_in_polytope_per_s": ">= 1e7",
                      "projection": "faster than polytope's"}
    return out


def _fmt(v):
    return float(f"{v:.4g}") if isinstance(v, float) else v


if __name__ == "__main__":
    res = main()
    json.dump({k: _fmt(v) for k, v in res.items()}, sys.stdout)
    sys.stdout.write("\n")
