"""Constraint rows of many demonstrations at once, grouped per demonstration.

A constraint ``c`` means ``c . w >= 0``. Rows are primitive int64 vectors (divided by the gcd
of their entries, sign kept), so equal half-spaces have equal rows and sets can be compared
and deduplicated by their bytes. `RowSet` holds the rows of D demonstrations in one array,
sorted by demo (CSR layout), with duplicates inside a demo removed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cfteach.geometry import reduce_many


def primitive(rows: np.ndarray) -> np.ndarray:
    """Divide integer rows by the gcd of their entries (zero rows stay zero)."""
    rows = np.asarray(rows, dtype=np.int64)
    if rows.size == 0:
        return rows.reshape(-1, rows.shape[-1] if rows.ndim else 0)
    g = np.gcd.reduce(np.abs(rows), axis=-1, keepdims=True)
    return rows // np.where(g == 0, 1, g)


@dataclass(frozen=True, eq=False)
class RowSet:
    """Rows of D demonstrations: ``rows[offsets[d]:offsets[d+1]]`` belong to demo d.

    Inside one demo the rows are unique, nonzero, primitive and sorted lexicographically, so
    two demos have the same half-space set iff their slices are byte-identical.
    """

    rows: np.ndarray  # [R, F] int64
    demo: np.ndarray  # [R] int64, ascending
    offsets: np.ndarray  # [D + 1]

    @property
    def n_demos(self) -> int:
        return len(self.offsets) - 1

    @property
    def F(self) -> int:  # noqa: N802
        return self.rows.shape[1]

    def of(self, d: int) -> np.ndarray:
        """The rows of demo d, ``[k, F]``."""
        return self.rows[self.offsets[d]: self.offsets[d + 1]]

    def counts(self) -> np.ndarray:
        return np.diff(self.offsets)

    def key(self, d: int) -> bytes:
        """A content key of demo d's row set (equal sets give equal keys)."""
        return self.of(d).tobytes()

    def distinct(self, demos: np.ndarray) -> tuple[list[np.ndarray], np.ndarray]:
        """``(sets, slot)``: the distinct row sets of `demos`, and for each demo the index of
        its set (many demos share one, so set-level work is done once per set)."""
        first: dict[bytes, int] = {}
        slot = np.array([first.setdefault(self.key(int(d)), len(first)) for d in demos],
                        dtype=np.int64)
        sets = [np.frombuffer(k, dtype=np.int64).reshape(-1, self.F) for k in first]
        return sets, slot

    def select(self, mask: np.ndarray) -> RowSet:
        """Keep only the rows where `mask` (``[R]``) is true."""
        return _from_sorted(self.rows[mask], self.demo[mask], self.n_demos)

    def union(self, other: RowSet) -> RowSet:
        """Per-demo union with another RowSet over the same demos."""
        if other.n_demos != self.n_demos:
            raise ValueError(f"cannot join row sets of {self.n_demos} and {other.n_demos} demos")
        return group_rows(np.vstack([self.rows, other.rows]),
                          np.concatenate([self.demo, other.demo]), self.n_demos)


def _from_sorted(rows: np.ndarray, demo: np.ndarray, n_demos: int) -> RowSet:
    offsets = np.zeros(n_demos + 1, dtype=np.int64)
    np.cumsum(np.bincount(demo, minlength=n_demos), out=offsets[1:])
    return RowSet(rows=rows, demo=demo, offsets=offsets)


def _pack(rows: np.ndarray, demo: np.ndarray, n_demos: int) -> np.ndarray | None:
    """One int64 per (demo, row) that sorts like (demo, row lexicographically), or None if
    the values do not fit in 63 bits."""
    lo, hi = int(rows.min()), int(rows.max())
    base = hi - lo + 1
    bits = rows.shape[1] * float(np.log2(base)) + float(np.log2(max(n_demos, 2)))
    if bits > 62:
        return None
    key = demo.astype(np.int64)
    for f in range(rows.shape[1]):
        key = key * base + (rows[:, f] - lo)
    return key


def group_rows(rows: np.ndarray, demo: np.ndarray, n_demos: int) -> RowSet:
    """Make rows primitive, drop zeros, sort them by (demo, row) and drop duplicates."""
    rows = primitive(rows)
    demo = np.asarray(demo, dtype=np.int64)
    if rows.ndim != 2 or len(rows) != len(demo):
        raise ValueError(f"rows [R, F] and demo [R] must match, got {rows.shape}, {demo.shape}")
    keep = np.any(rows != 0, axis=1)
    rows, demo = rows[keep], demo[keep]
    if not len(rows):
        return _from_sorted(np.ascontiguousarray(rows), demo, n_demos)
    key = _pack(rows, demo, n_demos)
    if key is not None:
        _, first = np.unique(key, return_index=True)  # sorted by (demo, row), one per value
        rows, demo = rows[first], demo[first]
    else:
        order = np.lexsort((*rows.T[::-1], demo))
        rows, demo = rows[order], demo[order]
        new = np.ones(len(rows), dtype=bool)
        new[1:] = (demo[1:] != demo[:-1]) | np.any(rows[1:] != rows[:-1], axis=1)
        rows, demo = rows[new], demo[new]
    return _from_sorted(np.ascontiguousarray(rows), demo, n_demos)


def reduce_and_measure(rowset: RowSet, demos: np.ndarray | None = None, *,
                       measure: bool = True) -> tuple[dict[int, np.ndarray], np.ndarray]:
    """Irredundant constraints and area of each demo's row set (`geometry.reduce_many`,
    which solves each distinct set once).

    Returns ``({demo: reduced rows [k, F] int64}, areas [n])``; a demo without rows maps to
    ``(0, F)`` and the whole sphere's area. Rows of a RowSet are integers, so the reduced
    rows are exact integers too. ``measure=False`` leaves the areas NaN (not computed).
    """
    ids = np.arange(rowset.n_demos) if demos is None else np.asarray(demos, dtype=np.int64)
    sets, slot = rowset.distinct(ids)
    reduced, areas = reduce_many(sets, dim=rowset.F, measure=measure)
    return ({d: reduced[i] for d, i in zip(ids.tolist(), slot.tolist(), strict=True)},
            areas[slot] if len(slot) else np.zeros(0))


def reduce_sets(rowset: RowSet, demos: np.ndarray | None = None) -> dict[int, np.ndarray]:
    """`reduce_and_measure` without the areas: ``{demo: reduced rows [k, F] int64}``.

    The areas are not computed at all (for more than 3 features each one is a Monte Carlo
    estimate, and the callers here only need the rows)."""
    return reduce_and_measure(rowset, demos, measure=False)[0]
