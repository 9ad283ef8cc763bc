"""The benchmark's seed sets and the `--seeds` argument (`orchestrator benchmark`).

Two disjoint named sets: `EVALUATION_SEEDS`, which the suite reports on by default, and
`TUNING_SEEDS`, which anyone tuning a planner against the suite should use, so that the
reported figures never come from the seeds a parameter was chosen on.
"""

from __future__ import annotations

TUNING_SEEDS: tuple[int, ...] = tuple(range(100, 106))
"""Seeds to tune planners on (`--seeds tuning`, 100-105); never reported by default."""
EVALUATION_SEEDS: tuple[int, ...] = tuple(range(10))
"""Seeds the suite reports on (the default, 0-9)."""
QUICK_SEEDS: tuple[int, ...] = (0,)
"""Seeds of `--quick` when `--seeds` is not given (the first evaluation seed)."""


def parse_seeds(text: str | None, *, quick: bool = False) -> tuple[int, ...]:
    """`evaluation`, `tuning`, N (the evaluation seeds 0..N-1) or an explicit list
    `S1,S2,...` (e.g. two of the tuning seeds, for a quick look while tuning); None: the
    default (`EVALUATION_SEEDS`, or `QUICK_SEEDS` with --quick).

    Raises:
        ValueError: anything else, N reaching into the tuning seeds, or a list that mixes
            tuning and evaluation seeds (tune on one set, report on the other).
    """
    if text is None:
        return QUICK_SEEDS if quick else EVALUATION_SEEDS
    key = text.strip().lower()
    if key == "evaluation":
        return EVALUATION_SEEDS
    if key == "tuning":
        return TUNING_SEEDS
    if "," in key:
        return _seed_list(text)
    try:
        n = int(key)
    except ValueError:
        raise ValueError(f"--seeds: expected 'evaluation', 'tuning', a count or a list "
                         f"S1,S2,..., got {text!r}") from None
    if not 1 <= n <= min(TUNING_SEEDS):
        raise ValueError(f"--seeds: a count must be 1..{min(TUNING_SEEDS)} (seeds 0..N-1, "
                         f"below the tuning seeds), got {n}")
    return tuple(range(n))


def _seed_list(text: str) -> tuple[int, ...]:
    try:
        seeds = tuple(int(part) for part in text.split(","))
    except ValueError:
        raise ValueError(f"--seeds: a list must be whole numbers S1,S2,..., got {text!r}") \
            from None
    if min(seeds) < 0 or len(set(seeds)) != len(seeds):
        raise ValueError(f"--seeds: a list must hold distinct seeds >= 0, got {text!r}")
    tuning = set(seeds) & set(TUNING_SEEDS)
    if tuning and tuning != set(seeds):
        raise ValueError(f"--seeds: {text!r} mixes tuning seeds ({min(TUNING_SEEDS)}-"
                         f"{max(TUNING_SEEDS)}) with others: tune on one set, report on "
                         f"the other")
    return seeds
