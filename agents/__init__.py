"""Robot agents: one OS process per robot, bearing-only homing and deployment behaviours.

Modules: ``control`` (pure control laws), ``params`` (parameters from the run config),
``behaviours`` (pure task state machine: the facade and task life cycle),
``perception`` (what a robot perceives from a Sense), ``modes`` and ``openloop`` (one class
per mode), ``node`` (the ``swarmcover agent`` process),
``supervisor`` (start and reap agent processes), ``spawn`` (``swarmcover spawn``).
"""
