"""The topology core: pure functions, no I/O, no clocks.

Works on node ids, neighbour bearings (rad, body frame) and touch flags; never measured
positions (``shape`` estimates the swarm's shape from those bearings). One module per
concept: ``complex`` (the Rips complex from who-sees-whom), ``fence`` (frontier and
obstacle edges; its stages in ``fence_types``, ``fence_local``, ``fence_sides``,
``fence_probes``, ``fence_deploy``), ``evidence`` (what closes a fence side),
``certificate`` (relative homology H2(R, F) over GF(2)), ``solver`` (how certificate
solves it: Morse matching and peeling), ``gf2`` (elimination), ``redundancy``, ``shape``,
``paths`` (push paths on the fixed graph), ``targets`` (desired bearings), ``gvg``,
``params``.

Each module's ``__all__`` is the one list of what it exports; this package re-exports them
(``coordinator`` re-exports them again, with ``wrap`` and ``circular_mean``).
"""
from . import certificate, complex, fence, gvg, params, paths, redundancy, shape, targets
from .certificate import *  # noqa: F403
from .complex import *  # noqa: F403
from .fence import *  # noqa: F403
from .gvg import *  # noqa: F403
from .params import *  # noqa: F403
from .paths import *  # noqa: F403
from .redundancy import *  # noqa: F403
from .shape import *  # noqa: F403
from .targets import *  # noqa: F403

__all__ = [name for module in (params, complex, fence, certificate, redundancy, paths, targets,
                               gvg, shape)
           for name in module.__all__]
