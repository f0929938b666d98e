"""The study's visual language as a small table keyed by the names the built-in domains use.

Why a table: renderers must work for user domain files too, so nothing is hard-coded per
domain. A name found here (or one of its aliases) gets the study's look (spec
study-platform.md §1.5); any other name gets a generic style from a fixed palette, chosen
deterministically from the name's position so the same file always looks the same.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

CellShape = Literal["fill", "square", "ring", "dots"]
ObjectShape = Literal["circle", "rect", "hexagon", "diamond"]

AGENT_COLOR = "#628dbe"
TRAIL_COLOR = "#677387"
EXIT_COLOR = "#c0392b"  # the frame of an `exit` action
STAY_COLOR = "#8e44ad"  # the ring of a `stay` action
GRID_COLOR = "#000000"
BACKGROUND = "#ffffff"
WALL_COLOR = "#2E3131"
GOAL_COLOR = "#A9A9A9"


@dataclass(frozen=True)
class CellStyle:
    """How a static cell set is drawn: a shape within the cell, a colour, and a text char."""

    shape: CellShape
    color: str
    char: str
    label: str


@dataclass(frozen=True)
class ObjectStyle:
    """How a movable or consumable object is drawn."""

    shape: ObjectShape
    color: str
    char: str
    label: str


# Static cell sets of the built-in domains (names as in their TOML files), with aliases.
CELL_STYLES: dict[str, CellStyle] = {
    "walls": CellStyle("fill", WALL_COLOR, "#", "wall"),
    "mud": CellStyle("fill", "#E0E644", "~", "mud"),
    "A": CellStyle("square", "#C88B66", "a", "A tile"),
    "B": CellStyle("ring", "#588B66", "b", "B tile"),
    "path": CellStyle("fill", "#DCBBFC", "=", "path"),
}
CELL_ALIASES: dict[str, str] = {
    "wall": "walls",
    "toll": "mud",
    "tolls": "mud",
    "a": "A",
    "a_tiles": "A",
    "b": "B",
    "b_tiles": "B",
    "paths": "path",
}

# Objects: cargo (moves with the agent when held) and consumables.
OBJECT_STYLES: dict[str, ObjectStyle] = {
    "passenger": ObjectStyle("circle", "#B395C4", "p", "package"),
    "skateboard": ObjectStyle("rect", "#C88B66", "s", "skateboard"),
    "station": ObjectStyle("hexagon", "#58895F", "h", "battery station"),
}
OBJECT_ALIASES: dict[str, str] = {
    "package": "passenger",
    "battery": "station",
    "hotswap": "station",
    "hotswap_station": "station",
}

# Where a cargo has to be delivered (delivery's destination): a small square in its colour.
DESTINATION_CHAR = "d"
GOAL_CHAR = "G"
AGENT_CHAR = "@"
AGENT_CARRYING_CHAR = "&"
TRAIL_CHAR = "."
EMPTY_CHAR = " "

# Generic fallbacks for user domains (light, distinguishable colours).
PALETTE = (
    "#8DD3C7",
    "#FDB462",
    "#BEBADA",
    "#FB8072",
    "#80B1D3",
    "#B3DE69",
    "#FCCDE5",
    "#BC80BD",
    "#CCEBC5",
    "#FFED6F",
)
_GENERIC_CELL_CHARS = "xyzuvwkqrt"
_GENERIC_CARGO_CHARS = "ojqk"
_GENERIC_CONSUMABLE_CHARS = "cegiln"


def cell_style(name: str, position: int = 0) -> CellStyle:
    """The style of the static cell set `name`; `position` picks a generic style for new names."""
    key = name if name in CELL_STYLES else CELL_ALIASES.get(name, CELL_ALIASES.get(name.lower()))
    if key is not None:
        return CELL_STYLES[key]
    color = PALETTE[position % len(PALETTE)]
    char = _GENERIC_CELL_CHARS[position % len(_GENERIC_CELL_CHARS)]
    return CellStyle("fill", color, char, name)


def object_style(name: str, kind: str, position: int = 0) -> ObjectStyle:
    """The style of object `name` (`kind` is "cargo" or "consumable") with a generic fallback."""
    key = name if name in OBJECT_STYLES else OBJECT_ALIASES.get(name.lower())
    if key is not None:
        return OBJECT_STYLES[key]
    if kind == "cargo":
        color = PALETTE[(position + 5) % len(PALETTE)]
        char = _GENERIC_CARGO_CHARS[position % len(_GENERIC_CARGO_CHARS)]
        shape: ObjectShape = "circle"
    else:
        color = PALETTE[(position + 7) % len(PALETTE)]
        char = _GENERIC_CONSUMABLE_CHARS[position % len(_GENERIC_CONSUMABLE_CHARS)]
        shape = "hexagon"
    return ObjectStyle(shape, color, char, name)
