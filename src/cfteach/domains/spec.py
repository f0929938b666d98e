"""Parse and validate a domain description (TOML text or a plain dict) into a `DomainSpec`.

Validation is strict on purpose: a domain file is written by hand, and a typo in a key or a
cell on a wall would otherwise silently produce a different MDP. Every error names the file,
the key path (e.g. ``features[1].when.from_cells``) and the problem.
"""

from __future__ import annotations

import math
import re
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

ACTIONS: tuple[str, ...] = ("up", "down", "left", "right", "pickup", "dropoff")
MOVES: dict[str, tuple[int, int]] = {
    "up": (0, 1), "down": (0, -1), "left": (-1, 0), "right": (1, 0)}
INTERACT: tuple[str, ...] = ("pickup", "dropoff")

#: What an action does to the state. ``move`` shifts the agent by its delta; ``pickup`` and
#: ``dropoff`` act on the cargo; ``exit`` ends the episode from any non-terminal state;
#: ``stay`` leaves the state unchanged.
ACTION_EFFECTS: tuple[str, ...] = ("move", "pickup", "dropoff", "exit", "stay")


@dataclass(frozen=True)
class ActionSpec:
    """One action of a domain, in the domain's action order (the order breaks ties).

    `key` is the keyboard key the study app binds (a `KeyboardEvent.key` value such as
    ``"ArrowUp"`` or ``"x"``) and `label` the words shown beside it; the renderer and the
    Gymnasium environment read the same record.
    """

    name: str
    label: str
    key: str
    effect: str
    delta: tuple[int, int] | None = None  # for effect "move"


#: The built-in actions, as a domain file that lists action names gets them.
BUILTIN_ACTIONS: dict[str, ActionSpec] = {
    "up": ActionSpec("up", "move up", "ArrowUp", "move", (0, 1)),
    "down": ActionSpec("down", "move down", "ArrowDown", "move", (0, -1)),
    "left": ActionSpec("left", "move left", "ArrowLeft", "move", (-1, 0)),
    "right": ActionSpec("right", "move right", "ArrowRight", "move", (1, 0)),
    "pickup": ActionSpec("pickup", "pick up", "p", "pickup"),
    "dropoff": ActionSpec("dropoff", "drop", "d", "dropoff"),
}

Cell = tuple[int, int]

#: Demonstrations per curriculum when a domain file has no ``[teaching] max_demos``.
DEFAULT_MAX_DEMOS = 5


class DomainFileError(ValueError):
    """A domain file (or dict) is malformed; the message names file, key path and problem."""

    def __init__(self, source: str, key: str, problem: str) -> None:
        self.source = source
        self.key = key
        self.problem = problem
        where = f"{source}: {key}" if key else source
        super().__init__(f"{where}: {problem}")


@dataclass(frozen=True)
class Condition:
    """One conjunction of per-transition tests; unset fields are not tested."""

    actions: frozenset[str] | None = None
    moved: bool | None = None
    carrying: bool | None = None
    from_cells: str | None = None
    leaves_cells: str | None = None
    consumes: str | None = None
    to_cells: str | None = None  # the agent moved and its cell in s' is in the set
    cargo_at: frozenset[Cell] | str | None = None  # cells, or a cell set, holding the cargo in s
    negated: tuple[Condition, ...] = ()  # `not = {...}`: none of these may hold


@dataclass(frozen=True)
class FeatureSpec:
    name: str
    label: str
    weight: float
    any_of: tuple[Condition, ...]  # OR of conjunctions; empty tuple = always fires
    unless: tuple[int, ...]  # indices of earlier features that suppress this one


@dataclass(frozen=True)
class VariantSpec:
    name: str
    add_cells: tuple[tuple[str, tuple[Cell, ...]], ...]
    switch_on: tuple[str, ...]


@dataclass(frozen=True)
class CargoSpec:
    name: str
    start: Cell
    blocked_cells_when_carried: str | None


