"""`agent.process.StallWatch`: a stall is wall time neither the loop's CPU nor its waits explain."""

from __future__ import annotations

import pytest

from agent.process import StallWatch


class Clocks:
    """A wall clock and a thread CPU clock the test advances by hand."""

    def __init__(self) -> None:
        self.wall_s = 100.0
        self.cpu_s = 3.0

    def run(self, seconds: float) -> None:
        """The thread computes: both clocks advance."""
        self.wall_s += seconds
        self.cpu_s += seconds

    def idle(self, seconds: float) -> None:
        """The thread does not run (blocked, stopped or not scheduled)."""
        self.wall_s += seconds


@pytest.fixture
def clocks() -> Clocks:
    return Clocks()


@pytest.fixture
def watch(clocks: Clocks) -> StallWatch:
    w = StallWatch(wall=lambda: clocks.wall_s, cpu=lambda: clocks.cpu_s)
    assert w.tick() == 0.0  # the first call has nothing to compare with
    return w


def test_a_long_plan_and_a_full_nap_are_not_a_stall(clocks: Clocks, watch: StallWatch) -> None:
    clocks.run(0.4)  # a slow plan
    clocks.idle(0.25)  # then the nap times out
    watch.waited(0.25, 0.25)
    assert watch.tick() == pytest.approx(0.0)


def test_a_stop_during_the_nap_counts_beyond_the_naps_time_out(clocks: Clocks,
                                                               watch: StallWatch) -> None:
    clocks.run(0.002)
    clocks.idle(3.0)  # SIGSTOP while waiting on the pose queue with a 0.25 s time-out
    watch.waited(3.0, 0.25)
    assert watch.tick() == pytest.approx(2.75)


def test_a_stop_while_computing_is_a_stall(clocks: Clocks, watch: StallWatch) -> None:
    clocks.run(0.01)
    clocks.idle(1.5)  # stopped mid-plan: wall time passes, no CPU, no wait
    clocks.run(0.01)
    assert watch.tick() == pytest.approx(1.5)


def test_waits_add_up_and_each_iteration_starts_afresh(clocks: Clocks,
                                                       watch: StallWatch) -> None:
    clocks.idle(0.04)  # a CPU-token wait of 0.05 s at most
    watch.waited(0.04, 0.05)
    clocks.idle(0.2)  # a pose came after 0.2 s of a 0.25 s nap
    watch.waited(0.2, 0.25)
    clocks.idle(0.1)  # runnable but not scheduled
    assert watch.tick() == pytest.approx(0.1)
    clocks.idle(0.3)  # the earlier waits are not carried over
    assert watch.tick() == pytest.approx(0.3)


def test_a_wait_is_never_negative_and_the_stall_never_below_zero(clocks: Clocks,
                                                                 watch: StallWatch) -> None:
    watch.waited(-1.0, 0.25)  # a clock read out of order must not hide a stall
    clocks.idle(0.6)
    assert watch.tick() == pytest.approx(0.6)
    watch.waited(0.25, 0.25)  # a wait larger than the wall gap (rounding) gives 0, not < 0
    clocks.idle(0.1)
    assert watch.tick() == 0.0


def test_the_worst_ending_of_a_batch_follows_the_documented_order() -> None:
    from agent.process import ENDING_SEVERITY, ExitCode

    assert ExitCode.worst([]) == ExitCode.OK
    assert ExitCode.worst([0, 3, 0]) == ExitCode.INCOMPLETE
    # The order within a run (`ExitCode.of_run`): contact > lost > interrupted > time-out.
    assert ExitCode.worst([3, 130, 4]) == ExitCode.ROBOT_LOST
    assert ExitCode.worst([4, 1, 130]) == ExitCode.CONTACT
    # A run that could not be judged outranks any judged one; ERROR only from an ERROR.
    assert ExitCode.worst([1, 5]) == ExitCode.WORLD_LOST
    assert ExitCode.worst([1, 7]) == ExitCode.ERROR
    # A child killed by a signal (negative status) was interrupted, not broken.
    assert ExitCode.worst([3, -9]) == ExitCode.INTERRUPTED
    assert set(ENDING_SEVERITY) == set(ExitCode)
