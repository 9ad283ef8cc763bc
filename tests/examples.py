"""How many examples a Hypothesis property test draws, under the profile tests/conftest.py
loads: ``ci`` (`.ci/run`, ``pytest tests``) draws the full count, ``fast`` (plain ``pytest``)
half of it.

A test that names its count writes ``@settings(max_examples=examples(300))``; one that names
none gets the profile's default (`CI_EXAMPLES` or `FAST_EXAMPLES`). Counts of 50 and below
are written as plain numbers: they are the same under both profiles.
"""

from __future__ import annotations

from hypothesis import settings

CI_EXAMPLES = 100
"""Examples per property test under ``ci`` when the test names no count (Hypothesis's own
default)."""
FAST_EXAMPLES = 50
"""The same under ``fast``: every count is scaled by FAST_EXAMPLES / CI_EXAMPLES."""


def examples(full: int) -> int:
    """`full` under the ``ci`` profile, scaled like the loaded profile's default count
    otherwise (half under ``fast``), at least 1."""
    return max(1, round(full * settings.default.max_examples / CI_EXAMPLES))
