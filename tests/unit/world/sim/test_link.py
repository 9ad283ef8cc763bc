"""The seeded link-fault model: delays, loss, duplication, reordering, determinism."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.examples import examples
from world.sim.link import LINK_COMMANDS, LINK_POSES, FaultyLink, LinkFaults, link_rng


def stream(faults: LinkFaults, n: int = 2000, period_s: float = 0.02, seed: int = 0,
           drain_s: float = 5.0) -> list[tuple[float, int]]:
    """(release time, message) for n messages sent every period_s, drained at that rate."""
    link = FaultyLink(faults, link_rng(seed, LINK_POSES, 0))
    out = []
    steps = n + int(drain_s / period_s)
    for k in range(steps):
        now = k * period_s
        if k < n:
            link.send(now, k)
        out.extend((now, m) for m in link.receive(now))
    return out


def test_perfect_link_delivers_everything_at_once_in_order() -> None:
    got = stream(LinkFaults(), n=100)
    assert [m for _, m in got] == list(range(100))
    assert all(abs(t - m * 0.02) < 1e-12 for t, m in got)
    assert not LinkFaults().active


def test_fixed_latency_delays_by_exactly_that_much_sim_time() -> None:
    got = stream(LinkFaults(latency_ms=100.0), n=200)
    assert [m for _, m in got] == list(range(200))
    # Released at the first receive at or after send + 0.1 s (receives every 0.02 s).
    for t, m in got:
        assert t == pytest.approx(m * 0.02 + 0.1, abs=1e-9)


def test_jitter_stays_within_its_bounds_and_reorders_when_wider_than_the_period() -> None:
    link = FaultyLink(LinkFaults(latency_ms=100.0, jitter_ms=30.0), link_rng(3, 0, 0))
    delays = [link._delay_s() for _ in range(5000)]
    assert min(delays) >= 0.07 - 1e-12 and max(delays) <= 0.13 + 1e-12
    assert np.mean(delays) == pytest.approx(0.1, abs=0.002)
    got = [m for _, m in stream(LinkFaults(latency_ms=100.0, jitter_ms=30.0))]
    assert sorted(got) == list(range(2000))
    assert got != sorted(got)  # 60 ms of spread over 20 ms spacing: some overtake


def test_drop_rate_is_close_to_its_probability() -> None:
    got = stream(LinkFaults(drop=0.3), n=10000)
    assert len(got) == pytest.approx(7000, rel=0.05)
    assert len({m for _, m in got}) == len(got)  # no copies


def test_duplicates_are_extra_copies_of_real_messages() -> None:
    got = [m for _, m in stream(LinkFaults(latency_ms=20, jitter_ms=10, dup=0.2), n=5000)]
    assert set(got) == set(range(5000))
    assert len(got) - 5000 == pytest.approx(1000, rel=0.1)


def test_reordered_messages_are_overtaken() -> None:
    faults = LinkFaults(reorder=0.1, reorder_delay_ms=50.0)
    got = [m for _, m in stream(faults, n=5000)]
    assert sorted(got) == list(range(5000))
    overtaken = sum(1 for a, b in zip(got, got[1:]) if b < a)
    assert overtaken == pytest.approx(500, rel=0.15)


def test_links_are_deterministic_per_seed_and_independent_per_link() -> None:
    faults = LinkFaults(latency_ms=50.0, jitter_ms=40.0, drop=0.2, dup=0.1, reorder=0.1)
    assert stream(faults, seed=7) == stream(faults, seed=7)
    assert stream(faults, seed=7) != stream(faults, seed=8)
    a = FaultyLink(faults, link_rng(7, LINK_POSES, 1))
    b = FaultyLink(faults, link_rng(7, LINK_COMMANDS, 1))
    assert a.rng.random() != b.rng.random()


def test_counts_add_up() -> None:
    link = FaultyLink(LinkFaults(latency_ms=30, drop=0.2, dup=0.3), link_rng(1, 0, 0))
    for k in range(1000):
        link.send(k * 0.01, k)
    assert link.counts.offered == 1000
    in_flight = link.in_flight
    assert in_flight == 1000 - link.counts.dropped + link.counts.duplicated
    assert len(link.receive(100.0)) == in_flight and link.in_flight == 0
    link.send(200.0, "x")
    link.clear()
    assert link.receive(1e9) == []


@pytest.mark.parametrize("bad", [
    {"latency_ms": -1.0}, {"jitter_ms": float("nan")}, {"drop": 1.5}, {"dup": -0.1},
    {"reorder": 2.0}, {"latency_ms": float("inf")}, {"drop": True}, {"latency_ms": "10"},
])
def test_rejects_bad_fault_values(bad: dict) -> None:
    with pytest.raises(ValueError):
        LinkFaults(**bad)


@settings(max_examples=examples(60), deadline=None)
@given(latency=st.floats(0, 300), jitter=st.floats(0, 100), drop=st.floats(0, 1),
       dup=st.floats(0, 1), reorder=st.floats(0, 1), seed=st.integers(0, 2**32 - 1))
def test_never_invents_messages_or_releases_early(latency, jitter, drop, dup, reorder,
                                                  seed) -> None:
    faults = LinkFaults(latency_ms=latency, jitter_ms=jitter, drop=drop, dup=dup,
                        reorder=reorder)
    got = stream(faults, n=200, seed=seed)
    for t, m in got:
        assert 0 <= m < 200 and t + 1e-9 >= m * 0.02
    counts = {m: [x for _, x in got].count(m) for m in set(x for _, x in got)}
    assert max(counts.values(), default=1) <= 2
