"""Pieces the closed-loop likelihood tests share: an answer walked move by move, and two
fixed particles to score it under."""

from __future__ import annotations

import numpy as np


def walk(ds, d: int, moves: list[str]) -> tuple[list[int], list[int]]:
    """The states visited and the action indices taken by `moves` from demo d's start."""
    e, s = int(ds.env[d]), int(ds.start[d])
    states = []
    for name in moves:
        states.append(s)
        s = int(ds.batch.next_state[e, s, ds.batch.actions.index(name)])
    return states, [ds.batch.actions.index(m) for m in moves]


def two_particles() -> np.ndarray:
    """Two unit weight vectors inside skateboard's prior."""
    w = np.array([[-0.2, -0.5, -0.84], [-0.9, -0.1, -0.42]])
    return w / np.linalg.norm(w, axis=1, keepdims=True)
