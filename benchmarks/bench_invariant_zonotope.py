"""Largest control-invariant zonotope of the CSTR (thesis E6, §4.2.7, Alg 4.4, Fig 4.10).

Runs ``cm.largest_invariant_zonotope`` at the thesis' settings (search matrix M0,
eps_opt = 0.005, eps_sivia = 0.05 relative to each candidate, local law
u = [-0.0690, -4.3387] x) and prints one JSON line: the area of the zonotope found (proven
invariant), the area of the thesis' zonotope ``Z = M B^4`` and their ratio, the generators
found, the search statistics and the wall-clock time. A second run reads eps_sivia as an
absolute tolerance (``relative_eps=False``, a budget of ``--budget`` seconds): with 0.05
no candidate of E6 is ever bisected, which shows why the relative reading is the default.
"""

from __future__ import annotations

import argparse
import json
import sys
import time

import numpy as np

import casadi_cmpc as cm


def _run(relative: bool, time_limit: float | None) -> dict:
    ex = cm.models.load("cstr")
    info = ex.info
    t0 = time.perf_counter()
    res = cm.largest_invariant_zonotope(ex.model, ex.local_law, info["M0_search"],
                                        info["eps_opt"], info["eps_sivia"],
                                        relative_eps=relative, time_limit=time_limit,
                                        progress=False)
    seconds = time.perf_counter() - t0
    thesis = cm.Zonotope(np.zeros(2), info["zonotope_generators"]).volume()
    out = {"relative_eps": relative, "status": res.status.name, "area_found": res.volume,
           "area_thesis": thesis, "ratio": res.volume / thesis, "seconds": seconds,
           "proved": None if res.certificate is None else res.certificate.proved,
           "stats": {k: v for k, v in res.stats.items() if k != "seconds"}}
    if res.zonotope is not None:
        out["generators"] = res.zonotope.generators.tolist()
        out["M"] = res.M.tolist()
    return out


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--budget", type=float, default=60.0,
                    help="time limit (s) of the absolute-eps run (0: skip it)")
    args = ap.parse_args(argv)
    res = {"example": "E6 (cstr), Alg 4.4", "relative": _run(True, None)}
    if args.budget > 0:
        res["absolute"] = _run(False, args.budget)
    return res


def _round(v):
    if isinstance(v, float):
        return float(f"{v:.6g}")
    if isinstance(v, dict):
        return {k: _round(x) for k, x in v.items()}
    if isinstance(v, list):
        return [_round(x) for x in v]
    return v


if __name__ == "__main__":
    json.dump(_round(main()), sys.stdout)
    sys.stdout.write("\n")
