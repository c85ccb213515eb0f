"""run's reserve of agents started ahead of their robots (swarmcover/reserve.py)."""
from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st

from swarmcover.reserve import AgentReserve


def test_the_reserve_holds_the_next_ids_and_stops_those_passed_over():
    r = AgentReserve(3)
    assert r.plan() == ([0, 1, 2], [])
    assert r.take(0) and r.plan() == ([3], [])
    assert not r.take(7)                       # not reserved: run starts it itself
    assert r.plan() == ([8, 9, 10], [1, 2, 3])  # 1-3 passed over (a restart, a hand-join)
    assert r.passed == {1, 2, 3}
    r.saw([100])                               # an agent joined by hand as robot 100
    assert r.plan() == ([101, 102, 103], [8, 9, 10])
    assert AgentReserve(0).plan() == ([], [])


@settings(max_examples=200, deadline=None)
@given(size=st.integers(0, 6), ops=st.lists(st.tuples(st.sampled_from("sj"),
                                                       st.integers(0, 60)), max_size=40))
def test_every_id_spawned_next_is_reserved_and_nothing_reserved_lies_behind(size, ops):
    """Whatever comes (spawns in the coordinator's order, ids joined by hand), the reserve
    holds exactly the size ids after the highest one seen."""
    r = AgentReserve(size)
    r.plan()
    for kind, rid in ops:
        if kind == "s":
            nxt = r.top + 1                   # the coordinator's next new id
            assert r.take(nxt) == (size > 0)
        else:
            r.saw([rid])
        r.plan()
        assert r.ids == set(range(r.top + 1, r.top + 1 + size))