@dataclass(frozen=True)
class DomainSpec:
    """The validated content of a domain file, before instances are built."""

    source: str
    name: str
    title: str
    description: str
    reference_name: str | None
    width: int
    height: int
    discount: float
    actions: tuple[str, ...]
    walls: frozenset[Cell]
    cells: tuple[tuple[str, tuple[Cell, ...]], ...]  # default content of each named set
    agent_start: Cell
    cargo: CargoSpec | None
    consumables: tuple[tuple[str, Cell], ...]
    goal_kind: str  # "agent_at" or "cargo_delivered_at"
    goal: Cell
    variants: tuple[VariantSpec, ...]
    features: tuple[FeatureSpec, ...]
    prior: tuple[tuple[int, ...], ...]
    posterior: tuple[tuple[int, ...], ...]
    max_demos: int = DEFAULT_MAX_DEMOS  # [teaching] max_demos: demonstrations per curriculum
    action_specs: tuple[ActionSpec, ...] = ()  # one per action, same order as `actions`
    known: tuple[str, ...] = ()  # [beliefs] known: features whose weight the learner knows

    def __post_init__(self) -> None:
        if not self.action_specs:
            object.__setattr__(self, "action_specs",
                               tuple(BUILTIN_ACTIONS[a] for a in self.actions))


_TOP_KEYS = {"domain", "cells", "agent", "cargo", "consumables", "goal", "variants", "features",
             "beliefs", "teaching"}
_DOMAIN_KEYS = {"name", "title", "description", "reference_name", "width", "height", "discount",
                "actions", "walls"}
_COND_KEYS = {"action", "moved", "carrying", "from_cells", "leaves_cells", "to_cells", "consumes",
              "cargo_at", "not"}
_ACTION_KEYS = {"name", "label", "key", "effect", "delta"}
_KEY_RE = re.compile(r".|[A-Z][A-Za-z0-9]+", re.S)  # a character, or a named key ("ArrowUp")
#: Words an `action` condition accepts besides action names, so no action may be named so.
_ACTION_GROUPS = ("move", "interact")


class _Checker:
    """Small helpers that raise `DomainFileError` with the source attached."""

    def __init__(self, source: str) -> None:
        self.source = source

    def fail(self, key: str, problem: str) -> DomainFileError:
        return DomainFileError(self.source, key, problem)

    def table(self, value: Any, key: str, allowed: set[str], required: set[str] = frozenset()
              ) -> dict[str, Any]:
        if not isinstance(value, dict):
            raise self.fail(key, f"must be a table, got {type(value).__name__}")
        for k in value:
            if k not in allowed:
                sub = f"{key}.{k}" if key else k
                raise self.fail(sub, f"unknown key (allowed: {', '.join(sorted(allowed))})")
        for k in required:
            if k not in value:
                sub = f"{key}.{k}" if key else k
                raise self.fail(sub, "missing required key")
        return value

    def string(self, value: Any, key: str, *, nonempty: bool = True) -> str:
        if not isinstance(value, str):
            raise self.fail(key, f"must be a string, got {type(value).__name__}")
        if nonempty and not value.strip():
            raise self.fail(key, "must not be empty")
        return value

    def integer(self, value: Any, key: str, *, minimum: int | None = None) -> int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.fail(key, f"must be an integer, got {type(value).__name__}")
        if minimum is not None and value < minimum:
            raise self.fail(key, f"must be at least {minimum}, got {value}")
        return value

    def number(self, value: Any, key: str) -> float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise self.fail(key, f"must be a number, got {type(value).__name__}")
        if not math.isfinite(value):
            raise self.fail(key, f"must be finite, got {value}")
        return float(value)

    def boolean(self, value: Any, key: str) -> bool:
        if not isinstance(value, bool):
            raise self.fail(key, f"must be true or false, got {type(value).__name__}")
        return value

    def array(self, value: Any, key: str) -> list[Any]:
        if not isinstance(value, list):
            raise self.fail(key, f"must be a list, got {type(value).__name__}")
        return value

    def cell(self, value: Any, key: str, width: int, height: int,
             walls: frozenset[Cell] = frozenset()) -> Cell:
        if (not isinstance(value, list | tuple) or len(value) != 2
                or any(isinstance(v, bool) or not isinstance(v, int) for v in value)):
            raise self.fail(key, f"must be a cell [x, y] of two integers, got {value!r}")
        x, y = int(value[0]), int(value[1])
        if not (1 <= x <= width and 1 <= y <= height):
            raise self.fail(key, f"cell [{x}, {y}] is off the {width}x{height} grid "
                                 "(coordinates are 1-based, y up)")
        if (x, y) in walls:
            raise self.fail(key, f"cell [{x}, {y}] is on a wall")
        return (x, y)

    def cells(self, value: Any, key: str, width: int, height: int,
              walls: frozenset[Cell] = frozenset()) -> tuple[Cell, ...]:
        items = self.array(value, key)
        return tuple(self.cell(v, f"{key}[{i}]", width, height, walls) for i, v in enumerate(items))

    def name(self, value: Any, key: str, taken: dict[str, str]) -> str:
        s = self.string(value, key)
        if s in taken:
            raise self.fail(key, f"name {s!r} is already used by {taken[s]}")
        taken[s] = key
        return s


