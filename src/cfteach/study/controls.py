"""The keyboard controls of a study game: which key plays which action, and what it is called.

One list per domain, built from the domain's `ActionSpec`s and sent in the page data, so the
page binds keys and draws its key legend from the domain instead of a fixed table (a domain
file may declare its own actions, e.g. ``exit`` on ``x``). The practice game keeps the six
built-in actions.
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Sequence
from typing import Any

from cfteach.domains.spec import BUILTIN_ACTIONS

#: What an action name may look like in the study's requests (moves are stored space-joined).
ACTION_NAME_PATTERN = r"^[A-Za-z0-9_-]{1,40}$"
#: Keys the page keeps for itself: `r` resets a game.
RESERVED_KEYS = frozenset({"r", "R"})
#: How the legend names the keys that have no printable face.
KEY_WORDS = {"ArrowUp": "up arrow", "ArrowDown": "down arrow", "ArrowLeft": "left arrow",
             "ArrowRight": "right arrow", " ": "space", "Enter": "enter"}


def key_word(key: str) -> str:
    """How the key legend names a `KeyboardEvent.key` value."""
    return KEY_WORDS.get(key, key)


def action_specs_of(domain: Any) -> tuple[Any, ...]:
    """The domain's `ActionSpec`s; objects without them (the toy domains) get the built-ins."""
    specs = getattr(domain, "action_specs", None)
    if specs:
        return tuple(specs)
    return tuple(BUILTIN_ACTIONS[a] for a in domain.actions)


def controls(specs: Iterable[Any], keys: Sequence[str] | None = None,
             what: str = "domain") -> list[dict]:
    """`[{"action", "key", "key_label", "label", "effect"}]` for the actions in `keys`
    (default: all),
    in action order. ValueError (one line) for a name the study cannot store, a key the page
    keeps for itself, or two actions on one key."""
    out: list[dict] = []
    seen: dict[str, str] = {}
    for spec in specs:
        if keys is not None and spec.name not in keys:
            continue
        if not re.fullmatch(ACTION_NAME_PATTERN.strip("^$"), spec.name):
            raise ValueError(f"{what}: action name {spec.name!r} cannot be used in a study "
                             "(letters, digits, '_' and '-' only, at most 40)")
        if not spec.key or spec.key in RESERVED_KEYS:
            raise ValueError(f"{what}: action {spec.name!r} has key {spec.key!r}, which the "
                             "study keeps for resetting a game (choose another key)")
        folded = spec.key.lower() if len(spec.key) == 1 else spec.key
        if folded in seen:
            raise ValueError(f"{what}: actions {seen[folded]!r} and {spec.name!r} share the key "
                             f"{spec.key!r}")
        seen[folded] = spec.name
        out.append({"action": spec.name, "key": spec.key, "key_label": key_word(spec.key),
                    "label": spec.label, "effect": spec.effect})
    return out


#: The practice game's controls (the six built-in actions).
PRACTICE_CONTROLS = controls(BUILTIN_ACTIONS.values(), what="practice")
