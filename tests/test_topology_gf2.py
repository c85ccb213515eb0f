"""coordinator.topology.gf2 against a dense numpy elimination over GF(2)."""
from __future__ import annotations

import numpy as np
from hypothesis import given, settings, strategies as st

from swarmcover.coordinator.topology import gf2


def _dense_rank(M: np.ndarray) -> int:
    """Rank over GF(2) of a 0/1 matrix by plain row reduction (uint8)."""
    A = (M.astype(np.uint8) & 1).copy()
    r = 0
    for c in range(A.shape[1]):
        piv = np.nonzero(A[r:, c])[0]
        if piv.size == 0:
            continue
        p = r + piv[0]
        A[[r, p]] = A[[p, r]]
        others = np.nonzero(A[:, c])[0]
        others = others[others != r]
        A[others] ^= A[r]
        r += 1
        if r == A.shape[0]:
            break
    return r


def _to_int(col: np.ndarray) -> int:
    return sum(1 << i for i in np.nonzero(col)[0].tolist())


def _to_vec(v: int, m: int) -> np.ndarray:
    return np.array([(v >> i) & 1 for i in range(m)], dtype=np.uint8)


systems = st.tuples(st.integers(1, 24), st.integers(0, 24), st.integers(0, 2**32 - 1), st.floats(0.05, 0.6))


@settings(max_examples=120, deadline=None)
@given(systems)
def test_solve_matches_dense_elimination(sys_):
    m, k, seed, dens = sys_  # m coordinates, k vectors
    rng = np.random.default_rng(seed)
    A = (rng.random((m, k)) < dens).astype(np.uint8)  # columns are the vectors
    if rng.random() < 0.5 and k:  # a target in the span half of the time
        t = (A @ (rng.random(k) < 0.5).astype(np.uint8)) & 1
    else:
        t = (rng.random(m) < dens).astype(np.uint8)
    cols = [_to_int(A[:, j]) for j in range(k)]
    target = _to_int(t)
    solvable = _dense_rank(np.column_stack([A, t])) == _dense_rank(A)
    subset, y = gf2.solve(cols, target)
    assert (subset is not None) == solvable
    assert gf2.in_span(cols, target) == solvable
    assert gf2.rank(cols) == _dense_rank(A)
    if subset is not None:
        assert y is None and len(set(subset)) == len(subset) and all(0 <= i < k for i in subset)
        acc = 0
        for i in subset:
            acc ^= cols[i]
        assert acc == target
    else:
        # the witness: orthogonal to every vector, odd on the target
        yv = _to_vec(y, m)
        assert y >= 0 and y < (1 << m)
        assert not np.any((yv @ A) & 1)
        assert int(yv @ t) & 1 == 1


@settings(max_examples=100, deadline=None)
@given(st.lists(st.integers(0, 2**40), max_size=30), st.integers(0, 40))
def test_rank_stops_early_and_basis_counts(vecs, stop):
    full = gf2.rank(vecs)
    assert gf2.rank(vecs, stop=stop or None) == (min(full, stop) if stop else full)
    B = gf2.Basis()
    assert sum(B.add(v) for v in vecs) == full == len(B)
    for v in vecs:
        assert B.reduce(v)[0] == 0


def test_bits_and_parity():
    assert gf2.bits(0) == [] and gf2.bits(0b101001) == [0, 3, 5]
    assert gf2.parity(0b1011) == 1 and gf2.parity(0) == 0
