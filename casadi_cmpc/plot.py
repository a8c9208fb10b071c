"""Matplotlib views of sets, pavings and trajectories.

All functions take ``ax=None`` (a new figure is created) and return the Axes; keyword arguments
go to matplotlib.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["plot_polygon_hull", "plot_boxes", "new_axes", "plot_trajectory"]


def new_axes(ax: Any = None) -> Any:
    """Return ``ax`` or a new Axes with equal aspect."""
    if ax is None:
        import matplotlib.pyplot as plt

        _, ax = plt.subplots()
        ax.set_aspect("equal", adjustable="datalim")
    return ax


def _hull_2d(points: np.ndarray) -> np.ndarray:
    """Vertices of the 2-D convex hull in counter-clockwise order (handles degenerate sets)."""
    pts = np.unique(np.asarray(points, dtype=float).reshape(-1, 2), axis=0)
    if len(pts) <= 2:
        return pts
    try:
        from scipy.spatial import ConvexHull

        return pts[ConvexHull(pts).vertices]
    except Exception:  # collinear points: the segment between the extreme ones
        d = pts - pts.mean(axis=0)
        axis = np.linalg.svd(d, full_matrices=False)[2][0]
        t = d @ axis
        return pts[[int(np.argmin(t)), int(np.argmax(t))]]


def plot_polygon_hull(points: Any, ax: Any = None, **kw: Any) -> Any:
    """Draw the convex hull of 2-D points (shape (k, 2)) as a filled polygon.

    Defaults: ``facecolor="C0"``, ``alpha=0.4``, ``edgecolor="k"``.
    """
    from matplotlib.patches import Polygon

    ax = new_axes(ax)
    hull = _hull_2d(points)
    kw.setdefault("facecolor", "C0")
    kw.setdefault("alpha", 0.4)
    kw.setdefault("edgecolor", "k")
    if len(hull) == 0:
        return ax
    if len(hull) <= 2:
        kw.pop("facecolor", None)
        color = kw.pop("edgecolor")
        ax.plot(hull[:, 0], hull[:, 1], "-o", color=color, **{k: v for k, v in kw.items()
                                                             if k in ("label", "alpha")})
    else:
        ax.add_patch(Polygon(hull, closed=True, **kw))
    ax.update_datalim(hull)
    ax.autoscale_view()
    return ax


def plot_boxes(boxes: Any, ax: Any = None, dims: tuple[int, int] = (0, 1), **kw: Any) -> Any:
    """Draw a batch of boxes (N, n, 2) as rectangles (projected on ``dims``).

    Defaults: ``facecolor="C0"``, ``edgecolor="k"``, ``linewidth=0.3``.
    """
    from matplotlib.collections import PatchCollection
    from matplotlib.patches import Rectangle

    ax = new_axes(ax)
    b = np.asarray(boxes, dtype=float)
    if b.ndim == 2:
        b = b[None]
    if b.shape[0] == 0:
        return ax
    i, j = dims if b.shape[1] > 1 else (0, 0)
    xl, xh = b[:, i, 0], b[:, i, 1]
    if b.shape[1] > 1:
        yl, yh = b[:, j, 0], b[:, j, 1]
    else:
        yl, yh = np.zeros_like(xl), np.full_like(xl, 0.1)
    label = kw.pop("label", None)
    kw.setdefault("facecolor", "C0")
    kw.setdefault("edgecolor", "k")
    kw.setdefault("linewidth", 0.3)
    rects = [Rectangle((a, c), w, h) for a, c, w, h in zip(xl, yl, xh - xl, yh - yl,
                                                           strict=True)]
    coll = PatchCollection(rects, **kw)
    if label is not None:
        coll.set_label(label)
    ax.add_collection(coll)
    ax.update_datalim(np.array([[xl.min(), yl.min()], [xh.max(), yh.max()]]))
    ax.autoscale_view()
    return ax


def _finite_or_nan(a: np.ndarray) -> np.ndarray:
    """A float copy with infinite entries replaced by NaN (matplotlib skips NaN)."""
    out = np.array(a, dtype=float)
    out[~np.isfinite(out)] = np.nan
    return out


def _named_sets(sets: Any) -> list[tuple[str, Any]]:
    """``(label, set)`` pairs from None, one set, a sequence of sets or a dict label -> set."""
    if sets is None:
        return []
    if isinstance(sets, dict):
        return [(str(k), v) for k, v in sets.items()]
    if hasattr(sets, "dim") and hasattr(sets, "vertices"):
        sets = [sets]
    return [(type(S).__name__, S) for S in sets]


def _names(names: Any, d: int, prefix: str, what: str) -> list[str]:
    if names is None:
        return [f"{prefix}{i + 1}" for i in range(d)]
    names = [str(v) for v in names]
    if len(names) != d:
        raise ValueError(f"{what} must have {d} entries; got {len(names)}")
    return names


def plot_trajectory(traj: Any, ax: Any = None, dims: tuple[int, int] = (0, 1), *,
                    sets: Any = None, obstacles: Any = None, state_names: Any = None,
                    input_names: Any = None, title: str | None = None) -> Any:
    """Draw a closed-loop trajectory: phase plane, states over k and inputs over k.

    Parameters
    ----------
    traj : Trajectory
        As returned by :func:`casadi_cmpc.simulate` (``x`` (K + 1, n), ``u`` (K, m)).
    ax : matplotlib Axes, sequence of Axes, or None
        None: a new figure with the phase plane on the left and the state and input time
        series on the right (for n = 1 the phase plane is replaced by the state time
        series, drawn with X as a band; without input the input panel is left out). One
        Axes: only the phase plane (n = 1: the states over k) is drawn on it. A sequence:
        the panels in the order phase plane, states, inputs (as many as the layout has).
    dims : (int, int)
        States on the horizontal and vertical axis of the phase plane (n >= 2).
    sets : set, sequence of sets or dict label -> set, optional
        Sets drawn in the phase plane (e.g. a terminal Polytope), projected on ``dims``.
    obstacles : sequence of (cx, cy, r), optional
        Circles in the phase plane (coordinates of ``dims``; the units of the states).
    state_names, input_names : sequence of str, optional
        Axis and legend labels (default ``x1, ..., xn`` and ``u1, ..., um``).
    title : str, optional
        Title of the figure.

    Returns
    -------
    matplotlib Figure
        Phase plane: X (dashed rectangle), the sets, the trajectory with its start and end
        marked and the states outside X crossed. Inputs: one step curve per input, its U
        bounds dashed in the same colour.
    """
    import matplotlib.pyplot as plt
    from matplotlib.patches import Circle, Rectangle

    x = _finite_or_nan(traj.x)
    u = _finite_or_nan(traj.u)
    n, m = x.shape[1], u.shape[1]
    K = x.shape[0] - 1
    model = getattr(traj, "model", None)
    snames = _names(state_names, n, "x", "state_names")
    unames = _names(input_names, m, "u", "input_names")
    i, j = (int(dims[0]), int(dims[1])) if n > 1 else (0, 0)
    if n > 1 and not (0 <= i < n and 0 <= j < n and i != j):
        raise ValueError(f"dims must be two different state indices in 0..{n - 1}; got {dims}")
    steps_out = np.asarray(traj.violations["state_steps"], dtype=int)
    k = np.arange(K + 1)

    n_panels = (1 if n > 1 else 0) + 1 + (1 if m > 0 else 0)
    single = ax is not None and not isinstance(ax, (list, tuple, np.ndarray))
    if ax is None:
        if n > 1:
            fig = plt.figure(figsize=(11.0, 5.0), layout="constrained")
            gs = fig.add_gridspec(2, 2, width_ratios=(1.0, 1.2))
            axes = [fig.add_subplot(gs[:, 0]), fig.add_subplot(gs[0, 1])]
            if m > 0:
                axes.append(fig.add_subplot(gs[1, 1], sharex=axes[1]))
        else:
            fig, arr = plt.subplots(n_panels, 1, figsize=(7.0, 2.6 * n_panels),
                                    layout="constrained", sharex=True, squeeze=False)
            axes = list(arr[:, 0])
    elif single:
        axes = [ax]
        fig = ax.figure
    else:
        axes = list(np.ravel(ax))
        if len(axes) != n_panels:
            raise ValueError(f"this trajectory needs {n_panels} Axes (phase plane, states, "
                             f"inputs as applicable); got {len(axes)}")
        fig = axes[0].figure

    def mark_ends(a: Any, px: np.ndarray, py: np.ndarray) -> None:
        a.plot(px[0], py[0], "o", ms=9, color="C2", mfc="none", mew=2, label="start x(0)",
               zorder=4)
        a.plot(px[-1], py[-1], "s", ms=7, color="C3", label=f"end x({K})", zorder=4)
        if steps_out.size:
            a.plot(px[steps_out], py[steps_out], "x", ms=8, color="red", mew=2,
                   label="outside X", zorder=5)

    labelled = {"text": False}

    def draw_states(a: Any) -> None:
        for d in range(n):
            a.plot(k, x[:, d], "-", marker="." if K <= 100 else None, color=f"C{d % 10}",
                   label=snames[d])
        a.set_xlabel("step k")
        a.set_ylabel(snames[0] if n == 1 else "state")
        a.set_title("states")

    if n > 1:
        pa = axes[0]
        if model is not None:
            X = model.X
            pa.add_patch(Rectangle((X.lo[i], X.lo[j]), X.hi[i] - X.lo[i], X.hi[j] - X.lo[j],
                                   fill=False, edgecolor="k", linestyle="--", linewidth=1.0,
                                   label="X"))
            pa.update_datalim([[X.lo[i], X.lo[j]], [X.hi[i], X.hi[j]]])
        for c, (label, S) in enumerate(_named_sets(sets)):
            S.plot(ax=pa, dims=(i, j), facecolor=f"C{(c + 1) % 10}", alpha=0.3,
                   edgecolor=f"C{(c + 1) % 10}", label=label)
        for c, obs in enumerate(obstacles or []):
            cx, cy, r = (float(v) for v in obs)
            pa.add_patch(Circle((cx, cy), r, facecolor="0.5", edgecolor="k", alpha=0.6,
                                label="obstacle" if c == 0 else None))
            pa.update_datalim([[cx - r, cy - r], [cx + r, cy + r]])
        pa.plot(x[:, i], x[:, j], "-", marker="." if K <= 200 else None, color="C0",
                label="trajectory", zorder=3)
        mark_ends(pa, x[:, i], x[:, j])
        pa.set_xlabel(snames[i])
        pa.set_ylabel(snames[j])
        pa.set_title("phase plane")
        pa.autoscale_view()
        pa.legend(loc="best", fontsize="small")
        labelled["text"] = True
        rest = axes[1:]
    else:
        sa = axes[0]
        if model is not None:
            sa.axhspan(model.X.lo[0], model.X.hi[0], color="0.85", alpha=0.5, label="X",
                       zorder=0)
        for c, (label, S) in enumerate(_named_sets(sets)):
            B = S.bounding_box()
            sa.axhspan(B.lo[0], B.hi[0], color=f"C{(c + 1) % 10}", alpha=0.25, label=label,
                       zorder=1)
        draw_states(sa)
        mark_ends(sa, k, x[:, 0])
        sa.legend(loc="best", fontsize="small")
        rest = axes[1:]
    if rest and n > 1:
        sa = rest[0]
        draw_states(sa)
        sa.legend(loc="best", fontsize="small", ncol=max(1, n // 4))
        rest = rest[1:]
    if rest and m > 0:
        ua = rest[0]
        kk = np.arange(K + 1)
        for d in range(m):
            col = f"C{d % 10}"
            if K > 0:
                ua.step(kk, np.append(u[:, d], u[-1, d]), where="post", color=col,
                        label=unames[d])
            else:
                ua.plot([], [], color=col, label=unames[d])
            if model is not None:
                for b, bound in enumerate((model.U.lo[d], model.U.hi[d])):
                    ua.axhline(bound, color=col, linestyle="--", linewidth=0.9,
                               label=f"{unames[d]} bounds (U)" if b == 0 else None)
        ua.set_xlabel("step k")
        ua.set_ylabel("input")
        ua.set_title("inputs")
        ua.legend(loc="best", fontsize="small", ncol=max(1, m // 4))
    if title is not None:
        fig.suptitle(title)
    return fig
