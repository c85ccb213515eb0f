"""swarmcover: user-facing commands (CLI, router, topic inspection, one-command runs)."""
__version__ = "0.1.0"
