"""The generic gridworld engine: `Domain` (a family of instances) and `Instance` (one MDP).

All three study domains, and any user domain, run through this one engine; what differs is
only the data in the domain file (see docs/domains.md). Features are computed per transition
(s, a, s'), as the paper's R = w* . phi(s, a, s') (Section III); the conventions (1-based
coordinates with y up, blocked moves leave the state unchanged) are those of the authors'
code (docs/domains.md, "Using a domain from Python").
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import numpy as np

from cfteach.domains.dynamics import Layout, explore, step_arrays
from cfteach.domains.records import ActionSpec, Cell, DomainSpec

State = tuple[int, ...]


@dataclass(frozen=True)
class _Table:
    """Every transition from an instance's reachable states: row `index[s] * A + a`."""

    index: dict[State, int]
    next: np.ndarray  # int64 [n * A, L]
    phi: np.ndarray  # bool [n * A, F]
    terminal: np.ndarray  # bool [n * A]


_ROW0 = np.zeros(1, dtype=np.int64)  # the one instance of a single-instance layout


@dataclass(frozen=True, eq=False)
class Domain:
    """A family of gridworld instances sharing reward features, w* and beliefs."""

    spec: DomainSpec = field(repr=False)
    name: str
    title: str
    description: str
    feature_names: tuple[str, ...]
    feature_labels: tuple[str, ...]
    weights: np.ndarray = field(repr=False)  # [F], unit L2 norm
    weights_raw: np.ndarray = field(repr=False)  # [F], as written in the file
    prior: np.ndarray = field(repr=False)  # int [k, F], c . w >= 0
    posterior: np.ndarray = field(repr=False)  # int [k, F]
    actions: tuple[str, ...]
    width: int
    height: int
    source: str

    @classmethod
    def from_spec(cls, spec: DomainSpec) -> Domain:
        raw = np.array([f.weight for f in spec.features], dtype=float)
        w = raw / np.linalg.norm(raw)
        f = len(spec.features)
        prior = np.array(spec.prior, dtype=np.int64).reshape(-1, f)
        post = np.array(spec.posterior, dtype=np.int64).reshape(-1, f)
        for arr in (raw, w, prior, post):
            arr.setflags(write=False)
        return cls(
            spec=spec, name=spec.name, title=spec.title, description=spec.description,
            feature_names=tuple(x.name for x in spec.features),
            feature_labels=tuple(x.label for x in spec.features),
            weights=w, weights_raw=raw, prior=prior, posterior=post, actions=spec.actions,
            width=spec.width, height=spec.height, source=spec.source,
        )

    @property
    def action_specs(self) -> tuple[ActionSpec, ...]:
        """Name, label, key and effect of each action, in action order."""
        return self.spec.action_specs

    @property
    def max_demos(self) -> int:
        """Demonstrations per curriculum (``[teaching] max_demos``, default 5)."""
        return self.spec.max_demos

    @property
    def n_features(self) -> int:
        return len(self.feature_names)

    @property
    def n_bits(self) -> int:
        return len(self.spec.variants)

    @property
    def walls(self) -> frozenset[Cell]:
        return self.spec.walls

    @property
    def reference_name(self) -> str | None:
        return self.spec.reference_name

    def instances(self) -> list[Instance]:
        """All instances, index i = binary number of env_code with bit 0 most significant."""
        return list(self._instances)

    def instance(self, env: int | tuple[int, ...] | list[int]) -> Instance:
        """One instance by index or by env code."""
        insts = self._instances
        if isinstance(env, int | np.integer):
            if not 0 <= env < len(insts):
                raise IndexError(f"{self.name}: instance index {env} out of range "
                                 f"0..{len(insts) - 1}")
            return insts[int(env)]
        code = tuple(int(b) for b in env)
        if len(code) != self.n_bits or any(b not in (0, 1) for b in code):
            raise ValueError(f"{self.name}: env_code must be {self.n_bits} bits of 0/1, "
                             f"got {list(env)}")
        return insts[int("".join(map(str, code)) or "0", 2)]

    @cached_property
    def _instances(self) -> tuple[Instance, ...]:
        return tuple(Instance(self, i, code) for i, code in
                     enumerate(itertools.product((0, 1), repeat=self.n_bits)))

    def n_demonstrations(self) -> int:
        """Candidate demonstrations = reachable non-terminal states over all instances."""
        self.prefetch_states()
        return sum(len(inst.states()) for inst in self._instances)

    def prefetch_states(self, indices: list[int] | None = None, chunk: int = 1024) -> None:
        """Search the reachable states of many instances at once (one vectorised search per
        `chunk` instances) and keep them where `Instance.states()` finds them: much faster
        than one instance at a time. `indices`: instance indices (default: all of this
        domain's instances)."""
        insts = (list(self._instances) if indices is None
                 else [self.instance(int(i)) for i in indices])  # original indices
        insts = [i for i in insts if "_states" not in i.__dict__]
        for lo in range(0, len(insts), chunk):
            part = insts[lo:lo + chunk]
            found = explore(Layout(part), np.array([i.initial_state for i in part],
                                                   dtype=np.int64))
            for inst, st in zip(part, found.states, strict=True):
                inst.__dict__["_states"] = tuple(map(tuple, st.tolist()))


