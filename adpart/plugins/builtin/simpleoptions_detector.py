"""The ``simpleoptions`` subgoal detector: a peer's betweenness, eigenoption and diffusion-option
generators (the ``simpleoptions`` package) run on adpart's MDP, their subgoals brought back.

The package is optional (``pip install 'adpart[simpleoptions]'``) and imported only when the
detector runs; without it the detector ends in one error naming that command. The bridge, its
settings and the comparison with adpart's own ``betweenness`` and ``eigenoptions`` detectors are in
:mod:`adpart.subgoals.simpleoptions_bridge` and docs/subgoals.md.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from adpart.params import build_settings, settings_params
from adpart.plugins.hookspecs import hookimpl
from adpart.plugins.registry import Registrar
from adpart.subgoals.simpleoptions_bridge import SimpleOptionsSettings

if TYPE_CHECKING:
    import numpy as np

    from adpart.mdp.model import FiniteMDP
    from adpart.subgoals.result import SubgoalResult


class SimpleOptions:
    """simpleoptions' subgoals: betweenness local maxima (Şimşek & Barto 2008), eigenoption
    sinks (Machado, Bellemare & Bowling 2017) or diffusion-score local maxima (``--generator``).

    Policy-independent. Its parameters are
    :class:`~adpart.subgoals.simpleoptions_bridge.SimpleOptionsSettings`' fields.
    """

    name = "simpleoptions"
    description = ("simpleoptions' betweenness, eigenoption or diffusion-option subgoals "
                   "(optional package)")
    params = settings_params(SimpleOptionsSettings)

    def __init__(self, **values: object) -> None:
        self.settings = build_settings(SimpleOptionsSettings, values)

    def detect(self, mdp: FiniteMDP, policy: np.ndarray | None, rng: np.random.Generator) -> (
        SubgoalResult
    ):
        from adpart.subgoals.simpleoptions_bridge import detect_simpleoptions

        return detect_simpleoptions(mdp, self.settings, name=self.name)


@hookimpl
def register_subgoal_detectors(register: Registrar) -> None:
    register(SimpleOptions)
