"""The figures ``swarmbed analyze`` draws for a scenario's sweeps, named by the scenario.

A scenario chooses *what* to plot (which summary metrics, in which kind of figure) and
``swarmbed.results.analyze`` owns *how* (style, colours, confidence intervals, files), so
a new scenario gets its paper's figures with no edit to the analysis: it lists them in
``Scenario.figures`` and labels its metrics in ``Scenario.metric_labels``. Every figure draws one
value per run from the sweep's table, except metrics the summary holds as one value per agent
(``distance_per_agent``), which are pooled over the runs' agents from each ``summary.json``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

FigureKind = Literal["by_range", "means", "boxes", "scatter", "against_count", "against_factor"]


@dataclass(frozen=True)
class Figure:
    """One figure (or one per metric, for ``by_range``). Kinds:

    - ``by_range``: per metric, boxes by communication range, one group per allocator, one panel
      per agent count (SPACE Fig. 3); one box per sweep scenario where a sweep varies neither.
    - ``means``: the metrics' means per allocator with 95 % CI bars side by side, the first filled,
      the rest hatched; one figure per sweep when several are analyzed together.
    - ``boxes``: one panel per metric, one box per allocator (counts of messages on a log scale).
    - ``scatter``: ``metrics[0]`` against ``metrics[1]``, one point per run, one colour per allocator.
    - ``against_count``: per metric, its mean per allocator against each key of ``over`` that the
      sweeps vary (victim count, robot count), on log axes.
    - ``against_factor``: ``metrics[0]`` per allocator against every other numeric factor a sweep
      varies (a tick length, a failure rate).
    """

    kind: FigureKind
    metrics: tuple[str, ...]
    #: ``against_count``: the dotted config keys to plot against (read from each run's config.yaml
    #: where a sweep leaves them at the base's value)
    over: tuple[str, ...] = ()
    #: the value axis's label where one axis shows several metrics (``means``)
    label: str = ""
