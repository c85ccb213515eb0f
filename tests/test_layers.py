"""The house's floors import downwards only (issue 17): the pure cores and the drawing
library never import the process layer. Read from the source (ast), so a new import that
breaks a floor fails here, not in a user's import cycle."""
from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

# package -> packages it must never import (at any depth, lazily inside functions too)
NEVER = {
    "ground": {"agents", "bus", "coordinator", "hwbridge", "recording", "swarmcover", "viz",
               "world"},
    "viz": {"swarmcover", "coordinator", "agents", "hwbridge", "recording"},
    # recordings: the bus, the ground floor and the drawing library, never the commands
    "recording": {"swarmcover", "coordinator", "agents", "hwbridge", "world"},
    # the topology core: numpy, scipy and the ground floor only; no bus, no process
    "coordinator/topology": {"agents", "bus", "coordinator", "hwbridge", "swarmcover", "viz",
                             "world", "zenoh", "msgpack"},
}


# the card's folders, installed as swarmcover.<name> (pyproject.toml's package-dir)
FLOORS = ("agents", "bus", "coordinator", "ground", "hwbridge", "recording", "viz", "world")


def _package(module: str) -> str:
    """The house's package of an absolute module name: swarmcover.world.core -> world,
    swarmcover.run -> swarmcover, numpy.linalg -> numpy."""
    parts = module.split(".")
    if parts[0] == "swarmcover" and len(parts) > 1 and parts[1] in FLOORS:
        return parts[1]
    return parts[0]


def _absolute_imports(path: Path) -> list[str]:
    out = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            out += [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            out.append(node.module)
    return out


def _imported_packages(path: Path) -> set[str]:
    out = {_package(m) for m in _absolute_imports(path)}
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.ImportFrom) and node.level >= 2:
            out.add("..")  # out of its own package: upwards, as far as this check knows
    return out


def _sources() -> list[Path]:
    return sorted(p for d in (*FLOORS, "swarmcover", "bench", "tests", "examples")
                  for p in (ROOT / d).rglob("*.py"))


def test_no_bare_import_of_a_floor():
    """Every import of the card's folders goes through the swarmcover namespace: a bare
    `import agents` or `from world import ...` would load another distribution's package
    of that name (or a second copy of ours)."""
    bad = [f"{p.relative_to(ROOT)}: {m}" for p in _sources() for m in _absolute_imports(p)
           if m.split(".")[0] in FLOORS]
    assert not bad, "; ".join(bad)


def test_lower_floors_never_import_upper_ones():
    bad = []
    for pkg, never in NEVER.items():
        never = never | {".."}
        files = sorted((ROOT / pkg).rglob("*.py"))
        assert files, pkg
        for path in files:
            hit = _imported_packages(path) & never
            if hit:
                bad.append(f"{path.relative_to(ROOT)} imports {sorted(hit)}")
    assert not bad, "; ".join(bad)


def test_the_check_sees_an_import_inside_a_function_and_one_upwards(tmp_path):
    f = tmp_path / "m.py"
    f.write_text("def g():\n    from swarmcover.run import main\n")
    assert "swarmcover" in _imported_packages(f)
    f.write_text("def g():\n    from swarmcover.recording.replay import read_messages\n")
    assert _imported_packages(f) == {"recording"}
    f.write_text("import swarmcover.agents.node as n\nfrom swarmcover.world import core\n")
    assert _imported_packages(f) == {"agents", "world"}
    f.write_text("from ..deployer import Deployer\n")
    assert ".." in _imported_packages(f)
