"""Figures: a run's trajectories (like the paper's Fig. of setups), a GIF of a run, and the
report's bar plots. Matplotlib's object API with the Agg canvas only: no pyplot, no
display, no global state.
"""

from __future__ import annotations

import io
import math
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.collections import PatchCollection
from matplotlib.figure import Figure
from matplotlib.patches import Circle

from agent.core.scenario import Scenario
from agent.files import replace_file
from eifp_wire import TIMING_COLUMNS
from orchestrator.analysis.latency import WALL_STAGES
from orchestrator.analysis.metrics import RunSpec, contact_episodes
from orchestrator.analysis.panels import Panel
from orchestrator.analysis.rundir import RunData, read_run_dir, read_timing

DISC_INTERVAL_S = 10.0
"""Robot discs are drawn every this many seconds along the paths."""


def save_figure(fig: Figure, path: Path, dpi: int) -> Path:
    """Render `fig` as the image format of `path`'s suffix and write it atomically, never
    through a symlink (`agent.files.replace_file`)."""
    buf = io.BytesIO()
    fig.savefig(buf, dpi=dpi, format=Path(path).suffix.lstrip(".") or "png")
    return replace_file(path, buf.getvalue())


def _figure(width_in: float, height_in: float) -> Figure:
    fig = Figure(figsize=(width_in, height_in), layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def robot_colours(n: int) -> np.ndarray:
    """(n, 4) RGBA, distinct for up to 20 robots, then cycling through a colour wheel."""
    from matplotlib import colormaps

    if n <= 10:
        return colormaps["tab10"](np.arange(n))
    if n <= 20:
        return colormaps["tab20"](np.arange(n))
    return colormaps["hsv"](np.linspace(0.0, 1.0, n, endpoint=False))


def _draw_scene(ax: Axes, data: RunData) -> None:
    """Obstacles (at t = 0, with their path if moving), starts and goals."""
    s = data.scenario
    colours = robot_colours(len(s.robots))
    t_end = float(data.trajectory.t_s[-1]) if data.trajectory.t_s.size else 0.0
    for o in s.obstacles:
        ax.add_patch(Circle(o.center, o.radius_m, color="0.55", alpha=0.6, zorder=1))
        if any(o.velocity):
            end = np.asarray(o.center) + np.asarray(o.velocity) * t_end
            ax.plot([o.center[0], end[0]], [o.center[1], end[1]], ls=":", c="0.55", zorder=1)
    for r, c in zip(s.robots, colours):
        ax.plot(*r.start[:2], marker="o", ms=6, mfc="white", mec=c, mew=1.5, zorder=4)
        ax.plot(*r.goal, marker="*", ms=11, c=c, mec="black", mew=0.4, zorder=4)


def profile_note(scenario: Scenario) -> str:
    """`` (paper profile)`` for a run of the paper's method as written, else empty: titles
    and summary headers tell such a run from a default one."""
    return " (paper profile)" if scenario.planner_config.is_paper else ""


def _finish_axes(ax: Axes, data: RunData, title: str | None) -> None:
    s = data.scenario
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.grid(True, lw=0.3, alpha=0.5)
    planners = sorted({r.planner for r in s.robots})
    ax.set_title(title or f"{s.name} - {', '.join(planners)}{profile_note(s)} - "
                          f"{len(s.robots)} robots",
                 fontsize=10)


def plot_trajectories(data: RunData, path: Path, *, disc_interval_s: float = DISC_INTERVAL_S,
                      title: str | None = None, dpi: int = 120) -> Path:
    """The run's paths: a colour per robot, start (o) and goal (*) markers, robot discs
    every `disc_interval_s`, and contacts marked with a red x.

    Returns:
        path, written as PNG (or whatever its suffix names).
    """
    traj, s = data.trajectory, data.scenario
    fig = _figure(7.0, 7.0)
    ax = fig.add_subplot()
    _draw_scene(ax, data)
    colours = robot_colours(len(s.robots))
    if traj.t_s.size:
        step = max(1, int(round(disc_interval_s / max(np.median(np.diff(traj.t_s)), 1e-9)))
                   ) if traj.t_s.size > 1 else 1
        for k, (r, c) in enumerate(zip(s.robots, colours)):
            xy = traj.pose[:, k, :2]
            ax.plot(xy[:, 0], xy[:, 1], c=c, lw=1.4, zorder=3, label=f"robot {r.id}")
            discs = [Circle(p, r.radius_m) for p in xy[::step]]
            ax.add_collection(PatchCollection(discs, facecolor=c, edgecolor=c, alpha=0.18,
                                              lw=0.6, zorder=2))
        episodes = contact_episodes(traj, RunSpec.from_scenario(s)).episodes
        spots = [_contact_spot(data, e.t_s, e.id_a, e.id_b) for e in episodes]
        spots = [p for p in spots if p is not None]
        if spots:
            pts = np.array(spots)
            ax.plot(pts[:, 0], pts[:, 1], "x", c="red", ms=10, mew=2.5, zorder=5,
                    label=f"contact ({len(spots)})")
    if len(s.robots) <= 16:
        ax.legend(fontsize=7, loc="best", framealpha=0.7)
    _finish_axes(ax, data, title)
    path = Path(path)
    save_figure(fig, path, dpi)
    return path


def _contact_spot(data: RunData, t_s: float, id_a: int, id_b: int) -> np.ndarray | None:
    """Midpoint between the two discs' centres at the sample nearest t_s."""
    traj, s = data.trajectory, data.scenario
    k = int(np.argmin(np.abs(traj.t_s - t_s)))
    col = {r.id: i for i, r in enumerate(s.robots)}

    def centre(i: int) -> np.ndarray | None:
        xy: np.ndarray
        if i in col:
            xy = traj.pose[k, col[i], :2]
            return xy
        for o in s.obstacles:
            if o.id == i:
                xy = np.asarray(o.center) + np.asarray(o.velocity) * traj.t_s[k]
                return xy
        return None

    a, b = centre(id_a), centre(id_b)
    return None if a is None or b is None else (a + b) / 2.0


def mp4_available() -> str | None:
    """None if MP4 can be written, else why not (the optional ``video`` extra)."""
    try:
        import imageio_ffmpeg

        imageio_ffmpeg.get_ffmpeg_exe()
    except (ImportError, RuntimeError) as exc:
        return (f"MP4 needs imageio-ffmpeg (pip install 'eifp-swarm[video]'): "
                f"{type(exc).__name__}: {exc}")
    return None


def animate(data: RunData, path: Path, *, fps: int = 10, max_frames: int = 200,
            tail_s: float = 8.0, dpi: int = 80) -> Path:
    """A GIF (or, for a ``.mp4`` path, an H.264 MP4) of the run: discs moving, a fading
    trail, sim time in a corner.

    At most `max_frames` frames, evenly spaced in sim time. Frames are rendered by
    matplotlib (the static background once, then only the moving artists, blitted) and
    written by Pillow with one shared palette, or piped to imageio-ffmpeg's ffmpeg (the
    optional ``video`` extra; 480 x 480 pixels at the default dpi, a multiple of 16).
    """
    from PIL import Image

    path = Path(path)
    mp4 = path.suffix.lower() == ".mp4"
    if mp4 and (why := mp4_available()) is not None:
        raise RuntimeError(why)
    traj, s = data.trajectory, data.scenario
    if traj.t_s.size == 0:
        raise ValueError("empty trajectory: nothing to animate")
    fig = Figure(figsize=(6.0, 6.0), dpi=dpi)  # fixed layout: no per-frame layout work
    canvas = FigureCanvasAgg(fig)
    ax = fig.add_axes((0.12, 0.1, 0.83, 0.82))
    _draw_scene(ax, data)
    colours = robot_colours(len(s.robots))
    xy_all = traj.pose[:, :, :2].reshape(-1, 2)
    pts = np.vstack([xy_all, [r.goal for r in s.robots]])
    lo, hi = pts.min(axis=0) - 2.0, pts.max(axis=0) + 2.0
    half = (hi - lo).max() / 2.0  # a square view, so that equal aspect needs no adjusting
    mid = (lo + hi) / 2.0
    _finish_axes(ax, data, None)
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlim(mid[0] - half, mid[0] + half)
    ax.set_ylim(mid[1] - half, mid[1] + half)
    discs = [Circle(tuple(traj.pose[0, k, :2].tolist()), r.radius_m, fc=c, ec="black", lw=0.5,
                    alpha=0.85, zorder=3) for k, (r, c) in enumerate(zip(s.robots, colours))]
    for d in discs:
        ax.add_patch(d)
    trails = [ax.plot([], [], c=c, lw=1.0, zorder=2)[0] for c in colours]
    clock = ax.text(0.02, 0.97, "", transform=ax.transAxes, va="top", fontsize=9,
                    bbox={"fc": "white", "ec": "none", "alpha": 0.7})
    moving = [*trails, *discs, clock]

    for a in moving:  # the background without the moving artists, rendered once
        a.set_visible(False)
    canvas.draw()
    background = canvas.copy_from_bbox(fig.bbox)
    for a in moving:
        a.set_visible(True)

    frames = np.unique(np.linspace(0, traj.t_s.size - 1, min(max_frames, traj.t_s.size))
                       .round().astype(int))
    dt = float(np.median(np.diff(traj.t_s))) if traj.t_s.size > 1 else 1.0
    tail = max(1, int(tail_s / dt))
    size = canvas.get_width_height()
    images: list[Image.Image] = []
    writer = None
    if mp4:
        import imageio_ffmpeg

        writer = imageio_ffmpeg.write_frames(str(path), size, fps=fps, codec="libx264",
                                             pix_fmt_in="rgb24", pix_fmt_out="yuv420p",
                                             macro_block_size=16, ffmpeg_log_level="error")
        writer.send(None)  # start the generator
    for i in frames.tolist():
        for k, (d, line) in enumerate(zip(discs, trails)):
            d.set_center(tuple(traj.pose[i, k, :2].tolist()))
            seg = traj.pose[max(0, i - tail):i + 1, k, :2]
            line.set_data(seg[:, 0], seg[:, 1])
        clock.set_text(f"t = {traj.t_s[i]:.1f} s")
        canvas.restore_region(background)
        for a in moving:
            ax.draw_artist(a)
        if writer is not None:
            writer.send(np.asarray(canvas.buffer_rgba())[:, :, :3].tobytes())
            continue
        rgb = Image.frombuffer("RGBA", size, bytes(canvas.buffer_rgba()), "raw", "RGBA", 0, 1)
        rgb = rgb.convert("RGB")
        images.append(rgb.quantize(colors=255) if not images
                      else rgb.quantize(palette=images[0]))
    if writer is not None:
        writer.close()
        return path
    buf = io.BytesIO()
    images[0].save(buf, format="GIF", save_all=True, append_images=images[1:],
                   duration=max(20, round(1000 / fps)), loop=0)
    replace_file(path, buf.getvalue())
    return path


def plot_report_bars(stats: Mapping[tuple[str, str], Mapping[str, tuple[float, float]]],
                     metrics: Sequence[tuple[str, str]], out_dir: Path, *,
                     prefix: str = "report") -> list[Path]:
    """Grouped bar plots: one bar per planner in each setup, mean with +-std error bars.

    Args:
        stats: (setup, planner) -> metric key -> (mean, std); missing metrics are skipped.
        metrics: (metric key, axis label) in plotting order.
        out_dir: where `<prefix>_<metric>.png` and `<prefix>_all.png` go.

    Returns:
        the written files (one per metric, then the combined figure).
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    setups = sorted({k[0] for k in stats})
    planners = sorted({k[1] for k in stats})
    written = []
    cols = 2 if len(metrics) > 1 else 1
    rows = (len(metrics) + cols - 1) // cols
    combined = _figure(6.0 * cols, 3.6 * rows)
    axes = combined.subplots(rows, cols, squeeze=False).ravel()
    for k, (key, label) in enumerate(metrics):
        single = _figure(max(5.0, 1.2 * len(setups) + 2.0), 3.6)
        for ax in (single.add_subplot(), axes[k]):
            _bars(ax, stats, setups, planners, key, label)
        path = out_dir / f"{prefix}_{key}.png"
        save_figure(single, path, 110)
        written.append(path)
    for ax in axes[len(metrics):]:
        ax.set_visible(False)
    path = out_dir / f"{prefix}_all.png"
    save_figure(combined, path, 110)
    written.append(path)
    return written


def _bars(ax: Axes, stats: Mapping[tuple[str, str], Mapping[str, tuple[float, float]]],
          setups: Sequence[str], planners: Sequence[str], key: str, label: str) -> None:
    width = 0.8 / max(1, len(planners))
    x = np.arange(len(setups))
    colours = robot_colours(max(1, len(planners)))
    for j, planner in enumerate(planners):
        mean = np.array([stats.get((s, planner), {}).get(key, (np.nan, np.nan))[0]
                         for s in setups], dtype=float)
        std = np.array([stats.get((s, planner), {}).get(key, (np.nan, np.nan))[1]
                        for s in setups], dtype=float)
        ax.bar(x + (j - (len(planners) - 1) / 2.0) * width, np.nan_to_num(mean), width,
               yerr=np.nan_to_num(std), capsize=2, color=colours[j], label=planner)
    ax.set_xticks(x, setups, rotation=30, ha="right", fontsize=8)
    ax.set_ylabel(label, fontsize=9)
    ax.grid(True, axis="y", lw=0.3, alpha=0.5)
    ax.legend(fontsize=7)


def write_run_plots(out_dir: Path, *, gif: bool, mp4: bool = False) -> None:
    """trajectory.png (and trajectory.gif, trajectory.mp4); a plotting failure is reported,
    not fatal."""
    try:
        data = read_run_dir(out_dir)
        plot_trajectories(data, out_dir / "trajectory.png")
        stamps = read_timing(out_dir)
        if stamps.shape[0]:
            plot_wall_latency(stamps, out_dir / "latency.png")
        if gif:
            animate(data, out_dir / "trajectory.gif")
        if mp4:
            animate(data, out_dir / "trajectory.mp4")
    except Exception as exc:  # noqa: BLE001 - the run itself is done; keep its result
        print(f"warning: plotting failed: {type(exc).__name__}: {exc}", file=sys.stderr)


LATENCY_AXIS_MARGIN = 1.15
"""latency.png's x axes end this factor past each stage's p99 (`latency_axis_ms`)."""


def latency_axis_ms(ms: np.ndarray) -> tuple[float, float, int]:
    """The x range of one latency histogram and what falls past it.

    The axis ends just past the p99 (`LATENCY_AXIS_MARGIN`), not at the largest value: one
    stall of a second would otherwise squash every distribution into its first bin. The
    samples past the end are counted (and the panel says so, with the largest).

    Args:
        ms: (K,) latencies [ms], K >= 1.

    Returns:
        (low, high) of the axis [ms] and how many samples lie above `high`.
    """
    ms = np.asarray(ms, dtype=float)
    low = float(ms.min())
    high = max(float(np.percentile(ms, 99)) * LATENCY_AXIS_MARGIN, low + 1e-3)
    return low, high, int(np.count_nonzero(ms > high))


def plot_wall_latency(stamps: np.ndarray, path: Path) -> Path | None:
    """latency.png: a histogram per wall-clock stage (`latency.WALL_STAGES`), p50 and p99
    marked, each x axis clipped just past the p99 (`latency_axis_ms`; the panel says how
    many samples lie beyond, and the largest); None (nothing written) if no stage could be
    measured.

    Args:
        stamps: (K, 9) timing.csv stamps (`eifp_wire.messages.TIMING_COLUMNS`).
        path: the PNG to write.
    """
    stamps = np.asarray(stamps, dtype=np.int64).reshape(-1, len(TIMING_COLUMNS))
    col = {name: stamps[:, k] for k, name in enumerate(TIMING_COLUMNS)}
    same = (col["robot_clock"] == col["world_clock"]) & (col["robot_clock"] != 0)
    panels = []
    for stage, start, end, crosses in WALL_STAGES:
        ok = (col[start] > 0) & (col[end] > 0) & (same if crosses else True)
        ms = (col[end][ok] - col[start][ok]) / 1e6
        if ms.size:
            panels.append((stage, ms))
    if not panels:
        return None
    cols = 2
    rows = (len(panels) + cols - 1) // cols
    fig = _figure(5.0 * cols, 2.4 * rows)
    axes = fig.subplots(rows, cols, squeeze=False).ravel()
    for ax, (stage, ms) in zip(axes, panels):
        low, high, above = latency_axis_ms(ms)
        ax.hist(ms[ms <= high], bins=min(60, max(10, ms.size // 20)), range=(low, high),
                color="tab:blue", alpha=0.8)
        ax.set_xlim(low, high)
        for q, style in ((50, "-"), (99, "--")):
            v = float(np.percentile(ms, q))
            ax.axvline(v, color="black", ls=style, lw=0.8, label=f"p{q} {v:.2f} ms")
        clipped = (f"; axis to p99, {above} above (max {float(ms.max()):.1f} ms)"
                   if above else "")
        ax.set_title(f"{stage}{clipped}", fontsize=9)
        ax.set_xlabel("wall ms")
        ax.legend(fontsize=7)
    for ax in axes[len(panels):]:
        ax.set_visible(False)
    path = Path(path)
    save_figure(fig, path, 100)
    return path


def plot_benchmark(rows: Sequence[Mapping[str, Any]], path: Path, *, title: str = "") -> Path:
    """The benchmark at a glance: per case, planners side by side, three panels.

    Success rate (%); oscillations per robot (bar: median over the robots, tick: the
    largest one robot had); time ratio (mean). Bars of a (case, planner) in which not every
    run succeeded are hatched in the lower panels, so a good-looking ratio of a failing
    planner is not mistaken for a result.

    Args:
        rows: `orchestrator.experiments.benchmark.summarize` rows (keys case, planner,
            success_rate, osc_per_robot_median, osc_per_robot_max, time_ratio_mean).
        path: the PNG to write.
    """
    cases = list(dict.fromkeys(r["case"] for r in rows))
    planners = list(dict.fromkeys(r["planner"] for r in rows))
    by = {(r["case"], r["planner"]): r for r in rows}
    fig = _figure(max(7.0, 0.55 * len(cases) * max(1, len(planners)) / 2.0 + 2.5), 8.0)
    axes = fig.subplots(3, 1, sharex=True)
    colours = robot_colours(max(1, len(planners)))
    width = 0.8 / max(1, len(planners))
    x = np.arange(len(cases))

    def values(key: str, planner: str) -> np.ndarray:
        return np.array([np.nan if by.get((c, planner), {}).get(key) is None
                         else float(by[(c, planner)][key]) for c in cases], dtype=float)

    for j, planner in enumerate(planners):
        xs = x + (j - (len(planners) - 1) / 2.0) * width
        success = values("success_rate", planner)
        failed = np.isfinite(success) & (success < 1.0)
        axes[0].bar(xs, np.nan_to_num(100.0 * success), width, color=colours[j],
                    label=planner)
        for xk, sk in zip(xs, success):
            if np.isfinite(sk):
                axes[0].text(xk, 100.0 * sk + 1.5, f"{100.0 * sk:.0f}", ha="center",
                             va="bottom", fontsize=6,
                             color="black" if sk >= 1.0 else "red")
        for k, key in ((1, "osc_per_robot_median"), (2, "time_ratio_mean")):
            v = values(key, planner)
            bars = axes[k].bar(xs, np.nan_to_num(v), width, color=colours[j],
                               edgecolor="black", linewidth=0.3)
            for bar, bad in zip(bars, failed):
                if bad:
                    bar.set_hatch("///")
            missing = ~np.isfinite(v) & np.isfinite(success)
            axes[k].scatter(xs[missing], np.zeros(int(missing.sum())), marker="x",
                            color="red", s=25, zorder=3,
                            label="no value (no robot arrived)" if j == 0 and k == 2
                            else None)
        top = values("osc_per_robot_max", planner)
        axes[1].scatter(xs, top, marker="_", s=60, color="black", zorder=3,
                        label="max (one robot)" if j == 0 else None)
    axes[0].set_ylabel("success %\n(runs)")
    axes[0].set_ylim(0, 115)
    axes[1].set_ylabel("oscillations / robot\n(median, max)")
    axes[2].set_ylabel("time ratio\n(mean, arrived robots)")
    axes[2].axhline(1.0, color="grey", lw=0.6, ls=":")
    for ax in axes:
        ax.grid(True, axis="y", lw=0.3, alpha=0.5)
    fig.legend(*axes[0].get_legend_handles_labels(), loc="outside upper center",
               ncols=max(1, len(planners)), fontsize=8)
    axes[1].legend(fontsize=7, loc="upper left")
    if any(h for h in axes[2].get_legend_handles_labels()[0]):
        axes[2].legend(fontsize=7, loc="upper left")
    axes[2].set_xticks(x, cases, rotation=40, ha="right", fontsize=8)
    axes[2].text(0.995, 0.97, "hatched: not every run succeeded", transform=axes[2].transAxes,
                 ha="right", va="top", fontsize=7)
    if title:
        axes[0].set_title(title, fontsize=9)
    path = Path(path)
    save_figure(fig, path, 110)
    return path


def figure_against_n(rows: Sequence[Mapping[str, Any]], panels: Sequence[Panel], *,
                     ncols: int = 3, x_key: str = "agents", x_label: str = "robots N",
                     title: str = "") -> Figure:
    """One panel per figure against N, N on a log2 axis, y from 0 (a flat cost looks flat).

    A missing value (None) leaves a gap. Panels past the last are hidden.

    Args:
        rows: one mapping per N, with `x_key` and the panels' keys.
        panels: what to draw, in reading order.
        ncols: panels per row of the figure.
        x_key: the rows' column that holds N.
        x_label: the x axes' label.
        title: the figure's title (none if empty).
    Raises:
        ValueError: no rows or no panels.
    """
    if not rows or not panels:
        raise ValueError("a figure against N needs at least one row and one panel")
    ordered = sorted(rows, key=lambda r: float(r[x_key]))
    ns = [float(r[x_key]) for r in ordered]
    ncols = max(1, min(ncols, len(panels)))
    nrows = -(-len(panels) // ncols)
    fig = _figure(3.2 * ncols + 0.4, 2.6 * nrows + (0.3 if title else 0.0))
    axes = fig.subplots(nrows, ncols, squeeze=False).ravel()
    for ax, panel in zip(axes, panels):
        labels = panel.labels or panel.keys
        drawn = 0
        for j, key in enumerate(panel.keys):
            ys = [math.nan if r.get(key) is None else float(r[key]) * panel.factor
                  for r in ordered]
            drawn += sum(math.isfinite(y) for y in ys)
            ax.plot(ns, ys, "o-" if j == 0 else "s--", ms=4, lw=1.2, label=labels[j])
        if not drawn:
            ax.text(0.5, 0.5, "no values", transform=ax.transAxes, ha="center", fontsize=8)
        ax.set_title(panel.title, fontsize=9)
        ax.set_xlabel(x_label, fontsize=8)
        if min(ns) > 0:  # about a third of an octave either side
            ax.set_xscale("log", base=2)
            ax.set_xlim(min(ns) / 1.25, max(ns) * 1.25)
        ax.set_xticks(ns, [f"{n:g}" for n in ns])
        ax.minorticks_off()
        high = ax.get_ylim()[1]
        ax.set_ylim(0.0, high * 1.08 if drawn and high > 0 else None)  # room above the top
        ax.tick_params(labelsize=7)
        if len(panel.keys) > 1:
            ax.legend(fontsize=6)
        ax.grid(alpha=0.3)
    for ax in axes[len(panels):]:
        ax.set_visible(False)
    if title:
        fig.suptitle(title, fontsize=9)
    return fig


def plot_against_n(rows: Sequence[Mapping[str, Any]], panels: Sequence[Panel], path: Path, *,
                   ncols: int = 3, x_label: str = "robots N", title: str = "",
                   dpi: int = 100) -> Path:
    """`figure_against_n`, written to `path` (`save_figure`)."""
    fig = figure_against_n(rows, panels, ncols=ncols, x_label=x_label, title=title)
    return save_figure(fig, Path(path), dpi)
