"""Tests of casadi_cmpc.plot and the figures of ``cmpc run``: labels from the model's names
and units, time in seconds, legends outside the data, the sets' legend, equal aspect of the
MiroSot field, the disturbance and level panels."""

from __future__ import annotations

import casadi as ca
import matplotlib
import numpy as np
import pytest

import casadi_cmpc as cm
from casadi_cmpc.plot import axis_label, legend_outside, plot_runs, plot_trajectory, time_axis

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.patches import Circle  # noqa: E402


@pytest.fixture(autouse=True)
def _close_figures():
    yield
    plt.close("all")


def tank(dt=2.0):
    """A two-state, one-input linear model with names, units and a sampling time."""
    x = ca.SX.sym("x", 2)
    u = ca.SX.sym("u")
    f = ca.vertcat(0.9 * x[0] + 0.1 * x[1], 0.95 * x[1] + 0.2 * u)
    return cm.Model(x=x, u=u, f=f, X=cm.Box([-1, -2], [1, 2]), U=cm.Box([-1], [1]),
                    name="tank", state_names=["level h", "inflow q"], input_names=["valve"],
                    units={"level h": "m", "inflow q": "l/s", "valve": "%"}, dt=dt)


def legends_of(fig):
    return [a.get_legend() for a in fig.axes if a.get_legend() is not None]


def legend_texts(ax):
    return [t.get_text() for t in ax.get_legend().get_texts()]


def overlaps(a, b) -> bool:
    """Whether two display-coordinate bounding boxes share interior points."""
    return not (a.x1 <= b.x0 or b.x1 <= a.x0 or a.y1 <= b.y0 or b.y1 <= a.y0)


def assert_legends_outside(fig):
    """No legend overlaps the data area (axes box) of any axes of the figure."""
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    legends = legends_of(fig)
    assert legends
    for leg in legends:
        lb = leg.get_window_extent(renderer)
        for a in fig.axes:
            if a.get_label() == "<colorbar>":
                continue
            assert not overlaps(lb, a.get_window_extent(renderer)), (
                [t.get_text() for t in leg.get_texts()], a.get_title())


# ------------------------------------------------------------------ labels and time
def test_axis_label_and_time_axis():
    assert axis_label("T", "K") == "T [K]"
    assert axis_label("x1", None) == "x1"
    t, lab = time_axis(tank(dt=0.5), 4)
    assert lab == "time t [s]" and np.allclose(t, [0.0, 0.5, 1.0, 1.5, 2.0])
    t, lab = time_axis(tank(dt=None), 3)
    assert lab == "step k" and np.array_equal(t, [0, 1, 2, 3])


def test_trajectory_labels_use_the_model_names_units_and_seconds():
    model = tank(dt=2.0)
    traj = cm.simulate(model, np.array([[-0.5, -0.5]]), [0.8, 1.0], 5)
    fig = traj.plot()
    phase = fig.axes[0]
    assert phase.get_xlabel() == "level h [m]"
    assert phase.get_ylabel() == "inflow q [l/s]"
    # the states have different units: one panel each, labelled with name and unit
    assert [a.get_ylabel() for a in fig.axes[1:]] == ["level h [m]", "inflow q [l/s]",
                                                     "input [%]"]
    for a in fig.axes[1:]:
        assert a.get_xlabel() == "time t [s]"
    # time in seconds: the state line is drawn at t = 2 k
    line = fig.axes[1].get_lines()[0]
    assert np.allclose(line.get_xdata(), 2.0 * np.arange(6))
    assert np.allclose(line.get_ydata(), traj.x[:, 0])
    assert "valve [%]" in legend_texts(fig.axes[3])
    assert "valve bounds (U)" in legend_texts(fig.axes[3])
    # m and l/s are not one scale: no equal aspect
    assert phase.get_aspect() == "auto"


def test_input_bounds_are_inside_the_view_with_a_margin():
    """The U bounds are drawn with the same 5 % margin as data (not at the frame)."""
    traj = cm.simulate(tank(), lambda x: np.array([0.95 if x[0] < 0.5 else -0.95]),
                       [0.8, 1.0], 12)
    assert traj.u.min() == -0.95 and traj.u.max() == 0.95
    fig = traj.plot()
    lo, hi = fig.axes[-1].get_ylim()
    assert np.isclose(lo, -1.1) and np.isclose(hi, 1.1)


def test_without_sampling_time_the_axis_is_the_step():
    traj = cm.simulate(tank(dt=None), np.array([[-0.5, -0.5]]), [0.8, 1.0], 4)
    fig = traj.plot()
    assert all(a.get_xlabel() == "step k" for a in fig.axes[1:])
    assert np.array_equal(fig.axes[1].get_lines()[0].get_xdata(), np.arange(5))


