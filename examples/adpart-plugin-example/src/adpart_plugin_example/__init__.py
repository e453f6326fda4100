"""An example adpart plugin package: an environment, a subgoal detector, a learner, a criterion.

Each module registers its class through its own ``adpart`` entry point (see ``pyproject.toml``):

* :class:`~adpart_plugin_example.environment.ThreeRoomsLine` - ``three-rooms-line``, three rooms
  in a row joined by single-cell doors (4 moves, deterministic, 77 states);
* :class:`~adpart_plugin_example.detector.Doorways` - ``doorways``, the cut vertices of the
  transition graph that cut off enough states (the narrowest of each chain);
* :class:`~adpart_plugin_example.learner.SarsaLearner` - ``sarsa``, on-policy TD(0) control;
* :class:`~adpart_plugin_example.criterion.CappedBlocks` - ``capped-blocks``, a partition
  criterion: delta-stability, then no block larger than ``size`` states.

The package imports adpart; adpart never imports it.
"""

from adpart_plugin_example.criterion import CappedBlocks
from adpart_plugin_example.detector import Doorways
from adpart_plugin_example.environment import ThreeRoomsLine
from adpart_plugin_example.learner import SarsaLearner, sarsa

__all__ = ["CappedBlocks", "Doorways", "SarsaLearner", "ThreeRoomsLine", "sarsa"]
__version__ = "0.1.0"
