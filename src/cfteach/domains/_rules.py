"""Parsing a domain file's actions (`domain.actions`) and feature conditions (`when`, `any`,
`not`): the two parts of the format whose entries reference each other (a condition names
actions, an action's effect decides which groups it joins)."""

from __future__ import annotations

import re
from typing import Any

from cfteach.domains._checker import Checker
from cfteach.domains.records import (
    ACTION_EFFECTS,
    ACTIONS,
    BUILTIN_ACTIONS,
    INTERACT,
    ActionSpec,
    CargoSpec,
    Cell,
    Condition,
)

_COND_KEYS = {"action", "moved", "carrying", "from_cells", "leaves_cells", "to_cells", "consumes",
              "cargo_at", "not"}
_ACTION_KEYS = {"name", "label", "key", "effect", "delta"}
_KEY_RE = re.compile(r".|[A-Z][A-Za-z0-9]+", re.S)  # a character, or a named key ("ArrowUp")
#: Words an `action` condition accepts besides action names, so no action may be named so.
_ACTION_GROUPS = ("move", "interact")


def parse_actions(c: Checker, value: Any, key: str) -> tuple[ActionSpec, ...]:
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


def _action_table(c: Checker, item: Any, key: str) -> ActionSpec:
    """One declared action. A built-in name may be given as a table to relabel or rebind it
    (its effect and delta then default to the built-in's)."""
    t = c.table(item, key, _ACTION_KEYS, {"name"})
    name = c.string(t["name"], f"{key}.name")
    if name in _ACTION_GROUPS:
        raise c.fail(f"{key}.name", f"{name!r} is reserved (a condition's `action = {name!r}` "
                                    "means a group of actions)")
    base = BUILTIN_ACTIONS.get(name)
    if "effect" in t:
        effect = c.string(t["effect"], f"{key}.effect")
    elif base is not None:
        effect = base.effect
    else:
        raise c.fail(f"{key}.effect", "missing required key (one of "
                                      f"{', '.join(ACTION_EFFECTS)})")
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


def parse_condition(c: Checker, value: Any, key: str, cell_sets: dict[str, Any],
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
        negated = (parse_condition(c, t["not"], f"{key}.not", cell_sets, consumables, actions,
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