def test_explicit_names_override_the_model_and_are_checked():
    traj = cm.simulate(tank(), np.array([[-0.5, -0.5]]), [0.8, 1.0], 3)
    fig = traj.plot(state_names=["a", "b"])
    assert fig.axes[0].get_xlabel() == "a [m]" and fig.axes[0].get_ylabel() == "b [l/s]"
    with pytest.raises(ValueError, match="state_names"):
        traj.plot(state_names=["a"])
    with pytest.raises(ValueError, match="horizon"):
        traj.plot(horizon="steps")


def test_cstr_figures_show_the_scaled_names_units_and_seconds():
    ex = cm.models.load("cstr")
    x_eq = ex.model.equilibrium(np.zeros(1), x0=np.zeros(2))
    traj = cm.simulate(ex.model, lambda x: np.zeros(1), x_eq + [0.01, 0.0], 3)
    fig = traj.plot()
    assert fig.axes[0].get_xlabel() == "C_A - 0.5 [mol/l]"
    assert fig.axes[0].get_ylabel() == "(T - 350)/100 [K]"
    assert fig.axes[1].get_xlabel() == "time t [s]"
    assert np.allclose(fig.axes[1].get_lines()[0].get_xdata(), [0.0, 1.8, 3.6, 5.4])
    # mol/l and K are not one scale: no equal aspect
    assert fig.axes[0].get_aspect() == "auto"


# ------------------------------------------------------------------------ legends
def test_legends_are_outside_the_data_area():
    model = tank()
    traj = cm.simulate(model, np.array([[-0.5, -0.5]]), [0.8, 1.0], 8)
    fig = traj.plot(sets={"T": cm.Box([-0.2, -0.2], [0.2, 0.2])})
    assert_legends_outside(fig)
    runs = [cm.simulate(model, np.array([[-0.5, -0.5]]), x0, 8)
            for x0 in ([0.8, 1.0], [-0.9, 0.5], [0.1, -1.8])]
    ax = plot_runs(runs)
    assert_legends_outside(ax.figure)


def test_legend_outside_keeps_one_entry_per_label():
    fig, ax = plt.subplots()
    ax.plot([0, 1], [0, 1], label="a")
    ax.plot([0, 1], [1, 0], label="a")
    ax.plot([0, 1], [0.5, 0.5], label="b")
    leg = legend_outside(ax, where="below")
    assert [t.get_text() for t in leg.get_texts()] == ["a", "b"]
    assert_legends_outside(fig)
    with pytest.raises(ValueError, match="where"):
        legend_outside(ax, where="inside")


def test_runs_have_distinct_colours_and_are_labelled_with_x0():
    model = tank()
    x0s = ([0.8, 1.0], [-0.9, 0.5], [0.1, -1.8])
    runs = [cm.simulate(model, np.array([[-0.5, -0.5]]), x0, 6) for x0 in x0s]
    ax = plot_runs(runs)
    texts = legend_texts(ax)
    assert "x0 = (0.8, 1)" in texts and "x0 = (-0.9, 0.5)" in texts
    assert "x0 = (0.1, -1.8)" in texts and "X" in texts
    lines = {ln.get_label(): ln for ln in ax.get_lines()}
    colours = {matplotlib.colors.to_hex(lines[f"x0 = {t}"].get_color())
               for t in ("(0.8, 1)", "(-0.9, 0.5)", "(0.1, -1.8)")}
    assert len(colours) == 3
    assert np.allclose(lines["x0 = (-0.9, 0.5)"].get_xydata(), runs[1].x)


# ------------------------------------------------------- disturbance and level panels
def test_robust_run_draws_the_disturbance_realisation():
    ex = cm.models.load("cannon_robust")
    traj = cm.simulate(ex.model, ex.local_law, [0.1, -0.1], 12, disturbance="uniform",
                       seed=3)
    fig = traj.plot()
    titles = [a.get_title() for a in fig.axes]
    wax = fig.axes[titles.index("disturbance w(k), drawn: uniform")]
    assert wax.get_ylabel() == "mu"
    (step,) = [ln for ln in wax.get_lines() if ln.get_label() == "mu"]
    # held over each step: w(k) on [k, k + 1)
    assert np.allclose(step.get_ydata()[:-1], traj.w[:, 0])
    bounds = sorted(ln.get_ydata()[0] for ln in wax.get_lines() if ln.get_linestyle() == "--")
    assert bounds == [0.85, 0.95]
    # a model without w has no such panel
    traj0 = cm.simulate(cm.models.load("cannon").model, ex.local_law, [0.1, -0.1], 5)
    assert not any("disturbance" in a.get_title() for a in traj0.plot().axes)


