"""Plot smoke tests: each file is written and non-empty (nothing more is claimed)."""

from __future__ import annotations

import numpy as np
import pytest

from agent.core.config import PlannerConfig
from agent.core.scenario import ObstacleSpec, RobotSpec, Scenario
from orchestrator.analysis.metrics import Commands, Trajectory
from orchestrator.analysis.plots import (
    animate,
    plot_benchmark,
    plot_report_bars,
    plot_trajectories,
)
from orchestrator.analysis.rundir import RunData


def run_data(tmp_path) -> RunData:
    scenario = Scenario(
        name="plot", description="", time_limit_s=20.0, goal_tolerance_m=0.25,
        planner_config=PlannerConfig(),
        robots=(RobotSpec(0, (0.0, 0.0, 0.0), (10.0, 0.0)),
                RobotSpec(1, (10.0, 0.2, np.pi), (0.0, 0.2))),
        obstacles=(ObstacleSpec(-1, (5.0, 4.0), 1.0, (0.0, -0.1)),),
    )
    t = np.arange(0, 101) * 0.1
    x0 = t
    x1 = 10.0 - t
    pose = np.zeros((t.size, 2, 3))
    pose[:, 0, 0], pose[:, 1, 0], pose[:, 1, 1], pose[:, 1, 2] = x0, x1, 0.2, np.pi
    traj = Trajectory(t, np.array([0, 1]), pose, np.zeros((t.size, 2, 2)))
    return RunData(tmp_path, scenario, traj, Commands.empty(), [])


def test_trajectory_png(tmp_path):
    path = plot_trajectories(run_data(tmp_path), tmp_path / "trajectory.png")
    assert path.stat().st_size > 0


def test_gif(tmp_path):
    path = animate(run_data(tmp_path), tmp_path / "trajectory.gif", max_frames=12)
    assert path.stat().st_size > 0


def test_report_bars(tmp_path):
    stats = {("setup_a", "eifp"): {"plan_ms_mean": (5.0, 1.0), "oscillations_per_robot":
                                   (2.0, 0.5)},
             ("setup_a", "orca"): {"plan_ms_mean": (1.0, 0.1)},
             ("setup_b", "eifp"): {"plan_ms_mean": (7.0, 0.0),
                                   "oscillations_per_robot": (float("nan"), float("nan"))}}
    written = plot_report_bars(stats, [("plan_ms_mean", "ms"), ("oscillations_per_robot",
                                                               "osc")], tmp_path / "r")
    assert len(written) == 3
    assert all(p.stat().st_size > 0 for p in written)


def test_benchmark_png_with_a_failing_planner_and_missing_values(tmp_path):
    def row(case, planner, success, osc, top, ratio):
        return {"case": case, "planner": planner, "success_rate": success,
                "osc_per_robot_median": osc, "osc_per_robot_max": top,
                "time_ratio_mean": ratio}

    rows = [row("circle_8", "eifp-mpc", 1.0, 2.0, 5.0, 1.1),
            row("circle_8", "orca", 0.0, 0.0, 0.0, None),  # nobody arrived
            row("swap_pairs_4", "eifp-mpc", 0.6, 1.0, 3.0, 1.3)]  # orca not run here
    path = plot_benchmark(rows, tmp_path / "benchmark.png", title="t")
    from PIL import Image

    with Image.open(path) as im:
        assert im.format == "PNG" and im.size[0] >= 700


def test_latency_axis_ends_past_the_p99_not_at_a_single_stall() -> None:
    from orchestrator.analysis.plots import LATENCY_AXIS_MARGIN, latency_axis_ms

    ms = np.r_[np.linspace(1.0, 3.0, 999), 1000.0]  # one 1 s stall among 1-3 ms
    low, high, above = latency_axis_ms(ms)
    p99 = float(np.percentile(ms, 99))
    assert low == 1.0 and high == pytest.approx(p99 * LATENCY_AXIS_MARGIN)
    assert high < 4.0 and above == 1  # the stall is counted, not drawn
    low, high, above = latency_axis_ms(np.array([2.0, 2.0]))  # one value: a usable axis
    assert high > low and above == 0


def test_figure_against_n_has_a_panel_per_quantity_on_a_log2_axis(tmp_path):
    from orchestrator.analysis.panels import Panel
    from orchestrator.analysis.plots import figure_against_n, plot_against_n

    rows = [{"agents": 256, "rx": 2200.0, "tick": 19.0, "a": 1.0, "b": None},
            {"agents": 64, "rx": 2000.0, "tick": 22.0, "a": 2.0, "b": 3.0}]  # any order
    panels = [Panel("rx [kB]", ("rx",), 1e-3), Panel("tick [us]", ("tick",)),
              Panel("parts", ("a", "b"), labels=("first", "second"))]
    fig = figure_against_n(rows, panels, ncols=2)
    shown = [ax for ax in fig.axes if ax.get_visible()]
    assert [ax.get_title() for ax in shown] == ["rx [kB]", "tick [us]", "parts"]
    assert len(fig.axes) == 4  # a 2 x 2 grid, the fourth hidden
    assert all(ax.get_xscale() == "log" for ax in shown)
    rx_line = shown[0].get_lines()[0]
    assert list(rx_line.get_xdata()) == [64.0, 256.0]  # sorted by N
    assert list(rx_line.get_ydata()) == pytest.approx([2.0, 2.2])  # the factor applied
    assert np.isnan(shown[2].get_lines()[1].get_ydata()[1])  # a missing value is a gap
    assert [t.get_text() for t in shown[2].get_legend().get_texts()] == ["first", "second"]
    assert all(ax.get_ylim()[0] == 0.0 for ax in shown)
    path = plot_against_n(rows, panels, tmp_path / "n.png")
    from PIL import Image

    with Image.open(path) as im:
        assert im.format == "PNG"


def test_figure_against_n_draws_a_single_n_and_refuses_nothing_to_draw():
    from orchestrator.analysis.panels import Panel
    from orchestrator.analysis.plots import figure_against_n

    fig = figure_against_n([{"agents": 64, "x": 1.5, "y": None}],
                           [Panel("x", ("x",)), Panel("y", ("y",))])
    ax, empty = fig.axes
    assert list(ax.get_lines()[0].get_xdata()) == [64.0]
    assert [t.get_text() for t in ax.get_xticklabels()] == ["64"]
    assert ax.get_xlim()[0] < 64.0 < ax.get_xlim()[1] and ax.get_ylim()[1] > 1.5
    assert [t.get_text() for t in empty.texts] == ["no values"]  # said, not left blank
    with pytest.raises(ValueError, match="at least one row"):
        figure_against_n([], [Panel("x", ("x",))])
    with pytest.raises(ValueError, match="at least one row"):
        figure_against_n([{"agents": 64, "x": 1.5}], [])
    with pytest.raises(ValueError, match="no columns"):
        Panel("x", ())
    with pytest.raises(ValueError, match="1 labels for 2 columns"):
        Panel("x", ("a", "b"), labels=("a",))
