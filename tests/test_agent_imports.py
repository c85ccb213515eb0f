"""An agent process stays light (issue 18): importing ``agents.node`` and reading a run
config the way ``swarmcover run`` starts an agent (``--run-config``) loads none of the heavy
libraries (numpy, scipy, pymunk, matplotlib, PIL). Checked in a fresh interpreter, since the
test process itself has them all loaded. The live-process side (no heavy shared library
mapped in a running agent) is in test_agent_process.py.
"""
from __future__ import annotations

import json
import subprocess
import sys

import pytest

from procs import ROOT

pytestmark = pytest.mark.timeout(60)

HEAVY = ("numpy", "scipy", "pymunk", "matplotlib", "PIL")

# what an agent's main imports, plus what its --run-config path uses at start-up
# (agents.node.resolve_params -> from_toml_text, world_mode -> world.config)
AGENT_START = """
import swarmcover.agents.node
from swarmcover.agents.params import from_toml_text
from swarmcover.world.config import WorldConfig
from_toml_text(open("configs/open_room.toml").read(), "configs/open_room.toml")
WorldConfig().mode
"""

PROBE = """
import json, sys
{code}
print(json.dumps(sorted(m for m in sys.modules if m.split(".")[0] in {heavy!r})))
"""


def heavy_after(code: str) -> list[str]:
    """The heavy modules in sys.modules of a fresh interpreter after running ``code``."""
    r = subprocess.run([sys.executable, "-c", PROBE.format(code=code, heavy=HEAVY)],
                       capture_output=True, text=True, cwd=str(ROOT), timeout=30)
    assert r.returncode == 0, r.stderr
    return json.loads(r.stdout.strip().splitlines()[-1])


def test_agent_imports_no_heavy_library():
    assert heavy_after(AGENT_START) == []


def test_the_probe_sees_a_heavy_import():
    """The check above can fail: the same probe reports numpy once something imports it
    (here the polygon check of a world config, which imports it on first use)."""
    got = heavy_after(AGENT_START + "from swarmcover.bus.configcheck import self_crossing\n"
                      "assert self_crossing([[0, 0], [1, 0], [1, 1], [0, 1]]) is None\n")
    assert "numpy" in got
