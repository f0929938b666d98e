"""Old option spellings, still accepted: each is rewritten to the grammar of docs/cli.md
before click parses the command line, with a one-line deprecation note on stderr.

Keeping the table here (not as hidden options in every command) leaves each command's
signature in the one grammar, and lets an old spelling be retired by deleting one line.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence

#: command path -> {old option: new option}; a new option of "" makes the value the
#: command's positional argument (the domain of `export minari demos`).
ALIASES: dict[tuple[str, ...], dict[str, str]] = {
    ("reproduce",): {"--domains": "--domain"},
    ("simulate",): {"--domains": "--domain", "--conditions": "--condition",
                    "--learner": "--learner-model", "--seeds": "--replications"},
    ("study", "init"): {"--domains": "--domain", "--conditions": "--condition"},
    ("export", "minari", "demos"): {"--domain": ""},
    ("export", "minari", "answers"): {"--domains": "--domain"},
}


def _note(old: str, new: str, path: tuple[str, ...]) -> None:
    what = "give the domain as the first argument" if not new else f"use {new}"
    print(f"note: `cfteach {' '.join(path)} {old}` is deprecated; {what} (docs/cli.md)",
          file=sys.stderr)


def _command_path(args: Sequence[str]) -> tuple[str, ...]:
    """The longest aliased command path the arguments start with."""
    best: tuple[str, ...] = ()
    for path in ALIASES:
        if tuple(args[: len(path)]) == path and len(path) > len(best):
            best = path
    return best


def rewrite(args: Sequence[str]) -> list[str]:
    """`args` with deprecated spellings replaced by the current ones (a note for each)."""
    args = list(args)
    path = _command_path(args)
    if not path:
        return args
    table = ALIASES[path]
    out = args[: len(path)]
    rest = args[len(path):]
    i = 0
    noted: set[str] = set()
    while i < len(rest):
        token = rest[i]
        if token == "--":
            out += rest[i:]
            break
        name, eq, value = token.partition("=")
        if name in table:
            new = table[name]
            if name not in noted:
                _note(name, new, path)
                noted.add(name)
            if new:
                out.append(f"{new}={value}" if eq else new)
            elif eq:
                out.append(value)
            i += 1
            continue
        out.append(token)
        i += 1
    return out
