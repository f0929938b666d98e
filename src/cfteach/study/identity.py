"""Who a Prolific participant is, for one study: the study's own key (written once, at
`cfteach study init`) plus the PROLIFIC_PID. The STUDY_ID a link carries plays no part, so
a participant cannot start again with another (or no) STUDY_ID."""

from __future__ import annotations

import json
import secrets
from pathlib import Path

from sqlalchemy import and_, case, or_, select
from sqlalchemy.orm import Session as DBSession

from .models import Session

#: The key of study files written before studies had one (each database serves one study).
LEGACY_KEY = "legacy"


def new_study_key(out: str | Path) -> str:
    """The key of the study being written to `out`: kept from a study file already there
    (re-running `study init` in the same folder is the same study), else a new random one."""
    old = Path(out) / "study.json"
    try:
        key = json.loads(old.read_text()).get("study_key")
    except (OSError, ValueError, AttributeError):
        key = None
    return key if isinstance(key, str) and key else secrets.token_hex(8)


def study_key(study: dict) -> str:
    return str(study.get("study_key") or LEGACY_KEY)


def participant_key(key: str, pid: str) -> str:
    """`sessions.pid_key`: '@' cannot occur in a key or a PID, so it tells these keys from
    the older ``STUDY_ID:PID`` ones."""
    return f"{key}@{pid}"


def find_participant(db: DBSession, pid_key: str, pid: str) -> Session | None:
    """The participant's session: by key, or one stored under an older ``STUDY_ID:PID`` key
    (an unfinished one first, then the newest)."""
    return db.scalar(select(Session).where(or_(
        Session.pid_key == pid_key,
        and_(Session.prolific_pid == pid, Session.is_preview.is_(False),
             Session.pid_key.is_not(None), Session.pid_key.not_like("%@%"))))
        .order_by(case((Session.pid_key == pid_key, 0), else_=1),
                  case((Session.status == "in_progress", 0), else_=1), Session.id.desc())
        .limit(1))
