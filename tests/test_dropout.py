"""No single camera frame decides a run: with 5% of the sightings dropped at random
(``[sensing] dropout``), the in-process run of the tiny room still certifies, covers it
(ground truth) and uses about the robots it uses without dropout (12). When a robot's
Status listed only the neighbours its last frame saw, every dropped sighting took an edge
out of the coordinator's complex: the run never certified (42 robots after 1,472 s
simulated, against an Euler bound of 13). The run goes through ``bench/coverage.py``'s
``--dropout``, which sets the config's ``[sensing] dropout``."""
from __future__ import annotations

from pathlib import Path

import pytest

from bench import coverage

ROOT = Path(__file__).resolve().parents[1]


def test_five_percent_camera_dropout_still_certifies_the_tiny_room_covered():
    assert "dropout" not in (ROOT / "configs" / "tiny.toml").read_text()
    s = coverage.run_inproc(str(ROOT / "configs" / "tiny.toml"), 0, 120.0, dropout=0.05)
    assert s["dropout"] == 0.05
    assert s["certified"] and s["stop_reason"] == "certified"
    assert s["coverage"] >= 0.995 and not s["false_certificate"]
    assert s["robots_used"] <= 1.5 * s["euler_bound"]


def test_the_coverage_bench_sets_dropout_in_process_only_and_names_a_bad_value(capsys):
    for argv, says in ((["configs/tiny.toml", "--dropout", "0.05"], "--dropout needs --inproc"),
                       (["configs/tiny.toml", "--inproc", "--dropout", "1.5"],
                        "--dropout 1.5: expected 0 <= P < 1")):
        with pytest.raises(SystemExit):
            coverage.main(argv)
        assert says in capsys.readouterr().err
