"""The library itself no longer uses the deprecated name ``outer`` of the proven-outside boxes
(``Paving.outer``, ``SetResult.outer``, ``ZonotopePaving.outer``, ``Paving(outer=...)``).

``outer`` stays the name of the engine's OUTER-labelled elements (``BnBOutcome.outer``,
internal, named after the label like ``inner``), of the *view* ``"outer"`` (inner ∪
boundary), of ``numpy.outer`` and of methods such as ``SemanticExtension.outer(...)``.
"""

from __future__ import annotations

import ast
import pathlib
import warnings

import casadi as ca
import numpy as np
import pytest

import casadi_cmpc as cm
from casadi_cmpc.solvers.zonotope_sivia import ZonotopePaving, zonotope_sivia

PACKAGE = pathlib.Path(cm.__file__).resolve().parent
#: receivers whose ``.outer`` is not the deprecated alias: numpy's function and the engine's
#: outcome (``out = branch_and_bound(...)``, a BnBOutcome)
ALLOWED_RECEIVERS = {"np", "numpy", "out"}
#: constructors whose keyword ``outer=`` is the deprecated alias of ``outside=``
CONSTRUCTORS = {"Paving", "ZonotopePaving", "_from_solver"}


def _name(node: ast.AST) -> str | None:
    if isinstance(node, ast.Name):
        return node.id
    if isinstance(node, ast.Attribute):
        return node.attr
    return None


def _uses_of_outer(path: pathlib.Path, root: pathlib.Path = PACKAGE.parent) -> list[str]:
    tree = ast.parse(path.read_text(), filename=str(path))
    called = {id(n.func) for n in ast.walk(tree) if isinstance(n, ast.Call)}
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute) and node.attr in ("outer", "n_outer"):
            if id(node) in called:  # a method call such as np.outer(a, b), ext.outer(X)
                continue
            if _name(node.value) in ALLOWED_RECEIVERS and node.attr == "outer":
                continue
            found.append(f"{path.relative_to(root)}:{node.lineno}: "
                         f"{ast.unparse(node)}")
        elif isinstance(node, ast.Call) and _name(node.func) in CONSTRUCTORS:
            for kw in node.keywords:
                if kw.arg == "outer":
                    found.append(f"{path.relative_to(root)}:{node.lineno}: "
                                 f"{_name(node.func)}(outer=...)")
    return found


def test_no_library_module_uses_the_deprecated_outer_attribute():
    files = sorted(PACKAGE.rglob("*.py"))
    assert len(files) > 20
    found = [hit for f in files for hit in _uses_of_outer(f)]
    assert not found, "use 'outside' instead of the deprecated 'outer':\n" + "\n".join(found)


def test_the_checker_finds_the_deprecated_uses(tmp_path):
    bad = tmp_path / "bad.py"
    bad.write_text("P = Paving(outer=b)\nx = res.outer[0]\nn = P.n_outer\n"
                   "ok = np.outer(a, b) + out.outer.boxes + ext.outer(X)\n"
                   "v = P.volume('outer')\n")
    hits = _uses_of_outer(bad, tmp_path)
    assert sorted(h.split(": ", 1)[1] for h in hits) == ["P.n_outer", "Paving(outer=...)",
                                                         "res.outer"]


def test_the_aliases_are_defined():
    for cls in (cm.Paving, cm.SetResult, ZonotopePaving):
        assert isinstance(cls.__dict__["outer"], property)


def test_library_paths_emit_no_deprecation_warning():
    """Solvers and the control code that consumes their pavings, with the warning an error."""
    x = ca.SX.sym("x")
    u = ca.SX.sym("u")
    w = ca.SX.sym("w")
    model = cm.Model(x=x, u=u, w=w, f=x + u + w, X=cm.Box([-4], [4]), U=cm.Box([-1], [1]),
                     W=cm.Box([-0.5], [0.5]))
    lin = cm.Model(x=x, u=u, f=x + u, X=cm.Box([-2], [2]), U=cm.Box([-1], [1]))
    T = cm.Box([-1], [1])
    with warnings.catch_warnings():
        warnings.simplefilter("error", DeprecationWarning)
        P = cm.sivia(lin.closed_loop(np.array([[-0.5]])), Y=T, eps=0.1, progress=False)
        P = P | P.paving
        P.plot(show_outer=True)
        cm.quantified_sivia(model, Y=T, eps=0.1, progress=False)
        for method in ("general", "modal"):
            cm.one_step_set(model, T, 0.1, robust=True, method=method, progress=False,
                            obstacles=[cm.Box([2.5], [3.0])])
        cert = cm.certify_invariant(lin, cm.Polytope.from_box(T), np.array([[-0.5]]),
                                    eps=0.1, progress=False)
        assert cert.proved
        z = zonotope_sivia(lin.closed_loop(np.array([[-0.5]])), cm.Box([-2], [2]), T, 0.1)
        assert z.volume("outside") >= 0 and z.success
    import matplotlib.pyplot as plt

    plt.close("all")


def test_old_name_warns_with_the_caller_line():
    P = cm.Paving(inner=[cm.Box([0], [1])], outside=[cm.Box([1], [2])])
    with pytest.warns(DeprecationWarning) as rec:
        P.outer  # noqa: B018
    assert rec[0].filename == __file__
