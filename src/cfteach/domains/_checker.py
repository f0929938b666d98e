"""`Checker`: the small typed readers the domain-file parser validates every value with; each
raises `DomainFileError` naming the file, the key path and the problem."""

from __future__ import annotations

import math
from collections.abc import Set
from typing import Any

from cfteach.domains.records import Cell, DomainFileError


class Checker:
    """Small helpers that raise `DomainFileError` with the source attached."""

    def __init__(self, source: str) -> None:
        self.source = source

    def fail(self, key: str, problem: str) -> DomainFileError:
        return DomainFileError(self.source, key, problem)

    def table(self, value: Any, key: str, allowed: Set[str], required: Set[str] = frozenset()
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
