"""The tests' call of the option learners: their settings and run given as flat keywords.

``hierarchical_learning(mdp, options, partition, settings, run, models)`` takes a
:class:`~adpart.learning.hierarchical_settings.HierarchicalSettings` and a
:class:`~adpart.learning.settings.Run`; the tests name a few fields of each, so
:func:`hierarchical_run` sorts keywords into the two by the fields' names (``epsilon`` is the
exploration schedule, ``partition_epsilon`` eq. 4.7's threshold) and builds both, so every value
still goes through the one check of its declaration.
"""

from __future__ import annotations

from dataclasses import fields
from typing import Any

from adpart.learning.hierarchical import HierarchicalResult, hierarchical_learning
from adpart.learning.hierarchical_settings import HierarchicalSettings
from adpart.learning.settings import Run
from adpart.learning.smdp_q import SMDPQResult, SMDPQSettings, smdp_q_learning
from adpart.params import build_settings

RUN_FIELDS = frozenset(f.name for f in fields(Run))


def split(keywords: dict[str, Any]) -> tuple[HierarchicalSettings, Run]:
    """The settings and the run named by ``keywords``."""
    run = Run(**{k: v for k, v in keywords.items() if k in RUN_FIELDS})
    rest = {k: v for k, v in keywords.items() if k not in RUN_FIELDS}
    return build_settings(HierarchicalSettings, rest), run


def hierarchical_run(mdp: Any, options: Any, partition: Any = None, *, models: Any = None,
                     **keywords: Any) -> HierarchicalResult:
    """``hierarchical_learning`` with its settings and run built from ``keywords``."""
    settings, run = split(keywords)
    return hierarchical_learning(mdp, options, partition, settings, run, models)


def smdp_q_run(mdp: Any, options: Any = (), *, models: Any = None,
               **keywords: Any) -> SMDPQResult:
    """``smdp_q_learning`` with its settings and run built from ``keywords``."""
    run = Run(**{k: v for k, v in keywords.items() if k in RUN_FIELDS})
    rest = {k: v for k, v in keywords.items() if k not in RUN_FIELDS}
    return smdp_q_learning(mdp, options, build_settings(SMDPQSettings, rest), run, models)
