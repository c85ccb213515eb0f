"""Robot agents: one OS process per robot, bearing-only homing and deployment behaviours.

Modules: ``control`` (pure control laws), ``params`` (parameters from the run config),
``behaviours`` (pure task state machine), ``node`` (the ``swarmcover agent`` process),
``supervisor`` (start and reap agent processes), ``spawn`` (``swarmcover spawn``).
"""
