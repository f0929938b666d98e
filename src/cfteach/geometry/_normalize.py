"""Canonical form of a constraint matrix: the rows that define the same region, once.

Integral input is kept exact (primitive integer rows, as the reference's rational
H-representation produces); anything else becomes unit-length float rows.
"""

from __future__ import annotations

import numpy as np

#: Integral rows with entries up to this magnitude are handled with exact int64 arithmetic
#: (the 3-D predicates need products of four entries); larger ones use float tolerances.
INT_EXACT_LIMIT = 8192
#: Float rows whose unit vectors agree to this many decimals are treated as duplicates.
FLOAT_DEDUP_DECIMALS = 12


def as_matrix(normals: object, dim: int | None = None) -> np.ndarray:
    """Validate the input and return it as a 2-D numeric array ``[k, F]``."""
    arr = np.asarray(normals)
    if arr.dtype == object or arr.dtype.kind not in "biuf":
        raise ValueError(
            f"constraint normals must be a numeric array, got dtype {arr.dtype!s}"
        )
    if arr.ndim == 1:
        if arr.size == 0:
            if dim is None:
                raise ValueError(
                    "an empty 1-D constraint array has no dimension; pass shape (0, F) "
                    "or dim=F"
                )
            arr = arr.reshape(0, dim)
        else:
            arr = arr[None, :]
    if arr.ndim != 2:
        raise ValueError(f"constraint normals must have shape [k, F], got shape {arr.shape}")
    if dim is not None and arr.shape[1] != dim:
        raise ValueError(f"constraint normals have {arr.shape[1]} columns, expected dim={dim}")
    if arr.shape[1] < 3:
        raise ValueError(
            f"regions need at least 3 features (the sphere S^2 or higher), got {arr.shape[1]}"
        )
    if arr.dtype.kind == "f" and not np.all(np.isfinite(arr)):
        raise ValueError("constraint normals contain NaN or infinite values")
    return arr


def canonical_rows(arr: np.ndarray) -> tuple[np.ndarray, bool]:
    """Return ``(rows, integral)``: zero rows dropped, duplicates collapsed.

    ``integral`` input (integer dtype, or floats that are all whole numbers of magnitude
    below 2**53) gives primitive ``int64`` rows (divided by the gcd of their entries, sign
    kept); other input gives unit-length ``float64`` rows de-duplicated to
    ``FLOAT_DEDUP_DECIMALS`` decimals. Row order: sorted (deterministic, input-order free).
    """
    if arr.dtype.kind in "biu":
        ints: np.ndarray | None = arr.astype(np.int64, copy=False)
        integral = True
    else:
        f = arr.astype(np.float64, copy=False)
        integral = bool(np.all(f == np.round(f))) and bool(np.all(np.abs(f) < 2.0**53))
        ints = f.astype(np.int64) if integral else None
    if integral:
        assert ints is not None
        nonzero = np.any(ints != 0, axis=1)
        if not nonzero.all():
            ints = ints[nonzero]
        if len(ints) == 0:
            return ints.reshape(0, arr.shape[1]), True
        g = np.gcd.reduce(ints, axis=1)
        if np.any(g != 1):
            ints = ints // np.abs(g)[:, None]
        if len(ints) > 1:
            ints = _unique_sorted_int_rows(ints)
        return ints, True
    f = arr.astype(np.float64, copy=False)
    norms = np.sqrt(np.einsum("ij,ij->i", f, f))
    keep = norms > 0
    unit = f[keep] / norms[keep, None]
    if len(unit) > 1:
        keys = np.round(unit, FLOAT_DEDUP_DECIMALS) + 0.0  # + 0.0 folds -0.0 into 0.0
        order = np.lexsort(keys.T[::-1])  # first column most significant
        ks = keys[order]
        keep = np.ones(len(ks), dtype=bool)
        keep[1:] = (ks[1:] != ks[:-1]).any(axis=1)
        unit = unit[order[keep]]
    return unit, False


def _unique_sorted_int_rows(ints: np.ndarray) -> np.ndarray:
    """np.unique(ints, axis=0) (lexicographic), via one int64 key per row when it fits."""
    lo = int(ints.min())
    span = int(ints.max()) - lo + 1
    dim = ints.shape[1]
    if span**dim >= 2**62:
        return np.unique(ints, axis=0)
    weights = span ** np.arange(dim - 1, -1, -1, dtype=np.int64)
    key = (ints - lo) @ weights
    _, first = np.unique(key, return_index=True)
    return ints[first]


def unit_rows(rows: np.ndarray) -> np.ndarray:
    """Unit-length float copies of ``rows`` (elementwise arithmetic: same bits in batches)."""
    f = rows.astype(np.float64)
    if len(f) == 0:
        return f
    sq = f[:, 0] ** 2
    for c in range(1, f.shape[1]):
        sq = sq + f[:, c] ** 2
    return f / np.sqrt(sq)[:, None]
