"""Balanced assignment over condition x domain order x test set, filled hierarchically.

psiTurk's counting rule: completed sessions plus sessions active within the cutoff, per
cell, for this study version, ignoring previews. The cell is chosen level by level: the
least-filled condition first (so conditions stay within one participant of each other from
the first arrival on), then its least-filled domain order, then that order's least-filled
test set; ties go to the order and test set least used over all conditions, then uniformly
at random. With no session freed, every cell holds k participants after 72k arrivals, as
with a flat least-filled-cell rule. Callers hold the database write lock while calling
`choose_cell`.
"""

from __future__ import annotations

import itertools
import random
from collections import Counter
from datetime import datetime, timedelta

from sqlalchemy import ColumnElement, func, or_, select
from sqlalchemy.orm import Session as DBSession

from .models import Session

Cell = tuple[str, tuple[str, ...], int]


def all_cells(study: dict) -> list[Cell]:
    return [(c, tuple(order), t) for c in study["conditions"]
            for order in itertools.permutations(study["domains"])
            for t in range(study["test_sets"])]


def cell_counts(db: DBSession, study: dict, now: datetime) -> dict[Cell, int]:
    """Sessions that occupy each cell now: completed, or in progress and recently active."""
    cutoff = now - timedelta(minutes=float(study["cutoff_minutes"]))
    return _count_by_cell(db, study, or_(
        Session.status == "completed",
        (Session.status == "in_progress") & (Session.last_active_at >= cutoff)))


def completed_counts(db: DBSession, study: dict) -> dict[Cell, int]:
    """Completed sessions per cell."""
    return _count_by_cell(db, study, Session.status == "completed")


def _count_by_cell(db: DBSession, study: dict, which: ColumnElement[bool]) -> dict[Cell, int]:
    """Sessions of this study version matching `which` per cell, previews left out."""
    rows = db.execute(
        select(Session.condition, Session.domain_order, Session.test_set, func.count())
        .where(Session.study_version == study["version"], Session.is_preview.is_(False))
        .where(which)
        .group_by(Session.condition, Session.domain_order, Session.test_set)
    ).all()
    counts = dict.fromkeys(all_cells(study), 0)
    for cond, order, ts, n in rows:
        key = (cond, tuple(order.split(";")), ts)
        if key in counts:
            counts[key] += n
    return counts


def choose_cell(db: DBSession, study: dict, now: datetime, rng: random.Random) -> Cell:
    """The cell for the next participant (see the module docstring)."""
    return pick_cell(cell_counts(db, study, now), rng)


def pick_cell(counts: dict[Cell, int], rng: random.Random) -> Cell:
    """Hierarchical least-filled choice from per-cell occupancy `counts`."""
    by_cond: Counter = Counter()
    by_cond_order: Counter = Counter()
    by_order: Counter = Counter()
    by_set: Counter = Counter()
    for (c, o, t), n in counts.items():
        by_cond[c] += n
        by_cond_order[c, o] += n
        by_order[o] += n
        by_set[t] += n

    def key(cell: Cell) -> tuple[int, ...]:
        c, o, t = cell
        return (by_cond[c], by_cond_order[c, o], by_order[o], counts[cell], by_set[t])

    best = min(key(cell) for cell in counts)
    return rng.choice([cell for cell in counts if key(cell) == best])
