"""The gridworld semantics over arrays of states: one implementation for `Instance.step` (one
state) and for the reachable-state search that compiles a whole domain (every state of every
instance at once).

`Layout` holds, for a group of instances of one domain, the arrays the step reads (walls,
each instance's cell sets, whether its cargo exists, the compiled feature conditions).
`step_arrays` applies one action to each of N states; `explore` runs the breadth-first search
of reachable states layer by layer over all instances of a layout, computing every
transition exactly once, in the same order as a one-state-at-a-time BFS (pop a state, try the
actions in order, append the states not seen yet).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property
from typing import Protocol

import numpy as np

from cfteach.domains.records import ACTION_EFFECTS, Cell, Condition, DomainSpec

__all__ = ["Exploration", "LaidOut", "Layout", "explore", "step_arrays"]

_MOVE, _PICKUP, _DROPOFF, _EXIT, _STAY = (ACTION_EFFECTS.index(e) for e in
                                          ("move", "pickup", "dropoff", "exit", "stay"))
_KEY_LIMIT = 2 ** 62  # state keys (env * radix + state code) must stay below this


@dataclass(frozen=True)
class _Cond:
    """A condition with its cell sets turned into masks indexed [row, x, y]."""

    actions: np.ndarray | None  # bool [A]
    moved: bool | None
    carrying: bool | None
    from_mask: np.ndarray | None
    leave_mask: np.ndarray | None
    to_mask: np.ndarray | None
    consumes: int | None
    cargo_mask: np.ndarray | None
    negated: tuple[_Cond, ...]


class _HasSpec(Protocol):
    @property
    def spec(self) -> DomainSpec: ...


class LaidOut(Protocol):
    """What `Layout` reads of an instance (`cfteach.domains.model.Instance` is one): its
    domain's spec, whether its cargo exists, and its cell sets. Written as a protocol so the
    rules stand on the domain records alone, below the `Instance` class that uses them."""

    @property
    def domain(self) -> _HasSpec: ...

    @property
    def cargo_present(self) -> bool: ...

    def cells(self, name: str) -> frozenset[Cell]: ...


class Layout:
    """What the step needs to know about a group of instances of one domain, as arrays.

    Cell masks have shape ``[E, W + 2, H + 2]`` (row = position of the instance in the group;
    the border is padding, so off-grid indices after clipping read False).
    """

    def __init__(self, instances: Sequence[LaidOut]) -> None:
        spec: DomainSpec = instances[0].domain.spec
        self.spec = spec
        self.n = len(instances)
        self.width, self.height = spec.width, spec.height
        shape = (spec.width + 2, spec.height + 2)
        self.wall = np.zeros(shape, dtype=bool)
        for x, y in spec.walls:
            self.wall[x, y] = True
        self._instances = instances
        self._masks: dict[str, np.ndarray] = {}
        self.has_cargo = spec.cargo is not None
        self.cargo_present = np.array([i.cargo_present for i in instances], dtype=bool)
        self.n_cons = len(spec.consumables)
        self.cons_off = 5 if self.has_cargo else 2
        self.cons_cells = np.array([c for _, c in spec.consumables],
                                   dtype=np.int64).reshape(-1, 2)
        self.width_of_state = self.cons_off + self.n_cons
        self.n_actions = len(spec.action_specs)
        self.unless = [f.unless for f in spec.features]
        self.goal_agent = spec.goal_kind == "agent_at"
        self.goal = spec.goal

    # Built on first use: `is_terminal` (checked when an instance is created) needs none of it.
    @cached_property
    def blocked(self) -> np.ndarray | None:
        spec = self.spec
        name = spec.cargo.blocked_cells_when_carried if spec.cargo else None
        return self._mask(name) if name else None

    @cached_property
    def effect(self) -> np.ndarray:
        return np.array([ACTION_EFFECTS.index(a.effect) for a in self.spec.action_specs],
                        dtype=np.int64)

    @cached_property
    def delta(self) -> np.ndarray:
        return np.array([a.delta or (0, 0) for a in self.spec.action_specs], dtype=np.int64)

    @cached_property
    def features(self) -> list[tuple[_Cond, ...]]:
        return [tuple(self._cond(c) for c in f.any_of) for f in self.spec.features]

    def _mask(self, name: str) -> np.ndarray:
        m = self._masks.get(name)
        if m is None:
            m = np.zeros((self.n, self.width + 2, self.height + 2), dtype=bool)
            for row, inst in enumerate(self._instances):
                for x, y in inst.cells(name):
                    m[row, x, y] = True
            self._masks[name] = m
        return m

    def _cond(self, c: Condition) -> _Cond:
        acts = None
        if c.actions is not None:
            acts = np.array([a.name in c.actions for a in self.spec.action_specs], dtype=bool)
        cargo = None
        if isinstance(c.cargo_at, str):
            cargo = self._mask(c.cargo_at)
        elif c.cargo_at is not None:
            cargo = np.zeros((1, self.width + 2, self.height + 2), dtype=bool)
            for x, y in c.cargo_at:
                cargo[0, x, y] = True
        cons = ([n for n, _ in self.spec.consumables].index(c.consumes)
                if c.consumes else None)
        return _Cond(
            actions=acts, moved=c.moved, carrying=c.carrying,
            from_mask=self._mask(c.from_cells) if c.from_cells else None,
            leave_mask=self._mask(c.leaves_cells) if c.leaves_cells else None,
            to_mask=self._mask(c.to_cells) if c.to_cells else None,
            consumes=cons, cargo_mask=cargo,
            negated=tuple(self._cond(n) for n in c.negated))

    def is_terminal(self, row: np.ndarray, states: np.ndarray) -> np.ndarray:
        """bool [N]: the goal holds in each state (row = instance position in the layout)."""
        gx, gy = self.goal
        if self.goal_agent:
            return (states[:, 0] == gx) & (states[:, 1] == gy)
        return (self.cargo_present[row] & (states[:, 4] == 0)
                & (states[:, 2] == gx) & (states[:, 3] == gy))

    def state_radix(self) -> np.ndarray:
        """Per state component, one more than its largest value (for integer state keys)."""
        w, h = self.width + 1, self.height + 1
        rad = [w, h] + ([w, h, 2] if self.has_cargo else []) + [2] * self.n_cons
        return np.array(rad, dtype=object)


def _pick(mask: np.ndarray, row: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """mask[row, x, y], with a shared mask (first axis 1) read for every row."""
    if mask.shape[0] == 1:
        return mask[0, x, y]
    return mask[row, x, y]


def _holds(c: _Cond, ctx: dict[str, np.ndarray]) -> np.ndarray:
    ok = np.ones(ctx["act"].shape[0], dtype=bool)
    if c.actions is not None:
        ok &= c.actions[ctx["act"]]
    if c.moved is not None:
        ok &= ctx["moved"] == c.moved
    if c.carrying is not None:
        ok &= ctx["held"] == c.carrying
    row, ax, ay = ctx["row"], ctx["ax"], ctx["ay"]
    if c.from_mask is not None:
        ok &= _pick(c.from_mask, row, ax, ay)
    if c.leave_mask is not None:
        ok &= ctx["moved"] & _pick(c.leave_mask, row, ax, ay)
    if c.to_mask is not None:
        ok &= ctx["moved"] & _pick(c.to_mask, row, ctx["nx"], ctx["ny"])
    if c.consumes is not None:
        ok &= ctx["consumed"][:, c.consumes]
    if c.cargo_mask is not None:
        ok &= ctx["cargo_on"] & _pick(c.cargo_mask, row, ctx["cx"], ctx["cy"])
    for n in c.negated:
        ok &= ~_holds(n, ctx)
    return ok


def step_arrays(lay: Layout, row: np.ndarray, states: np.ndarray, act: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Apply action `act[i]` to `states[i]` of instance `row[i]` (layout position).

    Returns (next states int64 [N, L], features bool [N, F], terminal bool [N]). Terminal
    inputs stay put with no feature; `exit` returns the state it left, flagged terminal.
    """
    states = np.asarray(states, dtype=np.int64)
    n = states.shape[0]
    was_term = lay.is_terminal(row, states)
    ax, ay = states[:, 0], states[:, 1]
    held = (states[:, 4] == 1) if lay.has_cargo else np.zeros(n, dtype=bool)
    eff = lay.effect[act]
    nx = ax + lay.delta[act, 0]
    ny = ay + lay.delta[act, 1]
    inside = (nx >= 1) & (nx <= lay.width) & (ny >= 1) & (ny <= lay.height)
    cx_ = np.minimum(np.maximum(nx, 0), lay.width + 1)  # np.clip is slow on small arrays
    cy_ = np.minimum(np.maximum(ny, 0), lay.height + 1)
    moved = (eff == _MOVE) & inside & ~lay.wall[cx_, cy_]
    if lay.blocked is not None:
        moved &= ~(held & lay.blocked[row, cx_, cy_])
    moved &= ~was_term
    nxt = states.copy()
    nxt[:, 0] = np.where(moved, nx, ax)
    nxt[:, 1] = np.where(moved, ny, ay)
    if lay.has_cargo:
        carried = moved & held
        nxt[:, 2] = np.where(carried, nx, states[:, 2])
        nxt[:, 3] = np.where(carried, ny, states[:, 3])
        pick = ((eff == _PICKUP) & lay.cargo_present[row] & ~held
                & (states[:, 2] == ax) & (states[:, 3] == ay) & ~was_term)
        nxt[pick, 4] = 1
        drop = (eff == _DROPOFF) & held & ~was_term
        nxt[drop, 4] = 0
    consumed = np.zeros((n, lay.n_cons), dtype=bool)
    for i in range(lay.n_cons):
        col = lay.cons_off + i
        hit = (moved & (states[:, col] == 1) & (ax == lay.cons_cells[i, 0])
               & (ay == lay.cons_cells[i, 1]))
        nxt[hit, col] = 0
        consumed[:, i] = hit
    if lay.has_cargo:
        cargo_on = lay.cargo_present[row]
        cx, cy = states[:, 2], states[:, 3]
    else:
        cargo_on = np.zeros(n, dtype=bool)
        cx = cy = np.zeros(n, dtype=np.int64)
    ctx = {"act": act, "moved": moved, "held": held, "row": row, "ax": ax, "ay": ay,
           "nx": nxt[:, 0], "ny": nxt[:, 1], "consumed": consumed, "cargo_on": cargo_on,
           "cx": cx, "cy": cy}
    fired = np.zeros((n, len(lay.features)), dtype=bool)
    for i, alts in enumerate(lay.features):
        if alts:
            f = _holds(alts[0], ctx)
            for alt in alts[1:]:
                f |= _holds(alt, ctx)
        else:
            f = np.ones(n, dtype=bool)
        for j in lay.unless[i]:
            f &= ~fired[:, j]
        fired[:, i] = f
    fired[was_term] = False
    terminal = was_term | (eff == _EXIT) | lay.is_terminal(row, nxt)
    return nxt, fired, terminal


