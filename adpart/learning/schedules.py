"""Step-size and exploration schedules for the learners (dissertation section 2.x, eq. 2.4).

Q-learning converges to ``Q*`` with probability one when every admissible pair is updated
infinitely often and the step sizes ``alpha_n(s, a)`` satisfy the stochastic-approximation
conditions ``sum_n alpha_n = inf`` and ``sum_n alpha_n**2 < inf`` (Watkins & Dayan 1992; the
dissertation's discussion of eq. 2.4). The visit-count schedule ``1 / n**omega`` meets them for
``omega`` in ``(0.5, 1]``; a constant step size does not, but tracks faster in practice.

Every schedule here is one formula with four numbers,

    value(n, e) = max(floor, scale * rate**e * n**(-omega)),

where ``e`` is the episode index of the run (0 for its first episode) and ``n >= 1`` is a visit
count that *includes* the current visit:

* for a step size ``alpha``: ``n = n(s, a)``, the number of updates of the pair so far,
  counting this one (so ``1/n`` gives ``alpha = 1`` on the first update and the sample mean
  of the targets afterwards);
* for an exploration rate ``epsilon``: ``n = n(s)``, the number of decisions taken in ``s``
  so far, counting this one.

The three documented kinds are special cases: :func:`constant` (``rate = 1, omega = 0``),
:func:`visit_count` (``rate = 1``) and :func:`exponential` (per-episode decay, ``omega = 0``).
A single parametric form lets the compiled kernels evaluate any schedule from four floats and
lets the knowledge base store a schedule as a small JSON object (:meth:`Schedule.to_dict`).
"""

from __future__ import annotations

import math
import numbers
import re
from dataclasses import asdict, dataclass
from typing import TYPE_CHECKING

from adpart.errors import TaskError

if TYPE_CHECKING:
    import numpy as np

__all__ = ["Schedule", "constant", "exponential", "parse_schedule", "visit_count"]


@dataclass(frozen=True)
class Schedule:
    """``value(n, e) = max(floor, scale * rate**e * n**(-omega))`` (see the module docstring).

    Attributes:
        scale: the value at the first visit of the first episode (before ``floor``).
        rate: per-episode multiplicative decay in ``(0, 1]``.
        omega: visit-count exponent in ``[0, 1]`` (``(0.5, 1]`` for guaranteed convergence).
        floor: lower bound of the value, ``>= 0``.
        kind: ``"constant"``, ``"visit-count"`` or ``"exponential"``; informational only.
    """

    scale: float
    rate: float = 1.0
    omega: float = 0.0
    floor: float = 0.0
    kind: str = "constant"

    def __post_init__(self) -> None:
        for what, value in (("scale", self.scale), ("rate", self.rate), ("omega", self.omega),
                            ("floor", self.floor)):
            if not isinstance(value, numbers.Real) or not math.isfinite(value):
                raise TaskError(f"schedule {what} = {value!r} must be a finite number")
        if self.scale < 0:
            raise TaskError(f"schedule scale = {self.scale!r} must be >= 0")
        if not 0.0 < self.rate <= 1.0:
            raise TaskError(f"schedule rate = {self.rate!r} must be in (0, 1] (a decay factor)")
        if not 0.0 <= self.omega <= 1.0:
            raise TaskError(
                f"schedule omega = {self.omega!r} must be in [0, 1]; (0.5, 1] satisfies the "
                "stochastic-approximation conditions"
            )
        if self.floor < 0:
            raise TaskError(f"schedule floor = {self.floor!r} must be >= 0")

    def value(self, visits: object, episode: object) -> np.ndarray:
        """The schedule at visit counts ``visits`` (``>= 1``) and episode indices ``episode``.

        Both arguments broadcast; the result is float64. This is the reference the kernels
        reproduce operation for operation (``rate**e`` first, then ``n**(-omega)``).
        """
        import numpy as np

        n = np.asarray(visits, dtype=np.float64)
        e = np.asarray(episode, dtype=np.float64)
        v = self.scale * np.power(self.rate, e)
        if self.omega != 0.0:
            v = v * np.power(n, -self.omega)
        else:
            v = v * np.ones_like(n)
        return np.maximum(self.floor, v)

    def params(self) -> tuple[float, float, float, float]:
        """``(scale, rate, omega, floor)`` as floats, the form the kernels take."""
        return (float(self.scale), float(self.rate), float(self.omega), float(self.floor))

    def to_dict(self) -> dict[str, object]:
        """A JSON-ready description for provenance records; ``Schedule(**d)`` inverts it."""
        return {k: (float(v) if isinstance(v, numbers.Real) else v)
                for k, v in asdict(self).items()}

    def check_probability(self, what: str) -> Schedule:
        """Raise unless every value lies in ``[0, 1]`` (step sizes and exploration rates)."""
        if max(self.scale, self.floor) > 1.0:
            raise TaskError(
                f"{what} schedule reaches {max(self.scale, self.floor)!r}; {what} must stay in "
                "[0, 1] (lower scale/floor)"
            )
        return self


def constant(value: float) -> Schedule:
    """The same value at every visit of every episode."""
    return Schedule(scale=value, kind="constant")


def visit_count(omega: float = 0.8, *, scale: float = 1.0, floor: float = 0.0) -> Schedule:
    """``max(floor, scale / n**omega)`` with ``n`` the visit count including the current one."""
    return Schedule(scale=scale, omega=omega, floor=floor, kind="visit-count")


def exponential(initial: float, rate: float, *, floor: float = 0.0) -> Schedule:
    """``max(floor, initial * rate**e)`` for episode index ``e = 0, 1, ...`` of the run."""
    return Schedule(scale=initial, rate=rate, floor=floor, kind="exponential")


_NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"


def parse_schedule(text: str | float | Schedule) -> Schedule:
    """A schedule from its command-line spelling.

    Accepted forms: a number (``"0.1"``, constant); ``"1/n"`` or ``"1/n^0.8"`` or
    ``"0.5/n^0.8"`` (visit count, optional ``",floor"``); ``"exp:0.5,0.99"`` or
    ``"exp:0.5,0.99,0.01"`` (exponential ``initial, rate[, floor]``). A :class:`Schedule` is
    returned unchanged.
    """
    if isinstance(text, Schedule):
        return text
    if isinstance(text, numbers.Real) and not isinstance(text, bool):
        return constant(float(text))
    if not isinstance(text, str):
        raise TaskError(f"cannot read a schedule from {text!r}; give e.g. '0.1', '1/n^0.8'")
    spec = text.strip().replace(" ", "")
    if re.fullmatch(_NUMBER, spec):
        return constant(float(spec))
    m = re.fullmatch(rf"({_NUMBER})?/n(?:\^({_NUMBER}))?(?:,({_NUMBER}))?", spec)
    if m:
        scale = float(m.group(1)) if m.group(1) else 1.0
        omega = float(m.group(2)) if m.group(2) else 1.0
        floor = float(m.group(3)) if m.group(3) else 0.0
        return visit_count(omega, scale=scale, floor=floor)
    m = re.fullmatch(rf"exp:({_NUMBER}),({_NUMBER})(?:,({_NUMBER}))?", spec)
    if m:
        floor = float(m.group(3)) if m.group(3) else 0.0
        return exponential(float(m.group(1)), float(m.group(2)), floor=floor)
    raise TaskError(
        f"cannot read a schedule from {text!r}; use a number ('0.1'), a visit-count rule "
        "('1/n^0.8', '0.5/n^0.6,0.01') or an exponential decay ('exp:0.5,0.99[,floor]')"
    )
