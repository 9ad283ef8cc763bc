"""What a figure against N draws (`orchestrator.analysis.plots.figure_against_n`).

Apart from the plotting so that the benchmarks can name their panels at import without
importing matplotlib.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Panel:
    """One panel of a figure against N: the row columns drawn in it as lines.

    Attributes:
        title: the panel's title, with the unit the values are shown in.
        keys: row columns, one line each (the first solid, the others dashed).
        factor: each value is multiplied by this before drawing (1e-3: bytes as kB).
        labels: the lines' names in the legend (default: the keys).
    """

    title: str
    keys: tuple[str, ...]
    factor: float = 1.0
    labels: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        if not self.keys:
            raise ValueError(f"panel {self.title!r}: no columns to draw")
        if self.labels and len(self.labels) != len(self.keys):
            raise ValueError(f"panel {self.title!r}: {len(self.labels)} labels for "
                             f"{len(self.keys)} columns")
