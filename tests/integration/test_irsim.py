"""The planner where people already simulate: IR-SIM worlds whose robots use eIFP-MPC through
the behaviour `agent.irsim` registers, and the plain-Python example of docs/api.md.

Headless (no figure is made); each run is a few seconds of CPU.
"""

from __future__ import annotations

import itertools
import re
from pathlib import Path

import numpy as np
import pytest

irsim = pytest.importorskip("irsim", reason="IR-SIM is not installed (it comes with pyrvo)")

import agent.irsim  # noqa: E402  (registers the behaviour)

REPO = Path(__file__).resolve().parents[2]
WORLD = REPO / "docs" / "examples" / "irsim_world.yaml"

SIX_ON_A_CIRCLE = """\
world: {height: 20, width: 20, offset: [-10, -10], step_time: 0.1,
        collision_mode: 'unobstructed'}
robot:
  - number: 6
    distribution: {name: 'manual'}
    kinematics: {name: 'diff'}
    shape: {name: 'circle', radius: 0.4}
    vel_max: [1.1, 1.5]
    vel_min: [0.0, -1.5]
    acce: [1.5, 6.0]
    state: %s
    goal: %s
    goal_threshold: 0.2
    behavior: {name: 'eifp'}
"""


def run_world(path: Path, max_steps: int = 1000) -> tuple[object, float]:
    """Step the world to its end; (the env, smallest surface gap over every pair [m])."""
    env = irsim.make(str(path), display=False, headless=True, log_level="ERROR")
    objects = env.robot_list + env.obstacle_list
    gap_m = np.inf
    for _ in range(max_steps):
        env.step()
        for a, b in itertools.combinations(objects, 2):
            d = np.linalg.norm(a.state[:2, 0] - b.state[:2, 0]) - a.radius - b.radius
            gap_m = min(gap_m, float(d))
        if env.done():
            break
    return env, gap_m


def test_the_example_world_runs_every_robot_to_its_goal_without_contact() -> None:
    env, gap_m = run_world(WORLD)
    robots = env.robot_list
    assert len(robots) == 4 and len(env.obstacle_list) == 1
    assert all(r.arrive for r in robots), [r.state[:2, 0] for r in robots]
    assert not any(r.collision for r in robots)
    assert gap_m > 0.05, gap_m  # measured here, not only IR-SIM's own collision flag
    assert env.time < 30.0  # 10 m at 1.1 m/s is 9 s: no robot stalled on the way
    env.end(0)


def test_six_robots_swapping_across_a_circle(tmp_path: Path) -> None:
    angles = np.arange(6) * np.pi / 3
    starts = [[round(float(7 * np.cos(a)), 3), round(float(7 * np.sin(a)), 3),
               round(float(a + np.pi), 3)] for a in angles]
    goals = [[-x, -y, 0.0] for x, y, _ in starts]
    path = tmp_path / "six.yaml"
    path.write_text(SIX_ON_A_CIRCLE % (starts, goals))
    env, gap_m = run_world(path)
    assert all(r.arrive for r in env.robot_list)
    assert not any(r.collision for r in env.robot_list) and gap_m > 0.0, gap_m
    env.end(0)


def test_an_unknown_planner_is_refused() -> None:
    with pytest.raises(ValueError, match="planner must be one of"):
        agent.irsim.EifpBehavior(planner="rrt")
    with pytest.raises(ValueError, match="profile must be one of"):
        agent.irsim.EifpBehavior(profile="fast")


def test_the_api_doc_example_runs_four_robots_to_their_goals(capsys) -> None:
    text = (REPO / "docs" / "api.md").read_text(encoding="utf-8")
    blocks = re.findall(r"```python\n(.*?)```", text, flags=re.S)
    example = next(b for b in blocks if "make_planner" in b)
    assert len(example.strip().splitlines()) <= 40  # "about thirty lines"
    scope: dict = {}
    exec(compile(example, "docs/api.md", "exec"), scope)  # noqa: S102 - our own doc
    assert scope["arrived"].all() and scope["min_gap_m"] > 0.0, scope["min_gap_m"]
    assert "arrived 4/4" in capsys.readouterr().out


def test_the_example_script_runs_headless() -> None:
    import subprocess
    import sys

    proc = subprocess.run([sys.executable, str(REPO / "docs/examples/irsim_run.py")],
                          capture_output=True, text=True, timeout=120, check=False, cwd=REPO)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "arrived 4/4, collisions 0" in proc.stdout
