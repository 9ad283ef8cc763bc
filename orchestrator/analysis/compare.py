"""Paired comparison of two sets of runs: is a variant better than chance says? (pure)

A crowd run is chaotic: one changed rounding moves every later decision, and the same
planner's reversals per robot move by a third from one seed to the next in the dense
families (docs/results.md). A variant judged on a few seeds can look better by luck; the
reciprocal share of docs/method.md did on six tuning seeds and not on ten others.
`compare` therefore pairs the runs of two directories by (case, planner, seed), takes the
difference of each metric run by run (variant minus base), and gives its mean with a 95 %
bootstrap interval over the pairs:

- per case: the pairs are resampled with replacement (`RESAMPLES` times, a fixed seed, so
  the interval is reproducible);
- overall: each case's pairs are resampled within the case and the cases' mean differences
  averaged with equal weight, so a case with more seeds does not count for more.

A difference whose interval excludes 0 is `lower` or `higher`; otherwise `within noise`.
With fewer than `MIN_PAIRS` pairs no interval is given (`too few`). Runs without a partner
(a seed the other side lacks, a seedless run, a key twice on one side) are counted and left
out; `report --compare` drops partial (interrupted) runs before pairing, so a partial run's
partner counts as unpaired and the partial run itself does not.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

COMPARE_METRICS = ("oscillations_per_robot", "time_ratio_mean", "path_ratio_mean",
                   "arrived_share", "contacts", "min_gap_m")
"""The metrics compared, from metrics.json (`arrived_share` = arrived / robots)."""

RESAMPLES = 2000
"""Bootstrap resamples per interval."""

MIN_PAIRS = 3
"""Fewer pairs than this give no interval."""

CONFIDENCE = 0.95


@dataclass(frozen=True)
class Difference:
    """One metric, variant against base, over paired runs.

    Args:
        base, variant: the means over the pairs.
        delta: the mean of the paired differences (variant - base).
        low, high: its bootstrap interval (NaN with fewer than `MIN_PAIRS` pairs).
        pairs: how many pairs had the metric on both sides.
    """

    base: float
    variant: float
    delta: float
    low: float
    high: float
    pairs: int

    @property
    def verdict(self) -> str:
        """`lower`, `higher`, `within noise` or `too few` (pairs)."""
        if not (math.isfinite(self.low) and math.isfinite(self.high)):
            return "too few"
        if self.high < 0.0:
            return "lower"
        if self.low > 0.0:
            return "higher"
        return "within noise"


@dataclass(frozen=True)
class Comparison:
    """Every case's differences and the overall ones.

    Args:
        cases: (case, planner) -> metric -> difference.
        overall: metric -> difference, the cases weighted equally.
        unmatched: runs on either side without a partner.
    """

    cases: dict[tuple[str, str], dict[str, Difference]]
    overall: dict[str, Difference]
    unmatched: int


def metric_value(metrics: Mapping[str, Any], name: str) -> float:
    """A metric of one run's metrics.json, NaN when absent or None."""
    if name == "arrived_share":
        robots, arrived = metrics.get("robots"), metrics.get("arrived")
        if not robots or arrived is None:
            return math.nan
        return float(arrived) / float(robots)
    value = metrics.get(name)
    return float(value) if isinstance(value, (int, float)) else math.nan


def pair_runs(base: Sequence[tuple[tuple[str, str, int | None], Mapping[str, Any]]],
              variant: Sequence[tuple[tuple[str, str, int | None], Mapping[str, Any]]],
              ) -> tuple[dict[tuple[str, str], list[tuple[Mapping[str, Any], Mapping[str, Any]]]],
                         int]:
    """Pairs of (base metrics, variant metrics) per (case, planner), by seed.

    Args:
        base, variant: ((case, planner, seed), metrics) of each run; runs without a seed,
            or a key seen twice on one side, cannot be paired.

    Returns:
        The pairs per (case, planner), in seed order, and the count of unpaired runs.
    """
    def index(runs: Sequence[tuple[tuple[str, str, int | None], Mapping[str, Any]]]
              ) -> tuple[dict[tuple[str, str, int], Mapping[str, Any]], int]:
        count = Counter(key for key, _ in runs)
        out = {(key[0], key[1], key[2]): metrics for key, metrics in runs
               if key[2] is not None and count[key] == 1}
        return out, len(runs) - len(out)

    a, loose_a = index(base)
    b, loose_b = index(variant)
    pairs: dict[tuple[str, str], list[tuple[Mapping[str, Any], Mapping[str, Any]]]] = {}
    for key in sorted(a.keys() & b.keys()):
        pairs.setdefault(key[:2], []).append((a[key], b[key]))
    unmatched = loose_a + loose_b + len(a.keys() ^ b.keys())
    return pairs, unmatched