def load_toml(path: Path) -> dict[str, Any]:
    """Read a TOML file; syntax errors are reported as `DomainFileError` naming the file."""
    try:
        with open(path, "rb") as fh:
            return tomllib.load(fh)
    except tomllib.TOMLDecodeError as exc:
        raise DomainFileError(str(path), "", f"not valid TOML: {exc}") from None
    except OSError as exc:
        raise DomainFileError(str(path), "", f"cannot read file: {exc.strerror}") from None


def parse_spec(data: Any, source: str = "<dict>") -> DomainSpec:
    """Validate a domain description and return its `DomainSpec`."""
    c = _Checker(source)
    top = c.table(data, "", _TOP_KEYS, {"domain", "agent", "goal", "features"})

    d = c.table(top["domain"], "domain", _DOMAIN_KEYS, {"name", "width", "height"})
    name = c.string(d["name"], "domain.name")
    title = c.string(d.get("title", name), "domain.title")
    description = c.string(d.get("description", ""), "domain.description", nonempty=False)
    reference_name = (c.string(d["reference_name"], "domain.reference_name")
                      if "reference_name" in d else None)
    width = c.integer(d["width"], "domain.width", minimum=1)
    height = c.integer(d["height"], "domain.height", minimum=1)
    discount = c.number(d.get("discount", 1.0), "domain.discount")
    if discount != 1.0:
        raise c.fail("domain.discount", f"only 1.0 is supported (undiscounted, as in the "
                                        f"reference), got {discount}")
    action_specs = (_actions(c, d["actions"], "domain.actions") if "actions" in d
                    else tuple(BUILTIN_ACTIONS[a] for a in ACTIONS))
    actions = tuple(a.name for a in action_specs)
    walls = frozenset(c.cells(d.get("walls", []), "domain.walls", width, height))

    taken: dict[str, str] = {"agent": "the agent", "carrying": "the carrying flag"}

    # Named static cell sets.
    cells_tbl = top.get("cells", {})
    if not isinstance(cells_tbl, dict):
        raise c.fail("cells", f"must be a table, got {type(cells_tbl).__name__}")
    cell_sets: dict[str, tuple[Cell, ...]] = {}
    for k, v in cells_tbl.items():
        if not k.strip():
            raise c.fail("cells", "a cell set needs a non-empty name")
        cell_sets[k] = c.cells(v, f"cells.{k}", width, height, walls)

    a = c.table(top["agent"], "agent", {"start"}, {"start"})
    agent_start = c.cell(a["start"], "agent.start", width, height, walls)

    cargo = None
    if "cargo" in top:
        t = c.table(top["cargo"], "cargo", {"name", "start", "blocked_cells_when_carried"},
                    {"name", "start"})
        cname = c.name(t["name"], "cargo.name", taken)
        cstart = c.cell(t["start"], "cargo.start", width, height, walls)
        blocked = None
        if "blocked_cells_when_carried" in t:
            blocked = c.string(t["blocked_cells_when_carried"], "cargo.blocked_cells_when_carried")
            if blocked not in cell_sets:
                raise c.fail("cargo.blocked_cells_when_carried",
                             f"unknown cell set {blocked!r} (declare it under [cells])")
        cargo = CargoSpec(cname, cstart, blocked)

    consumables: list[tuple[str, Cell]] = []
    for i, t in enumerate(c.array(top.get("consumables", []), "consumables")):
        key = f"consumables[{i}]"
        t = c.table(t, key, {"name", "cell"}, {"name", "cell"})
        consumables.append((c.name(t["name"], f"{key}.name", taken),
                            c.cell(t["cell"], f"{key}.cell", width, height, walls)))
    consumable_names = {n for n, _ in consumables}
    objects = consumable_names | ({cargo.name} if cargo else set())

    g = c.table(top["goal"], "goal", {"agent_at", "cargo_delivered_at"})
    if len(g) != 1:
        raise c.fail("goal", "give exactly one of agent_at = [x, y] or cargo_delivered_at = [x, y]")
    goal_kind = next(iter(g))
    goal = c.cell(g[goal_kind], f"goal.{goal_kind}", width, height, walls)
    if goal_kind == "cargo_delivered_at" and cargo is None:
        raise c.fail("goal.cargo_delivered_at", "needs a [cargo] table")
    if goal_kind == "agent_at" and goal == agent_start:
        raise c.fail("goal.agent_at", "the agent starts on the goal")

    variants: list[VariantSpec] = []
    for i, t in enumerate(c.array(top.get("variants", []), "variants")):
        key = f"variants[{i}]"
        t = c.table(t, key, {"name", "add_cells", "switch_on"})
        vname = c.string(t.get("name", f"bit {i}"), f"{key}.name")
        adds: list[tuple[str, tuple[Cell, ...]]] = []
        add_tbl = t.get("add_cells", {})
        if not isinstance(add_tbl, dict):
            raise c.fail(f"{key}.add_cells", "must be a table {set_name = [[x, y], ...]}")
        for sname, lst in add_tbl.items():
            if sname not in cell_sets:
                raise c.fail(f"{key}.add_cells.{sname}",
                             f"unknown cell set {sname!r} (declare it under [cells])")
            adds.append((sname, c.cells(lst, f"{key}.add_cells.{sname}", width, height, walls)))
        switch = c.array(t.get("switch_on", []), f"{key}.switch_on")
        for j, o in enumerate(switch):
            if o not in objects:
                raise c.fail(f"{key}.switch_on[{j}]", f"unknown object {o!r} (known: "
                             f"{', '.join(sorted(objects)) or 'none'})")
        if not adds and not switch:
            raise c.fail(key, "a variant must add cells or switch on an object")
        variants.append(VariantSpec(vname, tuple(adds), tuple(switch)))
    if len(variants) > 20:
        raise c.fail("variants", f"{len(variants)} bits give too many instances (at most 20)")

    features: list[FeatureSpec] = []
    fnames: dict[str, int] = {}
    for i, t in enumerate(c.array(top["features"], "features")):
        key = f"features[{i}]"
        t = c.table(t, key, {"name", "label", "weight", "when", "any", "unless"},
                    {"name", "weight"})
        fname = c.string(t["name"], f"{key}.name")
        if fname in fnames:
            raise c.fail(f"{key}.name", f"duplicate feature name {fname!r}")
        label = c.string(t.get("label", fname), f"{key}.label")
        weight = c.number(t["weight"], f"{key}.weight")
        if "when" in t and "any" in t:
            raise c.fail(key, "give either `when` or `any`, not both")
        if "any" in t:
            alts = c.array(t["any"], f"{key}.any")
            if not alts:
                raise c.fail(f"{key}.any", "must list at least one condition table")
            any_of = tuple(_condition(c, v, f"{key}.any[{j}]", cell_sets, consumable_names,
                                      action_specs, cargo, width, height, walls)
                           for j, v in enumerate(alts))
        elif "when" in t:
            any_of = (_condition(c, t["when"], f"{key}.when", cell_sets, consumable_names,
                                 action_specs, cargo, width, height, walls),)
        else:
            any_of = ()
        unless = []
        for j, u in enumerate(c.array(t.get("unless", []), f"{key}.unless")):
            if u not in fnames:
                raise c.fail(f"{key}.unless[{j}]",
                             f"{u!r} is not an earlier feature (features are evaluated in order)")
            unless.append(fnames[u])
        fnames[fname] = i
        features.append(FeatureSpec(fname, label, weight, any_of, tuple(unless)))
    if not features:
        raise c.fail("features", "must list at least one feature")
    if all(f.weight == 0.0 for f in features):
        raise c.fail("features", "the weights are all zero (w* must have a direction)")
    norm = math.sqrt(sum(f.weight ** 2 for f in features))
    if not math.isfinite(norm) or norm == 0.0:
        raise c.fail("features", "the weight vector has no finite unit direction")

    b = c.table(top.get("beliefs", {}), "beliefs", {"prior", "posterior", "known"})
    prior = _constraints(c, b.get("prior", []), "beliefs.prior", len(features))
    posterior = _constraints(c, b.get("posterior", []), "beliefs.posterior", len(features))
    known = _known(c, b.get("known", []), [f.name for f in features])

    t = c.table(top.get("teaching", {}), "teaching", {"max_demos"})
    max_demos = c.integer(t.get("max_demos", DEFAULT_MAX_DEMOS), "teaching.max_demos",
                          minimum=1)

    return DomainSpec(
        source=source, name=name, title=title, description=description,
        reference_name=reference_name, width=width, height=height, discount=discount,
        actions=actions, walls=walls, cells=tuple(cell_sets.items()), agent_start=agent_start,
        cargo=cargo, consumables=tuple(consumables), goal_kind=goal_kind, goal=goal,
        variants=tuple(variants), features=tuple(features), prior=prior, posterior=posterior,
        max_demos=max_demos, action_specs=action_specs, known=known,
    )


