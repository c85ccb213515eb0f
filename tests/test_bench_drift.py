"""bench/drift.py's summary of replacement displacements (the pure part; the run itself is
the in-process loop the coverage tests exercise)."""
from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.drift import along_table, displacement_table  # noqa: E402


def test_displacements_are_summed_by_landmark_count_with_four_and_more_pooled():
    rows = [(1, 0.2), (2, 0.02), (2, 0.04), (3, 0.01), (4, 0.005), (7, 0.005)]
    t = displacement_table(rows)
    assert t["n"] == 6 and t["mean"] == pytest.approx(0.28 / 6)
    by = t["by_landmarks"]
    assert set(by) == {"1", "2", "3", "4+"}
    assert by["2"]["n"] == 2 and by["2"]["mean"] == pytest.approx(0.03)
    assert by["4+"]["n"] == 2 and by["4+"]["mean"] == pytest.approx(0.005)
    assert by["1"]["share"] == pytest.approx(0.2 / 0.28)
    assert sum(v["share"] for v in by.values()) == pytest.approx(1.0)
    assert t["p50"] <= t["p90"] <= t["p99"] <= 0.2


def test_no_replacement_gives_an_empty_summary():
    assert displacement_table([]) == {"n": 0}


def test_the_signed_miss_keeps_its_sign_so_a_bias_to_one_side_shows():
    rows = [(2, -0.004), (2, -0.006), (3, 0.001), (5, -0.002), (4, 0.0)]
    t = along_table(rows)
    assert t["n"] == 5 and t["mean"] == pytest.approx(-0.011 / 5) and t["p50"] == -0.002
    assert t["by_landmarks"]["2"] == {"n": 2, "mean": pytest.approx(-0.005)}
    assert t["by_landmarks"]["4+"]["mean"] == pytest.approx(-0.001)
    assert along_table([]) == {"n": 0}
