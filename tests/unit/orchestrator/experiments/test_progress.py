"""Following a run from its files (`orchestrator.experiments.progress`)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from orchestrator.experiments.progress import EventTail, distributed_progress, last_trajectory_time


def test_event_tail_reads_only_complete_lines(tmp_path: Path) -> None:
    path = tmp_path / "events.jsonl"
    tail = EventTail(path)
    assert tail.poll() == []  # no file yet
    path.write_text('{"kind": "start", "t": 0.0}\n{"kind": "arr')
    assert [e["kind"] for e in tail.poll()] == ["start"]
    with open(path, "a") as f:
        f.write('ived", "t": 1.5, "robot": 2}\n')
    assert tail.poll() == [{"kind": "arrived", "t": 1.5, "robot": 2}]
    assert len(tail.events) == 2 and tail.poll() == []


def testlast_trajectory_time(tmp_path: Path) -> None:
    path = tmp_path / "trajectory.csv"
    assert last_trajectory_time(path) == 0.0
    path.write_text("t,robot,x,y,theta,v,omega\n")
    assert last_trajectory_time(path) == 0.0
    path.write_text("t,robot,x,y,theta,v,omega\n1.2000,0,0,0,0,0,0\n1.2200,0,0,0,0,0,0\n1.24")
    assert last_trajectory_time(path) == pytest.approx(1.22)


def test_progress_summarises_events(tmp_path: Path) -> None:
    events = [json.loads(line) for line in (
        '{"kind": "start", "t": 0.0}',
        '{"kind": "arrived", "t": 3.0, "robot": 1}',
        '{"kind": "robot_lost", "t": 3.5, "robot": 0}',
        '{"kind": "contact", "t": 4.0, "a": 0, "b": 2}',
        '{"kind": "robot_lost", "t": 4.2, "robot": 2}',
        '{"kind": "robot_rejoined", "t": 4.4, "robot": 2}',
    )]
    p = distributed_progress(events, tmp_path, 0.0, 3, [])
    assert p.started and p.arrived == {1} and p.lost == {0} and p.contacts == 1
    assert p.sim_t_s == pytest.approx(4.4) and p.n_robots == 3 and p.robots_running == 0