@dataclass(frozen=True)
class Exploration:
    """Reachable non-terminal states and their transitions, for the instances of a layout.

    `states[r]` is instance r's states in BFS order (int64 ``[n_r, L]``); the transitions are
    flat rows ``(row, src, action) -> dest`` (dest = -1: terminal) with features ``phi``.
    """

    states: list[np.ndarray]
    row: np.ndarray
    src: np.ndarray
    action: np.ndarray
    dest: np.ndarray
    phi: np.ndarray  # bool [T, F]


def explore(lay: Layout, initial: np.ndarray) -> Exploration:
    """Breadth-first search of every instance's reachable non-terminal states, all at once.

    `initial[r]` is instance r's initial state (non-terminal). Layer by layer, each frontier
    state (instance-major, BFS order) tries every action in order; the new states, first
    occurrence first, form the next layer. That is exactly the order of a one-state-at-a-time
    BFS, and every transition is computed once.
    """
    initial = np.asarray(initial, dtype=np.int64).reshape(lay.n, -1)
    rad = lay.state_radix()
    mult_obj = np.cumprod(np.concatenate([[1], rad[:-1]]))
    radix = int(np.prod(rad))
    if radix * lay.n >= _KEY_LIMIT:
        raise ValueError(f"{lay.spec.source}: too many state combinations to index "
                         f"({radix} per instance); declare fewer consumables")
    mult = mult_obj.astype(np.int64)
    n_a = lay.n_actions

    def key(rows: np.ndarray, st: np.ndarray) -> np.ndarray:
        return rows * radix + st @ mult

    f_row = np.arange(lay.n, dtype=np.int64)
    f_idx = np.zeros(lay.n, dtype=np.int64)
    f_st = initial
    count = np.ones(lay.n, dtype=np.int64)
    seen = key(f_row, f_st)
    seen_idx = np.zeros(lay.n, dtype=np.int64)
    order = np.argsort(seen, kind="stable")
    seen, seen_idx = seen[order], seen_idx[order]
    layers_st, layers_row = [f_st], [f_row]
    t_row, t_src, t_act, t_dest, t_phi = [], [], [], [], []
    while f_row.size:
        n = f_row.size
        row = np.repeat(f_row, n_a)
        src = np.repeat(f_idx, n_a)
        act = np.tile(np.arange(n_a, dtype=np.int64), n)
        nxt, phi, term = step_arrays(lay, row, np.repeat(f_st, n_a, axis=0), act)
        dest = np.full(n * n_a, -1, dtype=np.int64)
        live = np.flatnonzero(~term)
        k = key(row[live], nxt[live])
        pos = np.minimum(np.searchsorted(seen, k), seen.size - 1)
        hit = seen[pos] == k
        dest[live[hit]] = seen_idx[pos[hit]]
        miss = live[~hit]
        uniq, first, inv = np.unique(k[~hit], return_index=True, return_inverse=True)
        disc = np.argsort(first, kind="stable")  # unique keys in discovery order
        new_rows = miss[first[disc]]
        new_row = row[new_rows]
        # Index within each instance: its count so far + rank among this layer's new states
        # (new_row is non-decreasing, as the frontier is instance-major).
        starts = np.flatnonzero(np.r_[True, new_row[1:] != new_row[:-1]])
        group = np.repeat(starts, np.diff(np.r_[starts, new_row.size]))
        new_idx = count[new_row] + np.arange(new_row.size) - group
        count += np.bincount(new_row, minlength=lay.n)
        idx_of_uniq = np.empty(uniq.size, dtype=np.int64)
        idx_of_uniq[disc] = new_idx
        dest[miss] = idx_of_uniq[inv.reshape(-1)]
        t_row.append(row)
        t_src.append(src)
        t_act.append(act)
        t_dest.append(dest)
        t_phi.append(phi)
        merged = np.concatenate([seen, uniq])
        merged_idx = np.concatenate([seen_idx, idx_of_uniq])
        order = np.argsort(merged, kind="stable")
        seen, seen_idx = merged[order], merged_idx[order]
        f_row, f_idx, f_st = new_row, new_idx, nxt[new_rows]
        layers_st.append(f_st)
        layers_row.append(f_row)
    all_st = np.concatenate(layers_st)
    all_row = np.concatenate(layers_row)
    by_row = np.argsort(all_row, kind="stable")  # instance-major, BFS order within
    bounds = np.r_[0, np.cumsum(np.bincount(all_row, minlength=lay.n))]
    sorted_st = all_st[by_row]
    states = [sorted_st[bounds[r]:bounds[r + 1]] for r in range(lay.n)]
    return Exploration(states=states, row=np.concatenate(t_row), src=np.concatenate(t_src),
                       action=np.concatenate(t_act), dest=np.concatenate(t_dest),
                       phi=np.concatenate(t_phi))
