"""How many bad inputs end at once with exit 2 and the field named (issue 22).

Runs every row of tests/test_bad_inputs.py as a real ``swarmcover run`` against a source
tree (default: this one) and prints, per row, the exit code (or "hang" when it still runs
after TIMEOUT s: then a run had started), the wall time and whether the output names the
field with no traceback. Rows that start a run are killed with their children.

    python bench/bad_inputs.py [TREE] [TIMEOUT_S] [ROW NAME ...]

To measure an older commit: ``git archive COMMIT | tar -x -C /tmp/old``, copy
tests/test_bad_inputs.py there, and pass /tmp/old as TREE with PYTHONPATH=/tmp/old.
"""
from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def main() -> int:
    tree = Path(sys.argv[1] if len(sys.argv) > 1 else Path(__file__).resolve().parent.parent)
    timeout = float(sys.argv[2]) if len(sys.argv) > 2 else 30.0
    only = set(sys.argv[3:])
    sys.path.insert(0, str(tree / "tests"))
    import test_bad_inputs as T
    from procs import pids_with
    n = ok = 0
    for name, make, flags, needles in T.ROWS:
        if only and name not in only:
            continue
        tmp = Path(tempfile.mkdtemp(prefix="bad-input-"))
        busy, subs, argv = T.prepare(tmp, make, flags)
        t0 = time.monotonic()
        p = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                             cwd=str(tree), start_new_session=True)
        try:
            out, _ = p.communicate(timeout=timeout)
            rc = p.returncode
        except subprocess.TimeoutExpired:
            os.killpg(p.pid, signal.SIGKILL)
            out, _ = p.communicate()
            rc = "hang"
        dt = time.monotonic() - t0
        for pid in pids_with(str(tmp)):
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        busy.close()
        shutil.rmtree(tmp, ignore_errors=True)
        first = needles[0].format(**subs)
        field = first.split(" = ")[0].split("] ")[-1] if " = " in first else first
        good = rc == 2 and "Traceback" not in out and field in out
        n += 1
        ok += good
        last = out.strip().splitlines()[-1][:140] if out.strip() else ""
        print(f"{name:26s} rc={rc!s:5s} {dt:5.1f} s {'ok ' if good else 'BAD'} | {last}",
              flush=True)
    print(f"{ok} of {n} bad inputs end with exit 2, the field named, no traceback")
    return 0


if __name__ == "__main__":
    sys.exit(main())
