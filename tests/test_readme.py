"""The README's set-up commands are the ones CI runs, and they name real things."""
from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def _bash_blocks() -> list[str]:
    text = (ROOT / "README.md").read_text()
    setup = text.split("## Set up", 1)[1].split("\n## ", 1)[0]
    return re.findall(r"```bash\n(.*?)\n```", setup, re.S)


def test_exactly_two_setup_commands():
    blocks = _bash_blocks()
    assert len(blocks) == 2 and all(len(b.strip().splitlines()) == 1 for b in blocks), blocks


def test_ci_runs_the_readme_test_command():
    test_cmd = _bash_blocks()[1].strip()
    assert "pytest" in test_cmd
    assert test_cmd in (ROOT / ".ci/run").read_text()


def test_main_command_names_an_existing_config_and_command():
    main = _bash_blocks()[0]
    cfg = re.search(r"swarmcover run (\S+)", main).group(1)
    assert (ROOT / cfg).exists(), cfg
    from swarmcover.cli import COMMANDS
    assert "run" in COMMANDS
