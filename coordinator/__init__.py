"""swarmcover coordinator, in three layers, each importing only the ones below it:

* ``coordinator.topology``: the topology core (pure functions, no I/O);
* the deployment cycle: ``deployer`` (a pure state machine: statuses in, typed
  ``actions`` out) over ``roster`` (who is alive), ``placement`` (who holds which
  vertex), ``jobs`` and ``pushes`` (the cycle's push jobs) and ``tasks`` (the Task
  builders); ``planner`` (one cycle's plan from a snapshot), ``config``;
* ``node``: the Zenoh process around the deployer.

This package re-exports the topology core (and ``wrap`` and ``circular_mean``), so
``from swarmcover.coordinator import build_complex, certify`` keeps working.
"""
from swarmcover.ground.angles import circular_mean, wrap

from . import topology
from .topology import *  # noqa: F403
from .topology import certificate, complex, fence, gvg, params, paths, redundancy, shape, targets  # noqa: F401

__all__ = ["wrap", "circular_mean"] + topology.__all__
