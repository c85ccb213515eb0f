"""No machine-specific path in code, messages or docs (project rule): a home folder, a
scratch tree or one machine's virtual environment named in a shipped file would be wrong
on every other machine."""
from __future__ import annotations

import re
import subprocess
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PATTERN = re.compile(r"(?<![\w.~-])/(?:work|root|home|Users|tmp/[\w.-]+/)[\w./+-]*")
SUFFIXES = {".py", ".md", ".toml", ".html", ".json5", ".yaml", ".yml", ".txt", ".cfg"}


def _tracked() -> list[Path]:
    out = subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True,
                         timeout=30)
    files = out.stdout.split() if out.returncode == 0 else [
        str(p.relative_to(ROOT)) for p in ROOT.rglob("*") if p.is_file()]
    return [ROOT / f for f in files if Path(f).suffix in SUFFIXES
            and not f.startswith(("tests/data/", ".git/"))]


def test_no_machine_specific_paths():
    hits = []
    for path in _tracked():
        if path.name == "test_no_machine_paths.py" or not path.is_file():
            continue
        for n, line in enumerate(path.read_text(encoding="utf-8", errors="replace")
                                 .splitlines(), 1):
            m = PATTERN.search(line)
            if m:
                hits.append(f"{path.relative_to(ROOT)}:{n}: {m.group(0)}")
    assert not hits, "\n".join(hits)
