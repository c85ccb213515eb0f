"""bench/coverage.py's last table: issue 19's targets and the ones proposed in their place,
each marked per run."""
from __future__ import annotations

from bench import coverage


def test_the_bench_marks_the_proposed_targets_per_run():
    """The proposed targets (robots <= 1.15 x the bound at d0; time <= 1.5 x the push floor,
    judged only with 100 robots or more) are marked ok / MISS / n/a in the last table."""
    base = dict(name="m", seed=0, stop_reason="certified", certified=True, coverage=1.0,
                euler_bound=80, euler_bound_d0=100, sim_s_per_robot=9.0, cycles=10,
                push_floor_s=5.0, move_s=3.0, enter_s=2.0)
    small = dict(base, robots_used=90, s_per_robot_over_floor=1.8)
    big = dict(base, robots_used=120, s_per_robot_over_floor=1.4)
    p_small, p_big = coverage.proposed(small), coverage.proposed(big)
    assert [ok for _, ok in p_small.values()] == [True, None]     # 0.90 of the bound at d0
    assert [ok for _, ok in p_big.values()] == [False, True]      # 1.20 of it; 1.4 x floor
    assert not list(coverage.proposed(dict(big, certified=False)).values())[0][1]
    rows = coverage.table([small, big]).splitlines()
    assert "proposed: robots / bound at d0 <= 1.15" in rows[0]
    assert "90 / 100 = 0.90 ok" in rows[2] and "1.80 n/a" in rows[2]
    assert "120 / 100 = 1.20 MISS" in rows[3] and "1.40 ok" in rows[3]
