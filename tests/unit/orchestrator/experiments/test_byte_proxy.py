"""The byte counter of the link proxy: buckets, windows, directions (pure, a fake clock).

The proxy itself, over loopback sockets, is tests/integration/test_byte_proxy.py.
"""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from orchestrator.experiments.byte_proxy import DIRECTIONS, ByteCounter


def test_a_window_sums_the_buckets_that_start_in_it() -> None:
    counter = ByteCounter(bucket_s=0.1)
    counter.add("downstream", 100, at_s=10.05)  # bucket [10.0, 10.1)
    counter.add("downstream", 20, at_s=10.15)   # bucket [10.1, 10.2)
    counter.add("downstream", 3, at_s=10.25)    # bucket [10.2, 10.3)
    counter.add("upstream", 7, at_s=10.15)
    assert counter.between("downstream", 10.1, 10.3) == 23
    assert counter.between("downstream", 10.0, 10.2) == 120
    assert counter.between("downstream", 10.01, 10.2) == 20  # [10.0, ...) starts before
    assert counter.between("upstream", 0.0, 100.0) == 7
    assert counter.total("downstream") == 123 and counter.total("upstream") == 7
    assert counter.between("downstream", 11.0, 12.0) == 0


def test_now_is_the_counters_clock() -> None:
    counter = ByteCounter(bucket_s=1.0, clock=lambda: 41.5)
    counter.add("upstream", 5)
    assert counter.between("upstream", 41.0, 42.0) == 5
    assert counter.between("upstream", 42.0, 43.0) == 0


def test_bad_arguments_are_refused() -> None:
    with pytest.raises(ValueError):
        ByteCounter(bucket_s=0.0)
    with pytest.raises(KeyError):
        ByteCounter().add("sideways", 1, at_s=0.0)


@given(st.lists(st.tuples(st.sampled_from(DIRECTIONS), st.integers(0, 10_000),
                          st.floats(0.0, 100.0)), max_size=50),
       st.floats(0.0, 100.0), st.floats(0.0, 100.0), st.floats(0.0, 100.0))
def test_windows_split_the_total(adds: list[tuple[str, int, float]], a: float, b: float,
                                 c: float) -> None:
    """Adjacent windows add up to the window over both, and a window over everything
    holds every byte."""
    t0, t1, t2 = sorted((a, b, c))
    counter = ByteCounter(bucket_s=0.1)
    for direction, n, at in adds:
        counter.add(direction, n, at_s=at)
    for d in DIRECTIONS:
        assert (counter.between(d, t0, t1) + counter.between(d, t1, t2)
                == counter.between(d, t0, t2))
        assert counter.between(d, -1.0, 101.0) == counter.total(d) == sum(
            n for direction, n, _ in adds if direction == d)
