"""swarmcover coordinator: the topology core (pure functions, no I/O).

Works on node ids, neighbour bearings (rad, body frame) and touch flags; never measured
positions (``shape`` estimates the swarm's shape from those bearings).

Each module's ``__all__`` is the one list of what it exports; this package re-exports them
(of ``angles`` only ``wrap`` and ``circular_mean``).
"""
from . import certificate, complex, fence, gvg, params, paths, redundancy, shape, targets
from ground.angles import circular_mean, wrap
from .certificate import *  # noqa: F403
from .complex import *  # noqa: F403
from .fence import *  # noqa: F403
from .gvg import *  # noqa: F403
from .params import *  # noqa: F403
from .paths import *  # noqa: F403
from .redundancy import *  # noqa: F403
from .shape import *  # noqa: F403
from .targets import *  # noqa: F403

__all__ = ["wrap", "circular_mean"] + [
    name for module in (params, complex, fence, certificate, redundancy, paths, targets, gvg,
                        shape)
    for name in module.__all__]
