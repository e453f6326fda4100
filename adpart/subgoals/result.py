"""The result every subgoal detector returns (dissertation section 4.1)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True, eq=False)
class SubgoalResult:
    """Subgoals found in one MDP under one policy, with the evidence for them.

    Attributes:
        subgoals: sorted unique int64 state ids.
        scores: ``(S,)`` float64, the per-state score the detector ranks by (for the count
            metric: the largest gradient ratio seen at the state, 0 where none was seen; for
            betweenness: the centrality).
        threshold: the threshold ``mu`` a score had to reach (eq. 4.2), or None when the detector
            picks subgoals another way (top-k).
        stats: JSON-able figures of the run (ratio mean/sd, samples, time, MC batch history...).
        params: the detector's parameters, JSON-able (stored with the result for provenance).
        detector: the detector's registered name.
    """

    subgoals: np.ndarray
    scores: np.ndarray
    threshold: float | None
    stats: Mapping[str, object] = field(default_factory=dict)
    params: Mapping[str, object] = field(default_factory=dict)
    detector: str = ""

    def __post_init__(self) -> None:
        sub = np.unique(np.asarray(self.subgoals, dtype=np.int64))
        scores = np.asarray(self.scores, dtype=np.float64)
        sub.setflags(write=False)
        scores.setflags(write=False)
        object.__setattr__(self, "subgoals", sub)
        object.__setattr__(self, "scores", scores)

    @property
    def mask(self) -> np.ndarray:
        """``(S,)`` bool, True at the subgoals (what ``Domain.render(marked=...)`` takes)."""
        out = np.zeros(self.scores.shape[0], dtype=bool)
        out[self.subgoals] = True
        return out

    def to_json(self) -> dict[str, object]:
        """A JSON-ready summary (the arrays as lists)."""
        return {
            "detector": self.detector,
            "subgoals": self.subgoals.tolist(),
            "threshold": self.threshold,
            "params": dict(self.params),
            "stats": dict(self.stats),
        }
