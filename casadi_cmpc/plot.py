"""Matplotlib views of sets, pavings and trajectories.

All functions take ``ax=None`` (a new figure is created) and return the Axes (or the Figure
for the multi-panel :func:`plot_trajectory`); keyword arguments go to matplotlib.

Labels come from the model: its ``state_names``, ``input_names``, ``disturbance_names`` and
``units`` give axis labels ``"name [unit]"``, and its sampling time ``dt`` (seconds) gives
time axes in seconds (``"step k"`` without it). Legends are placed outside the axes so that
they never cover data.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["plot_polygon_hull", "plot_boxes", "new_axes", "plot_trajectory", "plot_runs",
           "axis_label", "variable_labels", "time_axis", "legend_outside", "run_style",
           "RUN_COLORS"]

# Colours of several closed-loop runs drawn together: a qualitative set that stays distinct
# from each other and from the sequential colour maps of set figures (viridis).
RUN_COLORS = ("tab:red", "tab:orange", "black", "tab:pink", "tab:brown", "tab:cyan",
              "tab:olive", "tab:gray", "tab:purple")
_RUN_MARKERS = ("o", "s", "^", "D", "v", "P", "X", "*", "h")

_KINDS = {"x": ("state_names", "state"), "u": ("input_names", "input"),
          "w": ("disturbance_names", "disturbance")}


def new_axes(ax: Any = None) -> Any:
    """Return ``ax`` or a new Axes with equal aspect."""
    if ax is None:
        import matplotlib.pyplot as plt

        _, ax = plt.subplots()
        ax.set_aspect("equal", adjustable="datalim")
    return ax


def axis_label(name: str, unit: str | None = None) -> str:
    """``"name [unit]"``, or ``name`` alone without a unit.

    Examples
    --------
    >>> axis_label("T", "K"), axis_label("x1")
    ('T [K]', 'x1')
    """
    return f"{name} [{unit}]" if unit else str(name)


def variable_labels(model: Any, kind: str, d: int | None = None, names: Any = None,
                    units: Any = None) -> tuple[list[str], list[str | None]]:
    """Names and units of the components of x, u or w of a model.

    Parameters
    ----------
    model : Model or None
        Source of ``state_names`` / ``input_names`` / ``disturbance_names`` and ``units``;
        None gives the defaults ``x1..``, ``u1..``, ``w1..`` without units.
    kind : {"x", "u", "w"}
        The variable.
    d : int, optional
        Number of components (default: the model's).
    names : sequence of str, optional
        Names to use instead of the model's (length d).
    units : mapping of str to str, optional
        Units by (displayed) name, used instead of the model's.

    Returns
    -------
    names : list of str, length d
    units : list of (str or None), length d

    Raises
    ------
    ValueError
        ``names`` with a length other than d (the message names the keyword, e.g.
        ``state_names``).
    """
    attr, _ = _KINDS[kind]
    model_names = getattr(model, attr, None) if model is not None else None
    if d is None:
        d = len(model_names) if model_names is not None else 0
    if model_names is not None and len(model_names) != d:
        model_names = None
    default = list(model_names) if model_names is not None else [
        f"{kind}{i + 1}" for i in range(d)]
    if names is None:
        out = default
    else:
        out = [str(v) for v in names]
        if len(out) != d:
            raise ValueError(f"{attr} must have {d} entries; got {len(out)}")
    if units is not None:
        unit_list = [units.get(v) or None for v in out]
    else:
        model_units = getattr(model, "units", None) or {}
        unit_list = [model_units.get(v) or None for v in default]
    return out, unit_list


def time_axis(model: Any, K: int) -> tuple[np.ndarray, str]:
    """Times of x(0), ..., x(K) and the axis label.

    Returns
    -------
    t : ndarray, shape (K + 1,)
        ``k dt`` in seconds when the model has a sampling time ``dt``, else the steps k.
    label : str
        ``"time t [s]"`` or ``"step k"``.
    """
    dt = getattr(model, "dt", None) if model is not None else None
    k = np.arange(K + 1, dtype=float)
    if dt:
        return k * float(dt), "time t [s]"
    return k, "step k"


def legend_outside(ax: Any, where: str = "right", extra: Any = (), **kw: Any) -> Any:
    """A legend placed outside the axes (right of it or below it), one entry per label.

    Parameters
    ----------
    ax : matplotlib Axes
    where : {"right", "below"}
        Side of the axes.
    extra : sequence of matplotlib Artist
        Labelled keys shown in the legend only (not drawn in the axes).
    **kw
        Passed to ``ax.legend`` (e.g. ``fontsize``, ``ncol``, ``title``).

    Returns
    -------
    matplotlib Legend or None
        None when the axes has no labelled artist.
    """
    handles, labels = ax.get_legend_handles_labels()
    handles = list(handles) + list(extra)
    labels = list(labels) + [a.get_label() for a in extra]
    keep: dict[str, Any] = {}
    for h, lab in zip(handles, labels, strict=True):
        keep.setdefault(lab, h)
    if not keep:
        return None
    kw.setdefault("fontsize", "small")
    if where == "below":  # clear of the tick labels and the axis label (about 36 pt)
        from matplotlib.transforms import ScaledTranslation

        kw.setdefault("loc", "upper center")
        kw.setdefault("bbox_to_anchor", (0.5, 0.0))
        kw.setdefault("bbox_transform", ax.transAxes + ScaledTranslation(
            0.0, -40.0 / 72.0, ax.figure.dpi_scale_trans))
        kw.setdefault("ncol", min(3, len(keep)))
    elif where == "right":
        kw.setdefault("loc", "upper left")
        kw.setdefault("bbox_to_anchor", (1.02, 1.0))
        kw.setdefault("borderaxespad", 0.0)
    else:
        raise ValueError(f"where must be 'right' or 'below'; got {where!r}")
    return ax.legend(list(keep.values()), list(keep.keys()), **kw)


def run_style(i: int) -> dict[str, Any]:
    """Colour and marker of run ``i`` (0-based) when several runs share one plot."""
    return {"color": RUN_COLORS[i % len(RUN_COLORS)],
            "marker": _RUN_MARKERS[i % len(_RUN_MARKERS)]}


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
    if "color" in kw:  # one colour for face and edge (matplotlib warns on color + facecolor)
        c = kw.pop("color")
        kw.setdefault("facecolor", c)
        kw.setdefault("edgecolor", c)
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


def _check_dims(dims: tuple[int, int], n: int) -> tuple[int, int]:
    if n == 1:
        return 0, 0
    i, j = int(dims[0]), int(dims[1])
    if not (0 <= i < n and 0 <= j < n and i != j):
        raise ValueError(f"dims must be two different state indices in 0..{n - 1}; got {dims}")
    return i, j


def _x0_text(x0: np.ndarray) -> str:
    return "x0 = (" + ", ".join(f"{v:.4g}" for v in np.asarray(x0, dtype=float)) + ")"


def draw_state_box(ax: Any, model: Any, i: int, j: int, label: str = "X") -> None:
    """The model's state box X projected on the axes (i, j): a dashed black rectangle,
    included in the data limits of ``ax``."""
    from matplotlib.patches import Rectangle

    X = model.X
    ax.add_patch(Rectangle((X.lo[i], X.lo[j]), X.hi[i] - X.lo[i], X.hi[j] - X.lo[j],
                           fill=False, edgecolor="k", linestyle="--", linewidth=1.0,
                           label=label))
    ax.update_datalim([[X.lo[i], X.lo[j]], [X.hi[i], X.hi[j]]])


def _draw_constraints_and_sets(pa: Any, model: Any, i: int, j: int, sets: Any,
                               obstacles: Any, obstacle_label: str) -> None:
    """X (dashed rectangle), the given sets and the obstacle discs in the phase plane."""
    from matplotlib.patches import Circle

    if model is not None:
        draw_state_box(pa, model, i, j)
    for c, (label, S) in enumerate(_named_sets(sets)):
        col = f"C{(c + 1) % 10}"
        S.plot(ax=pa, dims=(i, j), facecolor=col, alpha=0.3, edgecolor=col, label=label)
    for c, obs in enumerate(obstacles or []):
        cx, cy, r = (float(v) for v in obs)
        pa.add_patch(Circle((cx, cy), r, facecolor="0.5", edgecolor="k", alpha=0.6,
                            label=obstacle_label if c == 0 else None))
        pa.update_datalim([[cx - r, cy - r], [cx + r, cy + r]])


def _phase_labels_and_aspect(pa: Any, names: list[str], units: list[str | None], i: int,
                             j: int, equal: bool | None, obstacles: Any) -> None:
    pa.set_xlabel(axis_label(names[i], units[i]))
    pa.set_ylabel(axis_label(names[j], units[j]))
    if equal is None:  # both in the same unit (or discs, which must look round)
        equal = bool(obstacles) or units[i] == units[j]
    if equal:  # the axes box shrinks to the data's proportions (the data limits stay)
        pa.set_aspect("equal", adjustable="box")


def plot_runs(trajs: Any, ax: Any = None, dims: tuple[int, int] = (0, 1), *,
              sets: Any = None, obstacles: Any = None, obstacle_label: str = "obstacle",
              model: Any = None, show_X: bool = True, labels: Any = None,
              state_names: Any = None, equal_aspect: bool | None = None,
              legend: bool = True) -> Any:
    """Draw several closed-loop runs in one phase plane, each in its own colour.

    Parameters
    ----------
    trajs : sequence of Trajectory
        Runs of one model (``x`` of shape (K_r + 1, n), n >= 2).
    ax : matplotlib Axes, optional
        Created when omitted.
    dims : (int, int)
        States on the horizontal and vertical axes.
    sets : set, sequence of sets or dict label -> set, optional
        Sets drawn under the runs (e.g. ``{"T (terminal set)": T}``).
    obstacles : sequence of (cx, cy, r), optional
        Discs in the coordinates of ``dims`` (units of the states).
    obstacle_label : str
        Legend entry of the discs.
    model : Model, optional
        Source of X, names, units (default: the model of the first run).
    show_X : bool
        Draw X as a dashed rectangle (legend entry ``"X"``).
    labels : sequence of str, optional
        One legend entry per run (default ``"x0 = (...)"``, the run's initial state).
    state_names : sequence of str, optional
        Names instead of the model's.
    equal_aspect : bool, optional
        Equal scales on both axes; default: when obstacles are drawn or both states have
        the same unit (or both none).
    legend : bool
        Add a legend outside the axes (right of it).

    Returns
    -------
    matplotlib Axes
        One line per run (colours and markers of :func:`run_style`), start marked by a
        hollow circle and the end by a filled square in the run's colour.
    """
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D

    trajs = list(trajs)
    if not trajs:
        raise ValueError("plot_runs needs at least one trajectory")
    if model is None:
        model = getattr(trajs[0], "model", None)
    n = np.asarray(trajs[0].x).shape[1]
    if n < 2:
        raise ValueError("plot_runs draws a phase plane and needs n >= 2 states")
    i, j = _check_dims(dims, n)
    if labels is not None and len(labels) != len(trajs):
        raise ValueError(f"labels must have one entry per run ({len(trajs)}); got "
                         f"{len(labels)}")
    names, units = variable_labels(model, "x", n, state_names)
    if ax is None:
        _, ax = plt.subplots(figsize=(7.0, 5.2), layout="constrained")
    _draw_constraints_and_sets(ax, model if show_X else None, i, j, sets, obstacles,
                               obstacle_label)
    for r, traj in enumerate(trajs):
        x = _finite_or_nan(traj.x)
        st = run_style(r)
        lab = labels[r] if labels is not None else _x0_text(traj.x[0])
        K = x.shape[0] - 1
        ax.plot(x[:, i], x[:, j], "-", color=st["color"], marker=st["marker"],
                ms=3.5 if K <= 200 else 0, lw=1.4, label=lab, zorder=3)
        ax.plot(x[0, i], x[0, j], "o", ms=10, mfc="none", mec=st["color"], mew=2, zorder=4)
        ax.plot(x[-1, i], x[-1, j], "s", ms=7, color=st["color"], mec="white", zorder=4)
    # neutral legend keys for the start and end markers
    ax.add_line(Line2D([], [], ls="none", marker="o", ms=9, mfc="none", mec="0.3", mew=2,
                       label="start x(0)"))
    ax.add_line(Line2D([], [], ls="none", marker="s", ms=7, color="0.3", label="end x(K)"))
    _phase_labels_and_aspect(ax, names, units, i, j, equal_aspect, obstacles)
    ax.autoscale_view()
    if legend:
        legend_outside(ax)
    return ax


def _groups(units: list[str | None], idx: list[int]) -> list[list[int]]:
    """Indices split by unit (in order of first appearance); one group when all agree."""
    out: dict[Any, list[int]] = {}
    for k in idx:
        out.setdefault(units[k], []).append(k)
    return list(out.values())


def plot_trajectory(traj: Any, ax: Any = None, dims: tuple[int, int] = (0, 1), *,
                    sets: Any = None, obstacles: Any = None, obstacle_label: str = "obstacle",
                    state_names: Any = None, input_names: Any = None,
                    disturbance_names: Any = None, states: Any = None,
                    disturbance: bool | None = None, horizon: str | None = "auto",
                    equal_aspect: bool | None = None, title: str | None = None) -> Any:
    """Draw a closed-loop trajectory: phase plane and the time series of its signals.

    Parameters
    ----------
    traj : Trajectory
        As returned by :func:`casadi_cmpc.simulate` (``x`` (K + 1, n), ``u`` (K, m),
        ``w`` (K, l), ``horizon`` (K,)); names, units and the sampling time come from
        ``traj.model`` (defaults for a trajectory loaded without its model).
    ax : matplotlib Axes, sequence of Axes, or None
        None: a new figure with the phase plane on the left and the time series on the
        right, one panel per unit of the states, then the inputs (one panel per unit), one
        panel per disturbance component and the level or horizon (for n = 1 the phase
        plane is left out and the state panel shows X as a band). One Axes: only the phase
        plane (n = 1: the state over time) is drawn on it. A sequence: all panels in that
        order.
    dims : (int, int)
        States on the horizontal and vertical axis of the phase plane (n >= 2).
    sets : set, sequence of sets or dict label -> set, optional
        Sets drawn in the phase plane (e.g. a terminal Polytope), projected on ``dims``.
    obstacles : sequence of (cx, cy, r), optional
        Discs in the phase plane (coordinates of ``dims``; the units of the states).
    obstacle_label : str
        Legend entry of the discs (e.g. ``"keep-out zone (radius D = 15 cm)"``).
    state_names, input_names, disturbance_names : sequence of str, optional
        Names instead of the model's (default ``x1..``, ``u1..``, ``w1..``).
    states : sequence of int, optional
        States drawn over time (default: all).
    disturbance : bool, optional
        Draw the disturbance w(k) with the bounds of W; default: when the model has one.
    horizon : {"auto", "level", "horizon", None}
        A panel of what the controller recorded per step: ``"level"``, the level i(k) of a
        run along a set sequence (x(k) in K_i, i = 0 in T; ``traj.level``, or
        ``traj.horizon`` when the trajectory records no levels); ``"horizon"``, the
        horizon N(k) of a contractive MPC (``traj.horizon``); ``"auto"`` (default): the
        level panel when the trajectory records levels, else none; None: no panel.
    equal_aspect : bool, optional
        Equal scales in the phase plane; default: when obstacles are drawn or both states
        of ``dims`` have the same unit (or both none).
    title : str, optional
        Title of the figure.

    Returns
    -------
    matplotlib Figure
        Phase plane: X (dashed rectangle), the sets, the trajectory with its start and end
        marked and the states outside X crossed; axis labels ``"name [unit]"``. Time
        series against ``time t [s]`` when the model has a sampling time, else ``step k``;
        inputs and disturbances as held steps with their box bounds dashed in the same
        colour. Legends are placed outside the axes.
    """
    import matplotlib.pyplot as plt
    from matplotlib.ticker import MaxNLocator

    x = _finite_or_nan(traj.x)
    u = _finite_or_nan(traj.u)
    w = _finite_or_nan(getattr(traj, "w", np.zeros((x.shape[0] - 1, 0))))
    n, m, l = x.shape[1], u.shape[1], w.shape[1]
    K = x.shape[0] - 1
    model = getattr(traj, "model", None)
    snames, sunits = variable_labels(model, "x", n, state_names)
    unames, uunits = variable_labels(model, "u", m, input_names)
    wnames, wunits = variable_labels(model, "w", l, disturbance_names)
    t, t_label = time_axis(model, K)
    i, j = _check_dims(dims, n)
    if horizon not in (None, "auto", "level", "horizon"):
        raise ValueError(f"horizon must be 'auto', 'level', 'horizon' or None; got "
                         f"{horizon!r}")
    levels = tuple(getattr(traj, "level", ()) or ())
    has_levels = len(levels) == K and any(v is not None for v in levels)
    if horizon == "auto":
        horizon = "level" if has_levels else None
    sel = list(range(n)) if states is None else [int(s) for s in states]
    if not sel or any(not 0 <= s < n for s in sel):
        raise ValueError(f"states must be indices in 0..{n - 1}; got {states}")
    draw_w = (l > 0) if disturbance is None else bool(disturbance) and l > 0
    steps_out = np.asarray(traj.violations["state_steps"], dtype=int)

    panels: list[tuple[str, list[int]]] = []
    if n > 1:
        panels.append(("phase", []))
    panels += [("x", g) for g in _groups(sunits, sel)]
    if m > 0:
        panels += [("u", g) for g in _groups(uunits, list(range(m)))]
    if draw_w:  # one panel per component: parameters and additive terms differ in scale
        panels += [("w", [d]) for d in range(l)]
    if horizon is not None:
        panels.append(("h", []))

    single = ax is not None and not isinstance(ax, (list, tuple, np.ndarray))
    if ax is None:
        rows = len(panels) - (1 if n > 1 else 0)
        if n > 1:
            fig = plt.figure(figsize=(13.0, max(5.0, 2.3 * rows)), layout="constrained")
            gs = fig.add_gridspec(rows, 2, width_ratios=(1.0, 1.0))
            axes = [fig.add_subplot(gs[:, 0])]
            for r in range(rows):
                axes.append(fig.add_subplot(gs[r, 1], sharex=axes[1] if r else None))
        else:
            fig, arr = plt.subplots(rows, 1, figsize=(8.0, 2.6 * rows),
                                    layout="constrained", sharex=True, squeeze=False)
            axes = list(arr[:, 0])
    elif single:
        axes = [ax]
        fig = ax.figure
        panels = panels[:1]
    else:
        axes = list(np.ravel(ax))
        if len(axes) != len(panels):
            kinds = ", ".join({"phase": "phase plane", "x": "states", "u": "inputs",
                               "w": "disturbance", "h": "level/horizon"}[p[0]]
                              for p in panels)
            raise ValueError(f"this trajectory needs {len(panels)} Axes ({kinds}); got "
                             f"{len(axes)}")
        fig = axes[0].figure

    def mark_ends(a: Any, px: np.ndarray, py: np.ndarray) -> None:
        a.plot(px[0], py[0], "o", ms=9, color="C2", mfc="none", mew=2, label="start x(0)",
               zorder=4)
        a.plot(px[-1], py[-1], "s", ms=7, color="C3", label=f"end x({K})", zorder=4)
        if steps_out.size:
            a.plot(px[steps_out], py[steps_out], "x", ms=8, color="red", mew=2,
                   label="outside X", zorder=5)

    def held(a: Any, values: np.ndarray, col: str, label: str) -> None:
        """u(k), w(k), i(k) held over [t_k, t_{k+1})."""
        if K > 0:
            a.step(t, np.append(values, values[-1]), where="post", color=col, label=label)
        else:
            a.plot([], [], color=col, label=label)

    def bounds(a: Any, box: Any, d: int, col: str, name: str, what: str) -> None:
        for b, bound in enumerate((box.lo[d], box.hi[d])):
            a.axhline(bound, color=col, linestyle="--", linewidth=0.9,
                      label=f"{name} bounds ({what})" if b == 0 else None)
        a.autoscale_view()  # margins around the bounds too (not only around the signal)

    def group_label(kind: str, g: list[int], names: list[str], units: list[str | None]
                    ) -> str:
        if kind in "xw" and len(g) == 1:
            return axis_label(names[g[0]], units[g[0]])
        return axis_label({"x": "state", "u": "input", "w": "disturbance"}[kind],
                          units[g[0]])

    for a, (kind, g) in zip(axes, panels, strict=False):
        if kind == "phase":
            _draw_constraints_and_sets(a, model, i, j, sets, obstacles, obstacle_label)
            a.plot(x[:, i], x[:, j], "-", marker="." if K <= 200 else None, color="C0",
                   label="trajectory", zorder=3)
            mark_ends(a, x[:, i], x[:, j])
            _phase_labels_and_aspect(a, snames, sunits, i, j, equal_aspect, obstacles)
            a.set_title("phase plane")
            a.autoscale_view()
        elif kind == "x":
            if n == 1:
                if model is not None:
                    a.axhspan(model.X.lo[0], model.X.hi[0], color="0.85", alpha=0.5,
                              label="X", zorder=0)
                for c, (label, S) in enumerate(_named_sets(sets)):
                    B = S.bounding_box()
                    a.axhspan(B.lo[0], B.hi[0], color=f"C{(c + 1) % 10}", alpha=0.25,
                              label=label, zorder=1)
            for d in g:
                a.plot(t, x[:, d], "-", marker="." if K <= 100 else None,
                       color=f"C{d % 10}", label=axis_label(snames[d], sunits[d]))
            if n == 1:
                mark_ends(a, t, x[:, 0])
            a.set_ylabel(group_label("x", g, snames, sunits))
            a.set_title("states")
        elif kind == "u":
            for d in g:
                col = f"C{d % 10}"
                held(a, u[:, d], col, axis_label(unames[d], uunits[d]))
                if model is not None:
                    bounds(a, model.U, d, col, unames[d], "U")
            a.set_ylabel(group_label("u", g, unames, uunits))
            a.set_title("inputs")
        elif kind == "w":
            for d in g:
                col = f"C{(d + 4) % 10}"
                held(a, w[:, d], col, axis_label(wnames[d], wunits[d]))
                if model is not None and getattr(model, "W", None) is not None:
                    bounds(a, model.W, d, col, wnames[d], "W")
            a.set_ylabel(group_label("w", g, wnames, wunits))
            how = getattr(traj, "disturbance", "")
            a.set_title("disturbance w(k)" + (f", drawn: {how}" if how else ""))
        else:
            rec = levels if horizon == "level" and has_levels else tuple(traj.horizon)
            h = np.array([np.nan if v is None else float(v) for v in rec], dtype=float)
            if horizon == "level":
                held(a, h, "C7", "level i(k): x(k) in K_i (0: in T)")
                a.set_ylabel("level i(k)")
                a.set_title("level i(k) of K_i")
            else:
                held(a, h, "C7", "horizon N(k)")
                a.set_ylabel("horizon N(k)")
                a.set_title("horizon N(k) of the contractive MPC")
            a.plot(t[:-1], h, ".", color="C7")
            a.yaxis.set_major_locator(MaxNLocator(integer=True))
        if kind != "phase":
            a.set_xlabel(t_label)
            if t_label == "step k":
                a.xaxis.set_major_locator(MaxNLocator(integer=True))
        # the phase plane of a figure made here has room below it (its legend can be long)
        legend_outside(a, where="below" if kind == "phase" and ax is None else "right",
                       **({"ncol": 2} if kind == "phase" and ax is None else {}))
    if title is not None:
        fig.suptitle(title)
    return fig
