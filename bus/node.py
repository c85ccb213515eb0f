"""The one process skeleton: every swarmcover process's ``main`` is its wiring alone.

``run_node`` owns what each process used to repeat: the argument parser with the shared
Zenoh flags (layered as in zenoh-python's examples) and ``--log-level``, logging, opening
the session (exit 2 with the router named when it cannot be opened), the Shutdown context
(SIGINT/SIGTERM -> an event, bounded exit), closing the session on every path, and the
exit codes:

  * 0: the node ran and stopped normally (its ``serve`` returned 0 or None);
  * 1: only what ``serve`` returns itself ("ran, not certified" for run-like commands);
  * 2: a usage or configuration error (``UsageError``, ``ValueError``, ``SystemExit`` with a
    message, or a session that cannot be opened), logged as one line, never a traceback.

A process writes ``READY <what>`` on stdout through :func:`ready` once it serves, which
supervisors and tests wait for.

    def main(argv=None) -> int:
        return run_node("swarmcover demo", __doc__, _args, _serve, argv=argv)

A process that builds something from its flags before connecting (a checked config, a
map) hands it to its loop through ``prepare``, not through attributes set on ``args``:

    def _load(args) -> Loaded: ...            # ValueError -> exit 2, no session opened
    def _serve(args, session, keys, stop, loaded: Loaded) -> int: ...
    run_node("swarmcover world", __doc__, build_parser(), _serve, prepare=_load)
"""
from __future__ import annotations

import argparse
import logging
import os
from typing import Any, Callable

from .session import Shutdown, add_zenoh_args, keys_from_args, open_session, setup_logging

__all__ = ["UsageError", "run_node", "ready"]


class UsageError(ValueError):
    """A bad flag, config field or input: the process ends with exit code 2 and this
    message (which names the flag or field and its value)."""


# serve(args, session: zenoh.Session, keys: Keys, stop: Shutdown[, prepared]) -> exit code
Serve = Callable[..., "int | None"]


def run_node(prog: str, description: str | None,
             add_args: Callable[[argparse.ArgumentParser], None] | argparse.ArgumentParser,
             serve: Serve, *, argv: list[str] | None = None,
             logger: "str | Callable[[argparse.Namespace], str] | None" = None,
             mode: str = "client", session_mode: str | None = None,
             before_session: Callable[[argparse.Namespace], "int | None"] | None = None,
             prepare: Callable[[argparse.Namespace], Any] | None = None,
             formatter_class=argparse.HelpFormatter, grace_s: float | None = None) -> int:
    """Parse flags, set up logging, open the session, run ``serve`` inside Shutdown.

    add_args(parser): the process's own flags (the Zenoh flags and --log-level are added);
      or a ready parser (its ``build_parser()``), completed with whichever of those it lacks.
    serve(args, session, keys, stop): the process's loop; its return value is the exit code
      (None means 0). It must return soon after ``stop.is_set()``. With ``prepare`` it is
      called as serve(args, session, keys, stop, prepared).
    logger: the logger's name, or a function of the parsed flags giving it.
    mode: the default Zenoh mode of the shared flags; session_mode: force a mode when
      opening (a router opens its session in router mode).
    before_session(args): checks that must fail before any connection (exit 2); when it
      returns an int, the process ends there with that code and opens no session (a
      command with nothing to do on the bus, e.g. an offline conversion).
    prepare(args): runs after before_session, still before any connection (a ValueError
      is exit 2); what it returns (a checked config, a map) is passed to serve as its fifth
      argument, so nothing travels as attributes set on ``args``.
    grace_s: the Shutdown watchdog's grace (None: its default; 0: no watchdog, for a
      process that bounds its own exit, like a recorder that must not be cut mid-flush).
    """
    if isinstance(add_args, argparse.ArgumentParser):
        p = add_args
    else:
        p = argparse.ArgumentParser(prog=prog, description=description,
                                    formatter_class=formatter_class)
        add_args(p)
    if not any("--connect" in a.option_strings for a in p._actions):
        add_zenoh_args(p, mode=mode)
    if not any(a.dest == "log_level" for a in p._actions):
        p.add_argument("--log-level", default="INFO", help="logging level (default INFO)")
    args = p.parse_args(argv)
    name = logger(args) if callable(logger) else (logger or prog.replace(" ", "."))
    log = setup_logging(args.log_level, name)
    # installed first: a signal while the session opens (a router slow to answer) is a
    # clean exit, not a KeyboardInterrupt traceback
    with Shutdown(grace_s=grace_s) as stop:
        try:
            if before_session is not None:
                code = before_session(args)
                if code is not None:
                    return int(code)
            extra = (prepare(args),) if prepare is not None else ()
            keys = keys_from_args(args)
            session = open_session(args, session_mode)
        except (ValueError, ConnectionError) as e:
            log.error("%s", e)
            return 2
        try:
            code = serve(args, session, keys, stop, *extra)
            return 0 if code is None else int(code)
        except (ValueError, SystemExit) as e:
            if isinstance(e, SystemExit) and (e.code is None or isinstance(e.code, int)):
                return 0 if e.code is None else int(e.code)
            log.error("%s", e)
            return 2
        finally:
            session.close()


READY_FD_ENV = "SWARMCOVER_READY_FD"


def ready(what: str) -> None:
    """Tell the supervisor (or a test) that this process serves: one ``READY`` line, and a
    byte on the pipe whose descriptor ``$SWARMCOVER_READY_FD`` names, if any (how
    ``swarmcover spawn`` paces the agents it starts, agents.supervisor)."""
    print(f"READY {what}", flush=True)
    fd = os.environ.pop(READY_FD_ENV, None)
    if fd is not None:
        try:
            os.write(int(fd), b"R")
            os.close(int(fd))
        except (OSError, ValueError):
            pass
