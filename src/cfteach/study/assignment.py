"""Balanced assignment: condition x domain order x test set, least-filled cell first.

psiTurk's rule (study-platform.md §1.4): count completed sessions plus sessions active within
the cutoff, per cell, for this study version, ignoring previews, and pick uniformly among the
least-filled cells. Callers hold the database write lock while calling `choose_cell`.
"""

from __future__ import annotations

import itertools
import random
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
    counts = cell_counts(db, study, now)
    least = min(counts.values())
    return rng.choice([c for c, n in counts.items() if n == least])
