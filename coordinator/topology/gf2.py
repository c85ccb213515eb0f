"""Linear algebra over GF(2) on bitsets (Python ints): the one elimination of the core.

A vector is an int whose bit i is coordinate i. :class:`Basis` keeps an echelon basis
keyed by each vector's top bit, optionally with the combination of inputs that made it;
:func:`solve` finds a subset of given vectors XOR-ing to a target or, when there is none,
a witness y (orthogonal to every vector, odd overlap with the target: the Fredholm
alternative). :func:`rank` and :func:`in_span` are the span tests. Used by the
certificate (the Schur complement and the closure search) and the redundancy link tests.
"""
from __future__ import annotations

from typing import Iterable, Sequence

__all__ = ["Basis", "solve", "in_span", "rank", "bits", "parity"]


def bits(v: int) -> list[int]:
    """Indices of the set bits of v, ascending."""
    out = []
    i = 0
    while v:
        low = v & -v
        i = low.bit_length() - 1
        out.append(i)
        v ^= low
    return out


def parity(v: int) -> int:
    """Number of set bits of v, mod 2."""
    return v.bit_count() & 1


class Basis:
    """Echelon basis over GF(2). ``add`` returns True when the vector was independent.

    With ``track`` each basis vector carries the mask of the inputs (by their order of
    ``add``) that XOR to it, so :meth:`express` can name a subset.
    """

    __slots__ = ("piv", "track", "count")

    def __init__(self, track: bool = False):
        self.piv: dict[int, tuple[int, int]] = {}  # top bit -> (vector, combination)
        self.track = track
        self.count = 0

    def __len__(self) -> int:
        return len(self.piv)

    def add(self, v: int) -> bool:
        comb = (1 << self.count) if self.track else 0
        self.count += 1
        piv = self.piv
        while v:
            hb = v.bit_length() - 1
            b = piv.get(hb)
            if b is None:
                piv[hb] = (v, comb)
                return True
            v ^= b[0]
            comb ^= b[1]
        return False

    def reduce(self, v: int) -> tuple[int, int]:
        """(residual, combination): v = residual + XOR of the inputs in combination,
        where the residual's top bit is no pivot (0 when v is in the span)."""
        comb = 0
        piv = self.piv
        while v:
            b = piv.get(v.bit_length() - 1)
            if b is None:
                break
            v ^= b[0]
            comb ^= b[1]
        return v, comb

    def witness(self, r: int) -> int:
        """A vector y orthogonal to every basis vector with odd overlap with r, for a
        residual r != 0 returned by :meth:`reduce` (r outside the span)."""
        piv = sorted(self.piv)
        vec = {hb: self.piv[hb][0] for hb in piv}
        for hb in piv:  # fully reduce: clear every pivot bit from the other vectors
            vh = vec[hb]
            for other in piv:
                if other != hb and (vec[other] >> hb) & 1:
                    vec[other] ^= vh
        for hb in piv:  # r zero on every pivot
            if (r >> hb) & 1:
                r ^= vec[hb]
        q = r.bit_length() - 1  # a free bit where r is 1
        y = 1 << q
        for hb in piv:
            if (vec[hb] >> q) & 1:
                y |= 1 << hb
        return y


def solve(vectors: Sequence[int], target: int) -> tuple[list[int] | None, int | None]:
    """(indices of a subset of ``vectors`` XOR-ing to ``target``, None), or (None, y) with
    y orthogonal to every vector and ``parity(y & target) == 1``."""
    B = Basis(track=True)
    for v in vectors:
        B.add(v)
    r, comb = B.reduce(target)
    if r == 0:
        return bits(comb), None
    return None, B.witness(r)


def in_span(vectors: Iterable[int], target: int) -> bool:
    B = Basis()
    for v in vectors:
        B.add(v)
    return B.reduce(target)[0] == 0


def rank(vectors: Iterable[int], stop: int | None = None) -> int:
    """Rank of the vectors; counting stops early once it reaches ``stop``."""
    B = Basis()
    r = 0
    for v in vectors:
        if B.add(v):
            r += 1
            if stop is not None and r >= stop:
                break
    return r