class Instance:
    """One MDP of a domain: its static layout is fixed by `env_code` (the variant bits).

    State layout (a tuple of ints): ``(ax, ay)``, then ``(cx, cy, held)`` if the domain declares
    a cargo (all zero in instances where the cargo is switched off), then one present-bit per
    consumable declared by the domain.
    """

    def __init__(self, domain: Domain, index: int, env_code: tuple[int, ...]) -> None:
        spec = domain.spec
        self.domain = domain
        self.index = index
        self.env_code = tuple(env_code)
        on = [v for v, b in zip(spec.variants, env_code, strict=True) if b]
        sets: dict[str, list[Cell]] = {k: list(v) for k, v in spec.cells}
        switched_by_some = {o for v in spec.variants for o in v.switch_on}
        switched_on = {o for v in on for o in v.switch_on}
        for v in on:
            for sname, cells in v.add_cells:
                sets[sname].extend(cells)
        self._cells = {k: frozenset(v) for k, v in sets.items()}
        self.complexity = sum(len(c) for v in on for _, c in v.add_cells) + len(switched_on)

        def present(obj: str) -> bool:
            return obj not in switched_by_some or obj in switched_on

        self.walls: frozenset[Cell] = spec.walls
        self.has_cargo_slot = spec.cargo is not None
        self.cargo_present = spec.cargo is not None and present(spec.cargo.name)
        self.consumables_present = tuple(present(n) for n, _ in spec.consumables)
        self._blocked = (self._cells[spec.cargo.blocked_cells_when_carried]
                         if spec.cargo and spec.cargo.blocked_cells_when_carried else frozenset())
        self._n_cons = len(spec.consumables)
        self._cons_cells = tuple(c for _, c in spec.consumables)
        self._cons_names = tuple(n for n, _ in spec.consumables)
        self._action_names = spec.actions
        self._spec = spec

        init: list[int] = list(spec.agent_start)
        if spec.cargo is not None:  # has_cargo_slot
            init += [*spec.cargo.start, 0] if self.cargo_present else [0, 0, 0]
        init += [1 if p else 0 for p in self.consumables_present]
        self.initial_state: State = tuple(init)
        if self.is_terminal(self.initial_state):
            raise ValueError(f"{spec.source}: instance {self.env_code}: the initial state is "
                             "already terminal")
        object.__setattr__(self, "_frozen", True)

    def __setattr__(self, name: str, value: Any) -> None:
        if getattr(self, "_frozen", False):
            raise AttributeError(f"Instance is immutable (cannot set {name!r})")
        object.__setattr__(self, name, value)

    def __repr__(self) -> str:
        return (f"Instance({self.domain.name!r}, index={self.index}, "
                f"env_code={list(self.env_code)})")

    # ----------------------------------------------------------------- layout
    def cells(self, name: str) -> frozenset[Cell]:
        """The cells of a named cell set in this instance (defaults + switched-on variants)."""
        try:
            return self._cells[name]
        except KeyError:
            raise KeyError(f"{self.domain.name}: no cell set {name!r} "
                           f"(known: {', '.join(sorted(self._cells)) or 'none'})") from None

    @property
    def cell_set_names(self) -> tuple[str, ...]:
        return tuple(self._cells)

    # -------------------------------------------------------------- dynamics
    @cached_property
    def _layout(self) -> Layout:
        return Layout([self])

    def is_terminal(self, state: State) -> bool:
        """Whether the goal holds in `state` (the agent on it, or the cargo delivered)."""
        return bool(self._layout.is_terminal(_ROW0, np.asarray([state], dtype=np.int64))[0])

    def step(self, state: State, action: int) -> tuple[State, np.ndarray, bool]:
        """Apply action (index into the domain's actions): (next state, phi[F], terminal).

        After `exit` the next state is the state it left, flagged terminal. The semantics live
        in `cfteach.domains.dynamics.step_arrays`, shared with the compiled arrays. Once the
        instance's reachable states are known (`states()`, a compile), every transition from
        them is tabulated by one array step, and later calls read the table."""
        n_a = len(self._action_names)
        if not -n_a <= action < n_a:
            raise IndexError(f"action index {action} out of range for {self!r}")
        if "_states" in self.__dict__:
            table = self._table
            row = table.index.get(tuple(state))
            if row is not None:
                k = row * n_a + action % n_a
                return (tuple(table.next[k].tolist()), table.phi[k].astype(float),
                        bool(table.terminal[k]))
        nxt, phi, term = step_arrays(self._layout, _ROW0, np.asarray([state], dtype=np.int64),
                                     np.asarray([action], dtype=np.int64))
        return tuple(nxt[0].tolist()), phi[0].astype(float), bool(term[0])

    @cached_property
    def _table(self) -> _Table:
        states = np.asarray(self._states, dtype=np.int64)
        n, n_a = len(states), len(self._action_names)
        nxt, phi, term = step_arrays(self._layout, np.zeros(n * n_a, dtype=np.int64),
                                     np.repeat(states, n_a, axis=0),
                                     np.tile(np.arange(n_a, dtype=np.int64), n))
        return _Table({s: i for i, s in enumerate(self._states)}, nxt, phi, term)

    def states(self) -> list[State]:
        """Reachable non-terminal states, BFS over actions in order, the initial state first."""
        return list(self._states)

    @cached_property
    def _states(self) -> tuple[State, ...]:
        found = explore(self._layout, np.asarray([self.initial_state], dtype=np.int64))
        return tuple(map(tuple, found.states[0].tolist()))

    # ------------------------------------------------------------ JSON views
    def state_to_json(self, state: State) -> dict[str, Any]:
        """The schema's JSON form: {"agent": [x, y], <cargo>: [x, y] | null, "carrying", ...}."""
        out: dict[str, Any] = {"agent": [state[0], state[1]]}
        off = 2
        if self._spec.cargo is not None:  # has_cargo_slot
            out[self._spec.cargo.name] = ([state[2], state[3]] if self.cargo_present else None)
            out["carrying"] = bool(state[4])
            off = 5
        for i, n in enumerate(self._cons_names):
            out[n] = bool(state[off + i])
        return out

    def state_from_json(self, data: dict[str, Any]) -> State:
        """Parse and validate a JSON state for this instance (ValueError names the problem)."""
        where = f"{self.domain.name} instance {list(self.env_code)}"
        if not isinstance(data, dict):
            raise ValueError(f"{where}: a state must be a JSON object, got {type(data).__name__}")
        expected = {"agent"}
        if self._spec.cargo is not None:  # has_cargo_slot
            expected |= {self._spec.cargo.name, "carrying"}
        expected |= set(self._cons_names)
        if set(data) != expected:
            missing = sorted(expected - set(data))
            extra = sorted(set(data) - expected)
            raise ValueError(f"{where}: state keys must be {sorted(expected)}"
                             + (f"; missing {missing}" if missing else "")
                             + (f"; unknown {extra}" if extra else ""))

        def cell(key: str) -> Cell:
            v = data[key]
            if (not isinstance(v, list | tuple) or len(v) != 2
                    or any(isinstance(x, bool) or not isinstance(x, int) for x in v)):
                raise ValueError(f"{where}: {key!r} must be [x, y] integers, got {v!r}")
            x, y = v
            if not (1 <= x <= self._spec.width and 1 <= y <= self._spec.height):
                raise ValueError(f"{where}: {key!r} cell {[x, y]} is off the grid")
            if (x, y) in self.walls:
                raise ValueError(f"{where}: {key!r} cell {[x, y]} is on a wall")
            return (x, y)

        s: list[int] = list(cell("agent"))
        if self._spec.cargo is not None:  # has_cargo_slot
            cname = self._spec.cargo.name
            carrying = data["carrying"]
            if not isinstance(carrying, bool):
                raise ValueError(f"{where}: 'carrying' must be true or false")
            if data[cname] is None:
                if self.cargo_present:
                    raise ValueError(f"{where}: {cname!r} is null but this instance has one")
                if carrying:
                    raise ValueError(f"{where}: carrying is true but there is no {cname}")
                s += [0, 0, 0]
            else:
                if not self.cargo_present:
                    raise ValueError(f"{where}: this instance has no {cname}")
                c = cell(cname)
                if carrying and c != (s[0], s[1]):
                    raise ValueError(f"{where}: carrying is true but the {cname} at {list(c)} "
                                     f"is not at the agent's cell {s[:2]}")
                if carrying and c in self._blocked:
                    raise ValueError(f"{where}: the {cname} cannot be carried on {list(c)}")
                s += [c[0], c[1], int(carrying)]
        for i, n in enumerate(self._cons_names):
            v = data[n]
            if not isinstance(v, bool):
                raise ValueError(f"{where}: {n!r} must be true or false")
            if v and not self.consumables_present[i]:
                raise ValueError(f"{where}: this instance has no {n}")
            s.append(int(v))
        return tuple(s)

    # ------------------------------------------- the reference's tie-break views
    def _object_ints(self, state: State) -> tuple[list[int], list[int]]:
        cargo: list[int] = []
        if self.cargo_present:
            cargo = [state[2], state[3], state[4]]
        cons: list[int] = []
        off = 5 if self.has_cargo_slot else 2
        for i in range(self._n_cons):
            if state[off + i]:
                cons += list(self._cons_cells[i])
        return cargo, cons

    def state_hash_digits(self, state: State) -> list[int]:
        """Decimal digits of the reference's state identity string (the authors' visual
        dissimilarity: docs/domains.md, "Using a domain from Python")."""
        cargo, cons = self._object_ints(state)
        ints = [state[0], state[1], *cargo, *cons]
        return [int(ch) for v in ints for ch in str(v)]

    def state_attribute_tuple(self, state: State) -> list[int]:
        """The reference's raw attribute tuple of a state (the authors' visual dissimilarity:
        docs/domains.md, "Using a domain from Python")."""
        out = [state[0], state[1]]
        if self.has_cargo_slot:
            out.append(state[4])
        if self.cargo_present:
            out += [state[2], state[3]]
            if self._spec.goal_kind == "cargo_delivered_at":
                out += list(self._spec.goal)
            out.append(state[4])
        _, cons = self._object_ints(state)
        return out + cons
