"""Load and validate a study export (the tidy CSVs written by `cfteach study export`).

Every file is read by column name (extra columns and extra files are ignored); a missing
file, a missing column or a value outside its allowed set raises `ExportError` naming the
file and the column, and the checks across rows in `validate` (duplicates, the `optimal`
rule, test items, domains, timestamps) run before any statistic is computed.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from cfteach.analysis.errors import ExportError

CONDITIONS = ("baseline", "feature_only", "counterfactual_only", "proposed")
DIFFICULTIES = ("low", "medium", "high")
STATUSES = ("completed", "screened_out", "declined", "abandoned", "in_progress")
LIKERT_ITEMS = ("informativeness", "mental_effort")
CF_CONDITIONS = frozenset({"counterfactual_only", "proposed"})
FS_CONDITIONS = frozenset({"feature_only", "proposed"})
#: The study's design: every domain shows this many tests of each difficulty (3 x 2 = 6),
#: so a complete participant has len(domain_order) x 6 test responses.
TESTS_PER_DOMAIN_DIFFICULTY = 2

# column -> (kind, required non-empty). kinds: str, int, float, bool, or a tuple of allowed str.
SCHEMA: dict[str, dict[str, tuple[object, bool]]] = {
    "participants.csv": {
        "participant_id": ("str", True),
        "prolific_pid": ("str", False),
        "study_id": ("str", False),
        "session_id": ("str", False),
        "condition": (CONDITIONS, True),
        "counterfactual": ("bool", True),
        "feature_scaffolding": ("bool", True),
        "domain_order": ("str", False),
        "test_set": ("int", False),
        "status": (STATUSES, True),
        "is_preview": ("bool", True),
        "started_at": ("str", False),
        "completed_at": ("str", False),
        "practice_attempts": ("int", False),
        "age": ("int", False),
        "gender": ("str", False),
        "education": ("str", False),
        "study_version": ("str", False),
    },
    "test_responses.csv": {
        "participant_id": ("str", True),
        "condition": (CONDITIONS, True),
        "domain": ("str", True),
        "domain_position": ("int", False),
        "test_id": ("str", True),
        "difficulty": (DIFFICULTIES, True),
        "overlap": ("float", False),
        "trial_index": ("int", False),
        "actions": ("str", False),
        "n_actions": ("int", False),
        "reward": ("float", True),
        "optimal_reward": ("float", True),
        "optimal": ("bool", True),
        "optimal_length": ("int", False),
        "time_ms": ("int", False),
        "client_time_ms": ("int", False),
        "confidence": ("int", False),
    },
    "likert.csv": {
        "participant_id": ("str", True),
        "condition": (CONDITIONS, True),
        "domain": ("str", True),
        "domain_position": ("int", False),
        "item": (LIKERT_ITEMS, True),
        "value": ("int", True),
    },
    "demo_views.csv": {
        "participant_id": ("str", True),
        "condition": (CONDITIONS, True),
        "domain": ("str", True),
        "demo_index": ("int", True),
        "plays_completed": ("int", False),
        "replays": ("int", False),
        "watch_ms": ("int", False),
        "client_watch_ms": ("int", False),
    },
}

# Ranges checked after parsing: (file, column) -> (low, high), inclusive.
RANGES = {
    ("test_responses.csv", "confidence"): (1, 5),
    ("likert.csv", "value"): (1, 5),
    ("participants.csv", "test_set"): (0, 2),
}


@dataclass(frozen=True)
class StudyExport:
    """The four tables of a study export, parsed and validated (one DataFrame each)."""

    participants: pd.DataFrame
    tests: pd.DataFrame
    likert: pd.DataFrame
    demo_views: pd.DataFrame

    def subset(self, participant_ids: set[str] | list[str]) -> StudyExport:
        """The same export restricted to the given participants (order kept)."""
        keep = set(participant_ids)

        def sel(df: pd.DataFrame) -> pd.DataFrame:
            return df[df["participant_id"].isin(keep)].reset_index(drop=True)

        return StudyExport(
            sel(self.participants), sel(self.tests), sel(self.likert), sel(self.demo_views)
        )


def _parse_column(df: pd.DataFrame, fname: str, col: str, kind: object, required: bool) -> None:
    raw = df[col]
    missing = raw.isna()
    if required and missing.any():
        row = int(missing.to_numpy().nonzero()[0][0]) + 2  # +1 header, +1 one-based
        raise ExportError(f"{fname}: column '{col}' has an empty cell (line {row})")
    if isinstance(kind, tuple):
        bad = raw[~missing & ~raw.isin(kind)]
        if len(bad):
            raise ExportError(
                f"{fname}: column '{col}' has value {bad.iloc[0]!r}; allowed: {', '.join(kind)}"
            )
        return
    if kind == "str":
        return
    num = pd.to_numeric(raw, errors="coerce")
    bad = raw[~missing & num.isna()]
    if len(bad):
        raise ExportError(f"{fname}: column '{col}' has non-numeric value {bad.iloc[0]!r}")
    if kind in ("int", "bool"):
        huge = num[~missing].abs() >= 2**53  # beyond exact floats (and int64 wraps around)
        if huge.any():
            raise ExportError(
                f"{fname}: column '{col}' has an out-of-range integer "
                f"{raw[~missing][huge].iloc[0]!r}"
            )
        frac = num[~missing] % 1 != 0
        if frac.any():
            raise ExportError(
                f"{fname}: column '{col}' must hold integers, got {num[~missing][frac].iloc[0]!r}"
            )
    if kind == "bool":
        if (~num[~missing].isin([0, 1])).any():
            raise ExportError(f"{fname}: column '{col}' must be 0 or 1")
    if kind in ("int", "bool"):
        df[col] = num.astype("Int64") if missing.any() else num.astype("int64")
    else:
        df[col] = num.astype(float)


def read_table(path: Path, fname: str) -> pd.DataFrame:
    """Read one export CSV and check its columns and values against `SCHEMA`."""
    spec = SCHEMA[fname]
    if not path.is_file():
        raise ExportError(f"{fname} not found in export directory {path.parent}")
    str_cols = {c: str for c, (k, _) in spec.items() if k not in ("int", "float", "bool")}
    try:
        df = pd.read_csv(path, dtype=str_cols, keep_default_na=False, na_values=[""])
    except pd.errors.EmptyDataError as exc:
        raise ExportError(f"{fname} is empty (no header row)") from exc
    missing = [c for c in spec if c not in df.columns]
    if missing:
        raise ExportError(f"{fname}: missing column(s) {', '.join(repr(c) for c in missing)}")
    for col, (kind, required) in spec.items():
        _parse_column(df, fname, col, kind, required)
    for (f, col), (lo, hi) in RANGES.items():
        if f == fname:
            vals = df[col].dropna()
            out = vals[(vals < lo) | (vals > hi)]
            if len(out):
                raise ExportError(f"{fname}: column '{col}' value {out.iloc[0]} outside {lo}..{hi}")
    return df


def load_export(export_dir: str | Path, keep_sessions: list[str] | None = None) -> StudyExport:
    """Read and validate the export in `export_dir`; raise `ExportError` on any problem
    (two sessions of one Prolific participant too, unless `keep_sessions` says which)."""
    d = Path(export_dir)
    if not d.is_dir():
        raise ExportError(f"export directory {d} does not exist")
    participants = read_table(d / "participants.csv", "participants.csv")
    tests = read_table(d / "test_responses.csv", "test_responses.csv")
    likert = read_table(d / "likert.csv", "likert.csv")
    demos = read_table(d / "demo_views.csv", "demo_views.csv")
    # imported here: validate pulls in cfteach.mdp, which reading the CSVs does not need
    from cfteach.analysis import validate

    for fname, df in (
        ("participants.csv", participants),
        ("test_responses.csv", tests),
        ("likert.csv", likert),
    ):
        validate.check_no_rows(df, fname)
    dup = participants["participant_id"].duplicated()
    if dup.any():
        raise ExportError(
            "participants.csv: column 'participant_id' repeats "
            f"{participants['participant_id'][dup].iloc[0]!r}"
        )
    for col, members in (("counterfactual", CF_CONDITIONS), ("feature_scaffolding", FS_CONDITIONS)):
        implied = participants["condition"].isin(members).astype(int)
        bad = participants[participants[col].astype(int) != implied]
        if len(bad):
            raise ExportError(
                f"participants.csv: column '{col}' is {int(bad[col].iloc[0])} for "
                f"participant {bad['participant_id'].iloc[0]!r} in condition "
                f"{bad['condition'].iloc[0]!r}"
            )
    known = set(participants["participant_id"])
    for fname, df in (
        ("test_responses.csv", tests),
        ("likert.csv", likert),
        ("demo_views.csv", demos),
    ):
        unknown = set(df["participant_id"]) - known
        if unknown:
            raise ExportError(
                f"{fname}: column 'participant_id' has ids not in participants.csv, "
                f"e.g. {sorted(unknown)[0]!r}"
            )
        cond = df["participant_id"].map(participants.set_index("participant_id")["condition"])
        wrong = df[cond != df["condition"]]
        if len(wrong):
            raise ExportError(
                f"{fname}: column 'condition' is {wrong['condition'].iloc[0]!r} for participant "
                f"{wrong['participant_id'].iloc[0]!r}, but participants.csv says "
                f"{cond[wrong.index[0]]!r}"
            )
        if fname in validate.ROW_KEYS:
            validate.check_duplicates(df, fname)
        validate.check_domains_in_order(participants, df, fname)
    validate.check_timestamps(participants)
    validate.check_test_items(tests)
    validate.check_optimal(tests)
    export = StudyExport(participants, tests, likert, demos)
    kept = validate.one_session_per_participant(participants, keep_sessions)
    return export if len(kept) == len(participants) else export.subset(kept)


def write_export(export: StudyExport, export_dir: str | Path) -> Path:
    """Write an export in the agreed CSV format (plus `data_dictionary.csv`)."""
    d = Path(export_dir)
    d.mkdir(parents=True, exist_ok=True)
    tables = {
        "participants.csv": export.participants,
        "test_responses.csv": export.tests,
        "likert.csv": export.likert,
        "demo_views.csv": export.demo_views,
    }
    for fname, df in tables.items():
        cols = list(SCHEMA[fname])
        out = df[cols].copy()
        for c in cols:
            if out[c].dtype == bool:
                out[c] = out[c].astype(int)
        out.to_csv(d / fname, index=False, lineterminator="\n")
    rows = [
        {"file": f, "column": c, "type": _type_name(k), "description": DESCRIPTIONS.get(c, "")}
        for f, spec in SCHEMA.items()
        for c, (k, _) in spec.items()
    ]
    pd.DataFrame(rows).to_csv(d / "data_dictionary.csv", index=False, lineterminator="\n")
    return d


def _type_name(kind: object) -> str:
    return "category: " + "|".join(kind) if isinstance(kind, tuple) else str(kind)


DESCRIPTIONS = {
    "participant_id": "opaque participant/session identifier",
    "condition": "between-subjects teaching condition",
    "counterfactual": "1 if the condition uses counterfactual scaffolding",
    "feature_scaffolding": "1 if the condition uses feature scaffolding",
    "domain_order": "domains in the order shown, joined by ';'",
    "test_set": "which of the three test sets (0..2) the participant saw",
    "status": "session status",
    "is_preview": "1 for preview/test sessions",
    "difficulty": "test difficulty (Alg. 2)",
    "reward": "reward of the participant's trajectory under the true weights",
    "optimal_reward": "reward of the robot's optimal trajectory",
    "optimal": "1 if reward equals the optimal reward within 1e-9, relative or absolute (M1)",
    "optimal_length": "number of actions of the robot's optimal answer",
    "time_ms": "ms from the test being shown to its submission (server clock)",
    "client_time_ms": "the same time as the browser reported it (not trusted)",
    "study_version": "content hash of the study file the session ran on",
    "confidence": "confidence rating 1..5 (M4)",
    "item": "Likert item (M2 informativeness, M3 mental effort)",
    "value": "Likert rating 1..5",
    "plays_completed": "full plays of this demonstration (timed by the server)",
    "replays": "plays started beyond the first",
    "watch_ms": "total watching time in ms (server clock)",
    "client_watch_ms": "the same total as the browser reported it (not trusted)",
}