@pytest.fixture(scope="module")
def sequence_run():
    ex = cm.models.load("cannon")
    seq = cm.controllable_sets(ex.model, ex.terminal, 0.2, law=ex.local_law, progress=False)
    ctrl = cm.SetSequenceMPC(ex.model, seq, Q=np.eye(2), R=np.eye(1), local_law=ex.local_law)
    traj = cm.simulate(ex.model, ctrl, ex.x0s[0], 6)
    return ex, seq, traj


def test_sequence_run_draws_the_level(sequence_run):
    ex, seq, traj = sequence_run
    expected = [seq.level(x) for x in traj.x[:-1]]
    for fig in (traj.plot(horizon="level"), traj.plot()):  # "auto": the recorded levels
        (lax,) = [a for a in fig.axes if a.get_title() == "level i(k) of K_i"]
        assert lax.get_ylabel() == "level i(k)"
        dots = [ln for ln in lax.get_lines() if ln.get_linestyle() == "None"]
        assert np.array_equal(dots[0].get_ydata(), expected)
        assert expected[0] > expected[-1]  # the level decreases along the run
    # a run of a plain gain records no level: no level panel
    plain = cm.simulate(ex.model, ex.local_law, [0.1, -0.1], 4)
    assert not any("level" in a.get_title() for a in plain.plot().axes)


def test_set_sequence_figure_has_X_T_and_the_white_key(sequence_run):
    ex, seq, traj = sequence_run
    fig, ax = plt.subplots(figsize=(7, 6), layout="constrained")
    plot_runs([traj], ax=ax, model=ex.model, show_X=False, legend=False)
    seq.plot(ax=ax, model=ex.model)
    texts = legend_texts(ax)
    assert "X (state box)" in texts
    assert "T = K_0 (terminal set)" in texts
    assert "white (unfilled): not proven controllable" in texts
    assert "x0 = (1.9, -1.5)" in texts
    # X is drawn at the model's box
    (xrect,) = [p for p in ax.patches if p.get_label() == "X (state box)"]
    assert np.allclose(xrect.get_xy(), ex.model.X.lo)
    assert np.isclose(xrect.get_width(), 4.0) and np.isclose(xrect.get_height(), 4.0)
    assert_legends_outside(fig)


# ------------------------------------------------------------------------- MiroSot
def test_mirosot_field_has_equal_aspect_and_keep_out_zones(tmp_path, monkeypatch):
    from casadi_cmpc import cli

    saved = {}
    monkeypatch.setattr(matplotlib.figure.Figure, "savefig",
                        lambda self, path, **kw: saved.__setitem__(path.name, self))
    monkeypatch.setattr(plt, "close", lambda fig=None: None)
    assert cli.main(["run", "mirosot", "--steps", "3", "--out", str(tmp_path),
                     "--no-progress"]) == 0
    ex = cm.models.load("mirosot")
    D = ex.info["D"]
    for name in ("phase_plane.png", "run1.png"):
        pa = saved[name].axes[0]
        assert pa.get_aspect() == 1.0
        assert pa.get_xlabel() == "x [cm]" and pa.get_ylabel() == "y [cm]"
        discs = [p for p in pa.patches if isinstance(p, Circle)]
        assert len(discs) == len(ex.info["obstacles"])
        assert all(np.isclose(c.get_radius(), D) for c in discs)
        assert f"keep-out zone (radius D = {D:g} cm)" in legend_texts(pa)
        assert_legends_outside(saved[name])
    # the run figure draws the pose over time only (not the delayed copies)
    run = saved["run1.png"]
    ylabels = [a.get_ylabel() for a in run.axes[1:]]
    assert ylabels[:2] == ["state [cm]", "theta [rad]"]
    assert "input [%]" in ylabels


def test_plot_trajectory_on_given_axes_checks_their_number():
    traj = cm.simulate(tank(), np.array([[-0.5, -0.5]]), [0.8, 1.0], 3)
    fig, axes = plt.subplots(1, 3)
    with pytest.raises(ValueError, match="needs 4 Axes"):
        plot_trajectory(traj, ax=axes)
    fig, axes = plt.subplots(1, 4)
    assert plot_trajectory(traj, ax=axes) is fig
    assert [a.get_title() for a in axes] == ["phase plane", "states", "states", "inputs"]


def test_one_step_set_axes_carry_the_model_names_and_units():
    ex = cm.models.load("cstr")
    K1 = cm.one_step_set(ex.model, ex.terminal, 0.05)
    ax = K1.plot(model=ex.model)
    assert ax.get_xlabel() == "C_A - 0.5 [mol/l]" and ax.get_ylabel() == "(T - 350)/100 [K]"
    ax2 = K1.plot()
    assert (ax2.get_xlabel(), ax2.get_ylabel()) == ("x1", "x2")
    plt.close("all")
