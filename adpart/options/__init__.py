"""Options (I, pi, beta), their exact and sampled multi-time models, and the SMDP over them.

See docs/options.md for the semantics and the equations (dissertation section 3.1, 4.2.1).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from adpart.lazy import lazy_exports

if TYPE_CHECKING:
    from adpart.options.handmade import (
        doorway_options,
        hallway_options,
        room_options,
        rooms,
        wall_options,
    )
    from adpart.options.models import (
        OptionModel,
        SampledOptionModel,
        option_model,
        option_model_by_iteration,
        option_models,
        sample_option_model,
    )
    from adpart.options.option import Option, primitive_option, primitive_options
    from adpart.options.smdp import options_smdp, stack_models, sweeps_to_accuracy
    from adpart.options.subgoal_options import (
        basin,
        policy_to,
        reachable_set,
        subgoal_option,
        subgoal_options,
        transition_graph,
    )

lazy_exports(__name__, {
    "adpart.options.handmade": (
        "doorway_options", "hallway_options", "room_options", "rooms", "wall_options",
    ),
    "adpart.options.models": (
        "OptionModel", "SampledOptionModel", "option_model", "option_model_by_iteration",
        "option_models", "sample_option_model",
    ),
    "adpart.options.option": ("Option", "primitive_option", "primitive_options"),
    "adpart.options.smdp": ("options_smdp", "stack_models", "sweeps_to_accuracy"),
    "adpart.options.subgoal_options": (
        "basin", "policy_to", "reachable_set", "subgoal_option", "subgoal_options",
        "transition_graph",
    ),
})

__all__ = [
    "Option",
    "OptionModel",
    "SampledOptionModel",
    "basin",
    "doorway_options",
    "hallway_options",
    "option_model",
    "option_model_by_iteration",
    "option_models",
    "options_smdp",
    "policy_to",
    "primitive_option",
    "primitive_options",
    "reachable_set",
    "room_options",
    "rooms",
    "sample_option_model",
    "stack_models",
    "subgoal_option",
    "subgoal_options",
    "sweeps_to_accuracy",
    "transition_graph",
    "wall_options",
]
