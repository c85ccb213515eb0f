"""One meaning for ``--config`` across commands: the Zenoh JSON5 config file (the shared
connection flag). A run config is a positional CONFIG or ``--run-config``; a help text that
calls it ``--config`` sends a user to the wrong flag."""
from __future__ import annotations

import functools
import re
import subprocess
import sys
from pathlib import Path

import pytest

from swarmcover.cli import COMMANDS

ROOT = Path(__file__).resolve().parent.parent


def _help(name: str) -> str:
    out = subprocess.run([sys.executable, "-m", "swarmcover", name, "--help"],
                         capture_output=True, text=True, timeout=60, cwd=ROOT)
    assert out.returncode == 0, out.stderr[-2000:]
    return out.stdout


@pytest.mark.parametrize("name", sorted(COMMANDS))
def test_config_flag_means_the_zenoh_config_in_every_help(name):
    text = _help(name)
    usage = text.split("\n\n", 1)[0]
    wrong = [line.strip() for line in text.splitlines()
             if re.search(r"--config\b", line) and line not in usage
             and not re.search(r"zenoh|router", line, re.I)]
    assert not wrong, f"swarmcover {name} --help: {wrong}"
    if re.search(r"\[--config FILE\]", usage):
        assert re.search(r"--config FILE\s+Zenoh JSON5 config file", text)


# ---- every shared flag everywhere, and no help text naming a flag that does not exist

SESSION_COMMANDS = ["run", "router", "host", "world", "coordinator", "agent", "hwbridge", "fake-robot",
                    "record", "replay", "view", "demo", "topics list", "topics echo",
                    "topics hz", "topics alive"]
SUBCOMMANDS = {"topics": ["list", "echo", "hz", "alive"], "config": ["defaults", "docs", "check"],
               "secure": ["init", "export", "show", "router-config"]}


@functools.lru_cache(maxsize=None)
def _help_of(words: str) -> str:
    out = subprocess.run([sys.executable, "-m", "swarmcover", *words.split(), "--help"],
                         capture_output=True, text=True, timeout=60, cwd=ROOT)
    assert out.returncode == 0, out.stderr[-2000:]
    return out.stdout


def _defined(text: str) -> set[str]:
    """The long flags a help text's option lists define (lines '  --flag ...')."""
    flags: set[str] = set()
    for line in text.splitlines():
        m = re.match(r"^  (-\S.*?)(?:\s{2,}|$)", line)
        if m:
            flags |= set(re.findall(r"--[a-z][\w-]*", m.group(1)))
    return flags


def _own(name: str) -> set[str]:
    flags = _defined(_help_of(name))
    for sub in SUBCOMMANDS.get(name, []):
        flags |= _defined(_help_of(f"{name} {sub}"))
    return flags


@pytest.mark.parametrize("words", SESSION_COMMANDS)
def test_every_session_command_takes_every_shared_zenoh_flag(words):
    from swarmcover.bus.session import ZENOH_FLAGS
    text = _help_of(words)
    zenoh_group = text.split("\nzenoh:\n", 1)
    assert len(zenoh_group) == 2, f"swarmcover {words} --help has no 'zenoh:' group"
    missing = set(ZENOH_FLAGS) - _defined(zenoh_group[1])
    assert not missing, f"swarmcover {words} lacks the shared flags {sorted(missing)}"


def test_run_says_what_each_shared_flag_does_for_it():
    """`run` takes them with its own meaning: its session and every child it starts."""
    zenoh_group = _help_of("run").split("\nzenoh:\n", 1)[1]
    flat = " ".join(zenoh_group.split())
    for needle in ("--connect ENDPOINT, -e ENDPOINT use the router at ENDPOINT",
                   "--listen ENDPOINT, -l ENDPOINT endpoint the embedded router listens on",
                   "default: the config's name",
                   "--config FILE Zenoh JSON5 config file (applied first) for run's own session",
                   "every process it starts"):
        assert needle in flat, needle
    usage = _help_of("run").split("\n\n", 1)[0]
    assert usage.rstrip().endswith("CONFIG")   # the run config stays the positional


@pytest.mark.parametrize("name", sorted(COMMANDS))
def test_help_names_only_flags_that_exist(name):
    """A flag a help text mentions is one of the command's own (or its subcommands'), or one
    of a command the text names (`swarmcover router --config FILE`, spawn's agent flags)."""
    text = _help_of(name)
    body = text.split("\n\n", 1)[-1]
    mentioned = set(re.findall(r"(?<![\w-])--[a-z][\w-]*", body)) - {"--help"}
    allowed = _own(name)
    for other in COMMANDS:
        if other != name and re.search(rf"(?<![\w-]){re.escape(other)}(?![\w-])", body):
            allowed |= _own(other)
    assert not mentioned - allowed, (f"swarmcover {name} --help names flags it does not have: "
                                     f"{sorted(mentioned - allowed)}")


def test_the_option_reader_sees_fake_robots_flags():
    assert "--no-such-flag" not in _own("fake-robot")
    assert {"--run-config", "--id", "--cmd-timeout", "--connect"} <= _own("fake-robot")


def _readme_cli_lines() -> list[tuple[str, str]]:
    """(command, its arguments) of every `swarmcover CMD ...` in README.md and docs/*.md:
    inline code and lines of code blocks."""
    text = "\n".join(f.read_text() for f in [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))])
    blocks = re.findall(r"```\w*\n(.*?)```", text, re.S)
    prose = re.sub(r"```\w*\n.*?```", "", text, flags=re.S)
    spans = [" ".join(sp.split()) for sp in re.findall(r"`([^`]+)`", prose)]
    spans += [ln for b in blocks for ln in b.splitlines() if ln.startswith("swarmcover ")]
    return [(m.group(1), m.group(2).split("#")[0]) for sp in spans
            for m in re.finditer(r"swarmcover ([a-z][a-z-]*)((?:\s+[^\s`]+)*)", sp)]


def test_readme_cli_lines_name_real_commands_and_flags():
    lines = _readme_cli_lines()
    assert len(lines) >= 20 and any(c == "run" and "--record" in a for c, a in lines)
    wrong = []
    for cmd, rest in lines:
        if cmd not in COMMANDS:
            wrong.append(f"swarmcover {cmd}: no such command")
            continue
        missing = set(re.findall(r"(?<![\w-])--[a-z][\w-]*", rest)) - _own(cmd)
        if missing:
            wrong.append(f"swarmcover {cmd}{rest}: {sorted(missing)}")
    assert not wrong, wrong
