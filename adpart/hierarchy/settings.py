"""The hierarchy estimators' settings (section 4.4): one declaration of each default and check.

:class:`EstimateSettings` holds what both built-in estimators share - the constant ``c`` of
``T_conv = c |P|^2 |O|`` (eq. 4.10), the significance margin ``L`` of ``P_refine`` (eq. 4.12)
and delta of eq. 4.6 - and :class:`ExpectedTimeSettings` adds Algorithm 3's own. The plugins'
parameters, their options (``adpart hierarchy --threshold-scale 0.001``,
``--hierarchy-opt c=2``) and the stored provenance are derived from them.
"""

from __future__ import annotations

from dataclasses import field

from adpart.params import setting, settings

__all__ = ["EstimateSettings", "ExpectedTimeSettings"]


@settings
class EstimateSettings:
    """The expected learning time of a layer over the tasks learned so far (section 4.4)."""

    c: float = setting(1.0, min=0.0)
    """constant c of T_conv = c |P|^2 |O| (eq. 4.10)."""

    threshold: float | None = setting(None, kind="float", min=0.0, none="auto")
    """significance margin L of P_refine (eq. 4.12); auto: threshold-scale x each task's value
    range."""

    threshold_scale: float = setting(0.01, min=0.0)
    """the default L as a fraction of each task's value range over its non-terminal states."""

    delta: float | None = setting(0.3, min=0.0, max=1.0, none="none")
    """delta of eq. 4.6, in [0, 1]: expected-learning-time splits a block refined with an
    option by the option's delta-stable partition (none: by its initiation and termination
    alone); all-subgoals refines its multi-phase partition to it."""


@settings
class ExpectedTimeSettings:
    """Algorithm 3: greedy (block, option) refinements minimising E[t_learn | P] (4.4)."""

    max_refinements: int = setting(0, min=0)
    """cap on the accepted refinements (0: no cap)."""

    flat: bool = setting(True)
    """compare with the flat MDP ("no abstraction") and fall back to it when it is cheaper."""

    estimate: EstimateSettings = field(default_factory=EstimateSettings)
