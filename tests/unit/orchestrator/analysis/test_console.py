"""The live progress line (`orchestrator.analysis.console.ProgressLine`)."""

from __future__ import annotations

import io
from types import SimpleNamespace

from orchestrator.analysis.console import ProgressLine, run_summary


class _Tty(io.StringIO):
    def isatty(self) -> bool:
        return True


def _progress(arrived: int, t: float = 3.0, lost: frozenset[int] = frozenset()):
    return SimpleNamespace(arrived=frozenset(range(arrived)), n_robots=4, sim_t_s=t,
                           wall_s=1.0, contacts=0, started=True, lost=lost)


def test_a_log_file_gets_plain_lines_at_most_every_5_s() -> None:
    out = io.StringIO()
    line = ProgressLine("setup_d", out)
    line(_progress(1))
    line(_progress(2))  # within 5 s of the first: not written
    line.done()
    text = out.getvalue()
    assert text.count("\n") == 1 and "[setup_d]" in text and "arrived 1/4" in text


def test_a_terminal_gets_a_progress_bar_of_arrivals() -> None:
    out = _Tty()
    line = ProgressLine("setup_d", out)
    line(_progress(1))
    line(_progress(3, lost=frozenset({2})))
    line.done()
    text = out.getvalue()
    assert "setup_d" in text and "3/4" in text and "lost [2]" in text


def test_quiet_writes_nothing() -> None:
    out = _Tty()
    line = ProgressLine("x", out, quiet=True)
    line(_progress(1))
    line.done()
    assert out.getvalue() == ""


def test_summary_lists_the_run_and_each_robot() -> None:
    text = run_summary({"success": True, "arrived": 2, "robots": 2,
                        "per_robot": [{"id": 0, "arrived": True}, {"id": 1, "arrived": True}]},
                       "setup_a")
    assert "robots arrived" in text and "2/2" in text and text.count("yes") == 3


def test_summary_lists_the_latency_of_each_router_group() -> None:
    wall = {"p50": 2.0, "p99": 3.0, "max": 4.0, "n": 5}
    text = run_summary({"success": True, "arrived": 1, "robots": 1, "per_robot": [],
                        "wall_latency_ms": {"sense_to_act": wall, "transport": wall},
                        "wall_latency_ms_by_router": {
                            "world": {"sense_to_act": wall, "transport": wall},
                            "router-b": {"sense_to_act": wall}}}, "setup_d")
    assert "on the wire, both ways p50/p99/max" in text
    assert "sense to act, robots on world" in text
    assert "on the wire, both ways, robots on world" in text
    assert "sense to act, robots on router-b" in text
    assert "on the wire, both ways, robots on router-b" not in text
