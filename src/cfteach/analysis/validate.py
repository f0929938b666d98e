"""Checks across rows of a parsed export: what a column-by-column parse cannot see.

Each check raises `ExportError` naming the file, the column and the first few offending
rows, because every one of these problems silently changed a statistic before: a duplicated
row reweights a participant (or, through the completeness rule, excludes everybody else), an
`optimal` flag that disagrees with the rewards scores a wrong answer as right, a test filed
under the wrong domain corrupts the per-domain means.
"""

from __future__ import annotations

import pandas as pd

from cfteach.analysis.errors import ExportError
from cfteach.mdp.scoring import optimal_mask

#: file -> the columns that identify one row (a second row with the same key is a duplicate).
ROW_KEYS = {
    "test_responses.csv": ("participant_id", "domain", "test_id"),
    "likert.csv": ("participant_id", "domain", "item"),
    "demo_views.csv": ("participant_id", "domain", "demo_index"),
}
SHOW = 3  # offending rows listed in a message


def _lines(index: pd.Index) -> str:
    """CSV line numbers (header is line 1) of the first few rows of `index`."""
    lines = [str(int(i) + 2) for i in index[:SHOW]]
    more = f" and {len(index) - SHOW} more" if len(index) > SHOW else ""
    return ", ".join(lines) + more


def check_no_rows(df: pd.DataFrame, fname: str) -> None:
    """A header-only file cannot be analysed; say so instead of 'nobody is left'."""
    if df.empty:
        raise ExportError(f"{fname} has a header but no rows")


def check_duplicates(df: pd.DataFrame, fname: str) -> None:
    """The same participant x domain x test (or item, or demonstration) twice is an error."""
    key = list(ROW_KEYS[fname])
    dup = df[df.duplicated(key, keep="first")]
    if dup.empty:
        return
    shown = "; ".join(" / ".join(str(r[c]) for c in key) for _, r in dup.head(SHOW).iterrows())
    raise ExportError(
        f"{fname}: {len(dup)} duplicated row(s) of ({', '.join(key)}) at line(s) "
        f"{_lines(dup.index)}: {shown}"
    )


def check_optimal(tests: pd.DataFrame) -> None:
    """`optimal` must be what the study's rule gives for the two rewards (cfteach.mdp.scoring)."""
    expected = optimal_mask(
        tests["reward"].to_numpy(float), tests["optimal_reward"].to_numpy(float)
    )
    bad = tests.index[expected != tests["optimal"].astype(bool).to_numpy()]
    if len(bad):
        r = tests.loc[bad[0]]
        raise ExportError(
            f"test_responses.csv: column 'optimal' disagrees with reward vs optimal_reward "
            f"(within 1e-9) at line(s) {_lines(bad)}: e.g. optimal = {int(r['optimal'])} "
            f"with reward {r['reward']!r} and optimal_reward {r['optimal_reward']!r}"
        )


def check_test_items(tests: pd.DataFrame) -> None:
    """Every test_id belongs to one domain and one difficulty across the whole export."""
    for col in ("domain", "difficulty"):
        n = tests.groupby("test_id")[col].nunique()
        bad = n[n > 1]
        if len(bad):
            tid = bad.index[0]
            seen = tests.loc[tests["test_id"] == tid, col]
            first = seen.iloc[0]
            odd = seen.index[seen != first]
            raise ExportError(
                f"test_responses.csv: column '{col}': test {tid!r} is listed under "
                f"{', '.join(repr(v) for v in sorted(seen.unique()))} (line(s) {_lines(odd)} "
                f"differ from the first, {first!r})"
            )


def check_domains_in_order(participants: pd.DataFrame, df: pd.DataFrame, fname: str) -> None:
    """A row's domain must be one of its participant's `domain_order` (when that is given)."""
    order = participants.set_index("participant_id")["domain_order"].dropna()
    if order.empty:
        return
    allowed = order.str.split(";").map(set)
    have = df["participant_id"].map(allowed)
    known = have.notna()
    ok = pd.Series(
        [d in a for d, a in zip(df.loc[known, "domain"], have[known], strict=True)],
        index=df.index[known],
        dtype=bool,
    )
    bad = ok.index[~ok]
    if len(bad):
        r = df.loc[bad[0]]
        raise ExportError(
            f"{fname}: column 'domain' is {r['domain']!r} for participant "
            f"{r['participant_id']!r}, whose domain_order is {order[r['participant_id']]!r} "
            f"(line(s) {_lines(bad)})"
        )


def check_timestamps(participants: pd.DataFrame) -> None:
    """started_at / completed_at must be ISO 8601 when present (durations are computed)."""
    for col in ("started_at", "completed_at"):
        raw = participants[col]
        parsed = pd.to_datetime(raw, utc=True, errors="coerce", format="ISO8601")
        bad = raw.index[raw.notna() & parsed.isna()]
        if len(bad):
            raise ExportError(
                f"participants.csv: column '{col}' has a malformed timestamp "
                f"{raw[bad[0]]!r} at line(s) {_lines(bad)} (expected ISO 8601)"
            )
    start = pd.to_datetime(participants["started_at"], utc=True, format="ISO8601")
    end = pd.to_datetime(participants["completed_at"], utc=True, format="ISO8601")
    bad = participants.index[(end < start).fillna(False).astype(bool)]
    if len(bad):
        raise ExportError(
            f"participants.csv: column 'completed_at' is before 'started_at' at line(s) "
            f"{_lines(bad)}"
        )


def one_session_per_participant(participants: pd.DataFrame,
                                keep_sessions: list[str] | None = None) -> list[str]:
    """The sessions to analyse: all, unless a Prolific participant has several, which is
    refused (a participant counted twice) unless `keep_sessions` names the one to keep of
    each (the others are dropped). Previews (no prolific_pid) are not checked."""
    keep = list(keep_sessions or [])
    ids = set(participants["participant_id"].astype(str))
    unknown = [k for k in keep if k not in ids]
    if unknown:
        raise ExportError(f"--keep-session {unknown[0]!r} is not in participants.csv")
    pid = participants["prolific_pid"].fillna("").astype(str)
    sessions = participants.assign(_pid=pid)[pid != ""].groupby("_pid")["participant_id"]
    drop: list[str] = []
    for who, group in sessions:
        if len(group) < 2:
            continue
        chosen = [g for g in group if g in keep]
        if len(chosen) != 1:
            raise ExportError(
                f"participants.csv: prolific_pid {who!r} has {len(group)} sessions "
                f"({', '.join(map(str, group))}); name the one to analyse with "
                "--keep-session PARTICIPANT_ID"
            )
        drop += [g for g in group if g != chosen[0]]
    return [i for i in participants["participant_id"] if i not in set(drop)]
