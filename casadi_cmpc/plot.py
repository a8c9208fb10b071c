"""Matplotlib views of sets, pavings and trajectories.

All functions take ``ax=None`` (a new figure is created) and return the Axes; keyword arguments
go to matplotlib.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["plot_polygon_hull", "plot_boxes", "new_axes"]


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