def _known(c: _Checker, value: Any, names: list[str]) -> tuple[str, ...]:
    """`beliefs.known`: feature names whose weight the learner is told (at least one left)."""
    if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
        raise c.fail("beliefs.known", "must be a list of feature names")
    for j, v in enumerate(value):
        if v not in names:
            raise c.fail(f"beliefs.known[{j}]", f"unknown feature {v!r} (features: "
                         f"{', '.join(names)})")
        if v in value[:j]:
            raise c.fail(f"beliefs.known[{j}]", f"feature {v!r} listed twice")
    if len(value) >= len(names) - 1:
        raise c.fail("beliefs.known", "leaves fewer than two unknown weights (nothing to "
                     "teach on the slice)")
    return tuple(value)


def _actions(c: _Checker, value: Any, key: str) -> tuple[ActionSpec, ...]:
    """`domain.actions`: built-in names and/or tables declaring actions, in tie-break order."""
    items = c.array(value, key)
    if not items:
        raise c.fail(key, "must list at least one action")
    out: list[ActionSpec] = []
    names: dict[str, str] = {}
    keys: dict[str, str] = {}
    for i, item in enumerate(items):
        k = f"{key}[{i}]"
        if isinstance(item, str):
            if item not in BUILTIN_ACTIONS:
                raise c.fail(k, f"unknown action {item!r} (built-in: {', '.join(ACTIONS)}; "
                                "declare others as a table {name, label, key, effect})")
            spec = BUILTIN_ACTIONS[item]
        else:
            spec = _action_table(c, item, k)
        if spec.name in names:
            raise c.fail(f"{k}.name" if isinstance(item, dict) else k,
                         f"lists action {spec.name!r} twice (also {names[spec.name]})")
        if spec.key in keys:
            raise c.fail(f"{k}.key" if isinstance(item, dict) else k,
                         f"key {spec.key!r} of action {spec.name!r} is already bound to "
                         f"{keys[spec.key]}")
        names[spec.name] = k
        keys[spec.key] = f"action {spec.name!r}"
        out.append(spec)
    return tuple(out)