def _interval(samples: np.ndarray) -> tuple[float, float]:
    tail = 100.0 * (1.0 - CONFIDENCE) / 2.0
    low, high = np.percentile(samples, (tail, 100.0 - tail))
    return float(low), float(high)


def _values(pairs: Sequence[tuple[Mapping[str, Any], Mapping[str, Any]]], name: str
            ) -> tuple[np.ndarray, np.ndarray]:
    base = np.array([metric_value(p[0], name) for p in pairs], dtype=float)
    variant = np.array([metric_value(p[1], name) for p in pairs], dtype=float)
    keep = np.isfinite(base) & np.isfinite(variant)
    return base[keep], variant[keep]


def difference(base: np.ndarray, variant: np.ndarray, rng: np.random.Generator) -> Difference:
    """The paired difference of two equal-length samples and its bootstrap interval."""
    n = base.size
    if n == 0:
        return Difference(math.nan, math.nan, math.nan, math.nan, math.nan, 0)
    delta = variant - base
    low = high = math.nan
    if n >= MIN_PAIRS:
        means = delta[rng.integers(0, n, size=(RESAMPLES, n))].mean(axis=1)
        low, high = _interval(means)
    return Difference(float(base.mean()), float(variant.mean()), float(delta.mean()),
                      low, high, n)


def compare(pairs: Mapping[tuple[str, str], Sequence[tuple[Mapping[str, Any], Mapping[str, Any]]]],
            unmatched: int = 0, metrics: Sequence[str] = COMPARE_METRICS, seed: int = 0
            ) -> Comparison:
    """Each case's and the overall paired differences (module docstring)."""
    rng = np.random.default_rng(seed)
    cases: dict[tuple[str, str], dict[str, Difference]] = {}
    overall: dict[str, Difference] = {}
    for name in metrics:
        per_case = []
        for key in sorted(pairs):
            base, variant = _values(pairs[key], name)
            cases.setdefault(key, {})[name] = difference(base, variant, rng)
            if base.size:
                per_case.append((base, variant))
        overall[name] = _overall(per_case, rng)
    return Comparison(cases=cases, overall=overall, unmatched=unmatched)


def _overall(per_case: Sequence[tuple[np.ndarray, np.ndarray]], rng: np.random.Generator
             ) -> Difference:
    """The cases' mean differences averaged with equal weight, resampled within each case."""
    if not per_case:
        return Difference(math.nan, math.nan, math.nan, math.nan, math.nan, 0)
    pairs = sum(b.size for b, _ in per_case)
    base = float(np.mean([b.mean() for b, _ in per_case]))
    variant = float(np.mean([v.mean() for _, v in per_case]))
    low = high = math.nan
    if pairs >= MIN_PAIRS:
        means = np.zeros(RESAMPLES)
        for b, v in per_case:
            d = v - b
            means += d[rng.integers(0, d.size, size=(RESAMPLES, d.size))].mean(axis=1)
        low, high = _interval(means / len(per_case))
    return Difference(base, variant, variant - base, low, high, pairs)


def format_difference(d: Difference, digits: int = 2) -> str:
    """'base -> variant (delta [low, high])', the interval left out when there is none."""
    if d.pairs == 0:
        return "-"
    text = f"{d.base:.{digits}f} -> {d.variant:.{digits}f} ({d.delta:+.{digits}f}"
    if math.isfinite(d.low):
        text += f" [{d.low:+.{digits}f}, {d.high:+.{digits}f}]"
    return text + ")"
