"""Small helpers shared by the command modules (no heavy imports)."""

from __future__ import annotations


def split_list(values: list[str] | None) -> list[str] | None:
    """A list option given as repeated options, comma-separated lists, or both (None when
    the option was not given)."""
    if not values:
        return None
    return [v.strip() for item in values for v in item.split(",") if v.strip()]