def _action_table(c: _Checker, item: Any, key: str) -> ActionSpec:
    """One declared action. A built-in name may be given as a table to relabel or rebind it
    (its effect and delta then default to the built-in's)."""
    t = c.table(item, key, _ACTION_KEYS, {"name"})
    name = c.string(t["name"], f"{key}.name")
    if name in _ACTION_GROUPS:
        raise c.fail(f"{key}.name", f"{name!r} is reserved (a condition's `action = {name!r}` "
                                    "means a group of actions)")
    base = BUILTIN_ACTIONS.get(name)
    if "effect" not in t and base is None:
        raise c.fail(f"{key}.effect", "missing required key (one of "
                                      f"{', '.join(ACTION_EFFECTS)})")
    effect = c.string(t["effect"], f"{key}.effect") if "effect" in t else base.effect
    if effect not in ACTION_EFFECTS:
        raise c.fail(f"{key}.effect",
                     f"unknown effect {effect!r} (known: {', '.join(ACTION_EFFECTS)})")
    delta = None
    if effect == "move":
        if "delta" in t:
            raw = t["delta"]
            if (not isinstance(raw, list) or len(raw) != 2
                    or any(isinstance(v, bool) or not isinstance(v, int) for v in raw)):
                raise c.fail(f"{key}.delta", f"must be [dx, dy], two integers, got {raw!r}")
            delta = (int(raw[0]), int(raw[1]))
            if delta == (0, 0):
                raise c.fail(f"{key}.delta", "must not be [0, 0] (use effect = \"stay\")")
        elif base is not None and base.effect == "move":
            delta = base.delta
        else:
            raise c.fail(f"{key}.delta", "a move needs delta = [dx, dy] (x right, y up)")
    elif "delta" in t:
        raise c.fail(f"{key}.delta", f"only a move has a delta (effect is {effect!r})")
    if "key" not in t and base is None:
        raise c.fail(f"{key}.key", "missing required key (the keyboard key the study app "
                                   "binds, e.g. \"x\" or \"ArrowUp\")")
    kb = base.key if base is not None and "key" not in t else t["key"]
    if not isinstance(kb, str) or not _KEY_RE.fullmatch(kb) or not kb.isprintable():
        raise c.fail(f"{key}.key", f"must be one character or a key name such as \"ArrowUp\" "
                                   f"or \"Enter\" (a KeyboardEvent.key value), got {kb!r}")
    label = c.string(t.get("label", base.label if base else name), f"{key}.label")
    return ActionSpec(name, label, kb, effect, delta)


