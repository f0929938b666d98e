"""Study versions kept in the database: every `study.json` the server has run, by version.

A participant keeps the version they started on until they finish, so changing the study
file (new title, new codes, new curricula) never strands anyone mid-study.
"""

from __future__ import annotations

import json

from sqlalchemy import Engine, func, select
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session as DBSession

from .models import Session, StudyVersion, utcnow


def store_version(engine: Engine, study: dict) -> None:
    """Keep `study` in the database under its version (once; later calls change nothing)."""
    try:
        with DBSession(engine) as db, db.begin():
            if db.get(StudyVersion, study["version"]) is None:
                db.add(StudyVersion(version=study["version"],
                                    title=str(study.get("title", ""))[:200],
                                    content=json.dumps(study, separators=(",", ":")),
                                    created_at=utcnow()))
    except IntegrityError:
        pass  # another server process stored the same version at the same moment


def load_version(db: DBSession, version: str) -> dict | None:
    """The stored study of `version`, or None if this database never ran it."""
    row = db.get(StudyVersion, version)
    return None if row is None else json.loads(row.content)


def unstored_in_progress(engine: Engine, current: str) -> dict[str, int]:
    """In-progress sessions per study version that is neither `current` nor stored (a
    database from before versions were kept): they cannot be served any more."""
    with DBSession(engine) as db:
        stored = select(StudyVersion.version)
        rows = db.execute(
            select(Session.study_version, func.count())
            .where(Session.status == "in_progress", Session.study_version != current,
                   Session.study_version.not_in(stored))
            .group_by(Session.study_version)).all()
    return {v: n for v, n in rows}
