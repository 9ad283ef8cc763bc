"""A robot process's lifecycle under process faults (`world.sim.lifecycle`), in sim time."""

from __future__ import annotations

import math

import pytest

from world.sim.lifecycle import ProcessState, RobotLifecycle, Transition

LEASE_S = 1.0
RESTART_S = 2.0


def _fault(life: RobotLifecycle, kind: str, t_s: float, duration_s: float = 0.0) -> bool:
    return life.fault(kind, t_s, duration_s, lease_s=LEASE_S, restart_delay_s=RESTART_S)


def _run(life: RobotLifecycle, t0_s: float, t1_s: float, dt_s: float = 0.02
         ) -> list[tuple[float, Transition]]:
    """Every transition between t0 and t1, with its tick's time (ticks as the world adds them)."""
    seen = []
    t = t0_s
    while t <= t1_s + 1e-9:
        seen += [(round(t, 6), change) for change in life.advance(t)]
        t += dt_s
    return seen


def test_a_stop_shorter_than_the_lease_resumes_before_the_world_notices() -> None:
    life = RobotLifecycle()
    assert _fault(life, "stop", 4.0, 0.5) is False  # frozen, not dead
    assert life.state is ProcessState.STOPPED and not life.up and not life.down
    assert _run(life, 4.0, 6.0) == [(4.5, Transition.RESUMED)]
    assert life.up


def test_a_stop_longer_than_the_lease_is_lost_at_the_lease_until_it_resumes() -> None:
    life = RobotLifecycle()
    _fault(life, "stop", 4.0, 2.0)
    seen = _run(life, 4.0, 7.0)
    lease = [t for t, c in seen if c is Transition.LEASE_EXPIRED]
    # Reported at every tick from the lease's end (5.0 s) to the resumption (6.0 s), which
    # comes after it in the same tick.
    assert lease[0] == pytest.approx(5.0) and lease[-1] == pytest.approx(6.0)
    assert len(lease) == 51
    assert seen[-1] == (6.0, Transition.RESUMED) and seen[-2] == (6.0, Transition.LEASE_EXPIRED)
    assert life.up


def test_a_kill_is_for_good_and_a_restart_comes_back_after_its_delay() -> None:
    killed, restarted = RobotLifecycle(), RobotLifecycle()
    assert _fault(killed, "kill", 5.0) is True
    assert _fault(restarted, "restart", 5.0) is True
    assert killed.down and killed.gone_for_good
    assert restarted.down and not restarted.gone_for_good
    assert _run(killed, 5.0, 20.0) == []
    assert _run(restarted, 5.0, 20.0) == [(7.0, Transition.RESTARTED)]
    assert restarted.up and restarted.back_s == math.inf


@pytest.mark.parametrize("kind", ["stop", "kill", "restart"])
def test_a_dead_process_takes_no_further_fault(kind: str) -> None:
    life = RobotLifecycle()
    _fault(life, "kill", 1.0)
    assert _fault(life, kind, 2.0, 1.0) is False
    assert life.gone_for_good


def test_a_stopped_process_can_be_killed_but_not_stopped_again() -> None:
    life = RobotLifecycle()
    _fault(life, "stop", 1.0, 3.0)
    assert _fault(life, "stop", 1.5, 10.0) is False
    assert life.resume_s == 4.0  # the first stop's
    assert _fault(life, "kill", 2.0) is True
    assert life.gone_for_good and life.resume_s == life.lease_s == math.inf
    assert _run(life, 2.0, 10.0) == []  # neither the lease nor the resumption comes


def test_an_unknown_fault_changes_nothing() -> None:
    life = RobotLifecycle()
    assert _fault(life, "reboot", 1.0) is False
    assert life == RobotLifecycle()
