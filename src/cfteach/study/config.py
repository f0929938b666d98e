"""Loading a study folder (`study.json`, written by `cfteach study init`)."""

from __future__ import annotations

import json
from functools import lru_cache
from pathlib import Path

from .build import STUDY_SCHEMA


class StudyError(ValueError):
    """The study folder is missing or malformed."""


def load_study(path: str | Path) -> dict:
    """Read and sanity-check a study folder (or its `study.json`)."""
    p = Path(path)
    if p.is_dir():
        p = p / "study.json"
    if not p.exists():
        raise StudyError(f"no study at {p}: create one with `cfteach study init`")
    return _load(str(p.resolve()), p.stat().st_mtime_ns)


@lru_cache(maxsize=4)
def _load(path: str, _mtime: int) -> dict:
    try:
        study = json.loads(Path(path).read_text())
    except json.JSONDecodeError as e:
        raise StudyError(f"{path} is not valid JSON: {e}") from e
    if study.get("schema") != STUDY_SCHEMA:
        raise StudyError(f"{path}: expected schema {STUDY_SCHEMA!r}, got {study.get('schema')!r}")
    for key in ("version", "conditions", "domains", "test_sets", "curricula", "tests",
                "practice", "completion"):
        if key not in study:
            raise StudyError(f"{path}: missing key {key!r}")
    return study