def _condition(c: _Checker, value: Any, key: str, cell_sets: dict[str, Any],
               consumables: set[str], actions: tuple[ActionSpec, ...],
               cargo: CargoSpec | None, width: int, height: int,
               walls: frozenset[Cell]) -> Condition:
    t = c.table(value, key, _COND_KEYS)
    names = tuple(a.name for a in actions)
    acts = None
    if "action" in t:
        raw = t["action"]
        if raw == "move":
            raw = [a.name for a in actions if a.effect == "move"]
        elif raw == "interact":
            raw = [a.name for a in actions if a.effect in INTERACT]
        elif isinstance(raw, str):
            raw = [raw]
        raw = c.array(raw, f"{key}.action")
        for j, a in enumerate(raw):
            if a not in names:
                raise c.fail(f"{key}.action[{j}]", f"unknown action {a!r} (known: "
                             f"{', '.join(names)}, or the words \"move\" / \"interact\")")
        acts = frozenset(raw)
    for k in ("from_cells", "leaves_cells", "to_cells"):
        if k in t:
            s = c.string(t[k], f"{key}.{k}")
            if s not in cell_sets:
                raise c.fail(f"{key}.{k}", f"unknown cell set {s!r} (declare it under [cells])")
    if "consumes" in t:
        s = c.string(t["consumes"], f"{key}.consumes")
        if s not in consumables:
            raise c.fail(f"{key}.consumes", f"unknown consumable {s!r}")
    cargo_at: frozenset[Cell] | str | None = None
    if "cargo_at" in t:
        if cargo is None:
            raise c.fail(f"{key}.cargo_at", "needs a [cargo] table")
        raw = t["cargo_at"]
        if isinstance(raw, str):
            if raw not in cell_sets:
                raise c.fail(f"{key}.cargo_at",
                             f"unknown cell set {raw!r} (declare it under [cells])")
            cargo_at = raw
        else:
            cells = c.cells(raw, f"{key}.cargo_at", width, height, walls)
            if not cells:
                raise c.fail(f"{key}.cargo_at", "must list at least one cell")
            cargo_at = frozenset(cells)
    negated: tuple[Condition, ...] = ()
    if "not" in t:
        negated = (_condition(c, t["not"], f"{key}.not", cell_sets, consumables, actions,
                              cargo, width, height, walls),)
    return Condition(
        actions=acts,
        moved=c.boolean(t["moved"], f"{key}.moved") if "moved" in t else None,
        carrying=c.boolean(t["carrying"], f"{key}.carrying") if "carrying" in t else None,
        from_cells=t.get("from_cells"),
        leaves_cells=t.get("leaves_cells"),
        consumes=t.get("consumes"),
        to_cells=t.get("to_cells"),
        cargo_at=cargo_at,
        negated=negated,
    )


def _constraints(c: _Checker, value: Any, key: str, n: int) -> tuple[tuple[int, ...], ...]:
    rows = c.array(value, key)
    out = []
    for i, r in enumerate(rows):
        r = c.array(r, f"{key}[{i}]")
        if len(r) != n:
            raise c.fail(f"{key}[{i}]", f"has {len(r)} entries, the domain has {n} features")
        out.append(tuple(c.integer(v, f"{key}[{i}][{j}]") for j, v in enumerate(r)))
    return tuple(out)
