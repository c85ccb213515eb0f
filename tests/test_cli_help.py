"""One meaning for ``--config`` across commands: the Zenoh JSON5 config file (the shared
connection flag). A run config is a positional CONFIG or ``--run-config``; a help text that
calls it ``--config`` sends a user to the wrong flag."""
from __future__ import annotations

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
