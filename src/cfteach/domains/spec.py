"""Parse and validate a domain description (TOML text or a plain dict) into a `DomainSpec`.

Validation is strict on purpose: a domain file is written by hand, and a typo in a key or a
cell on a wall would otherwise silently produce a different MDP. Every error names the file,
the key path (e.g. ``features[1].when.from_cells``) and the problem.

The records themselves live in `domains/records.py`, the typed readers in
`domains/_checker.py` and the actions / conditions parser in `domains/_rules.py`; this module
re-exports the records, so ``from cfteach.domains.spec import DomainSpec`` keeps working.
"""

from __future__ import annotations

import math
import tomllib
from pathlib import Path
from typing import Any

from cfteach.domains._checker import Checker
from cfteach.domains._rules import parse_actions, parse_condition
from cfteach.domains.records import (
    ACTION_EFFECTS,
    ACTIONS,
    BUILTIN_ACTIONS,
    DEFAULT_MAX_DEMOS,
    INTERACT,
    MOVES,
    ActionSpec,
    CargoSpec,
    Cell,
    Condition,
    DomainFileError,
    DomainSpec,
    FeatureSpec,
    VariantSpec,
)

__all__ = ["ACTIONS", "ACTION_EFFECTS", "BUILTIN_ACTIONS", "DEFAULT_MAX_DEMOS", "INTERACT",
           "MOVES", "ActionSpec", "CargoSpec", "Cell", "Condition", "DomainFileError",
           "DomainSpec", "FeatureSpec", "VariantSpec", "load_toml", "parse_spec"]

_TOP_KEYS = {"domain", "cells", "agent", "cargo", "consumables", "goal", "variants", "features",
             "beliefs", "teaching"}
_DOMAIN_KEYS = {"name", "title", "description", "reference_name", "width", "height", "discount",
                "actions", "walls"}

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
    c = Checker(source)
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
    action_specs = (parse_actions(c, d["actions"], "domain.actions") if "actions" in d
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
            any_of = tuple(parse_condition(c, v, f"{key}.any[{j}]", cell_sets,
                                           consumable_names, action_specs, cargo, width,
                                           height, walls)
                           for j, v in enumerate(alts))
        elif "when" in t:
            any_of = (parse_condition(c, t["when"], f"{key}.when", cell_sets, consumable_names,
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


def _known(c: Checker, value: Any, names: list[str]) -> tuple[str, ...]:
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

def _constraints(c: Checker, value: Any, key: str, n: int) -> tuple[tuple[int, ...], ...]:
    rows = c.array(value, key)
    out = []
    for i, r in enumerate(rows):
        r = c.array(r, f"{key}[{i}]")
        if len(r) != n:
            raise c.fail(f"{key}[{i}]", f"has {len(r)} entries, the domain has {n} features")
        out.append(tuple(c.integer(v, f"{key}[{i}][{j}]") for j, v in enumerate(r)))
    return tuple(out)
