"""The live closed-loop condition against the others, from a study export.

The paper's statistics (2 x 2 between-subjects factors) are about its four conditions, so
`paper_only` hands them an export without the ``closed_loop`` participants; `compare`
then sets closed-loop beside every condition on what the closed-loop literature reports:
regret and proportion optimal on the same post-teaching tests, by difficulty (mean over
participants, t-based 95% CI), items shown per domain, and time on task.

Only completed, non-preview sessions are compared (the paper's exclusion rules are about
its own conditions and are not applied here).
"""

from __future__ import annotations

import html
import math
import shutil
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pandas as pd

CLOSED_LOOP = "closed_loop"
ITEMS = "closed_loop_items.csv"
#: Files that carry a `condition` column (filtered by `paper_only`).
CONDITION_FILES = ("participants.csv", "test_responses.csv", "likert.csv", "demo_views.csv")
DIFFICULTIES = ("low", "medium", "high")
SECTION = "Closed-loop teaching"


def _read(path: Path) -> pd.DataFrame:
    return pd.read_csv(path, dtype={"participant_id": str}, keep_default_na=False,
                       na_values=[""])


def has_closed_loop(export_dir: str | Path) -> bool:
    """Whether the export has closed-loop participants."""
    p = Path(export_dir) / "participants.csv"
    return p.is_file() and bool((_read(p)["condition"] == CLOSED_LOOP).any())


def sessions(export_dir: str | Path) -> dict[str, int]:
    """Every session participants.csv holds, by condition (closed_loop included)."""
    p = Path(export_dir) / "participants.csv"
    if not p.is_file():
        return {}
    counts = _read(p)["condition"].astype(str).value_counts()
    return {str(c): int(n) for c, n in counts.items()}


@contextmanager
def paper_only(export_dir: str | Path) -> Iterator[Path]:
    """The export as the paper's analysis reads it: without closed_loop participants (a
    temporary filtered copy when there are any; the folder itself otherwise)."""
    src = Path(export_dir)
    if not has_closed_loop(src):
        yield src
        return
    tmp = Path(tempfile.mkdtemp(prefix="cfteach-paper-"))
    try:
        for name in CONDITION_FILES:
            if (src / name).is_file():
                df = _read(src / name)
                df[df["condition"] != CLOSED_LOOP].to_csv(tmp / name, index=False)
        yield tmp
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def _ci(values: pd.Series) -> dict[str, float | int | None]:
    """Mean with a t-based 95% CI (None where undefined)."""
    from scipy import stats

    v = values.dropna().astype(float)
    n = int(len(v))
    if not n:
        return {"mean": None, "ci_low": None, "ci_high": None, "n": 0}
    mean = float(v.mean())
    if n < 2:
        return {"mean": mean, "ci_low": None, "ci_high": None, "n": n}
    half = float(stats.t.ppf(0.975, n - 1) * v.std(ddof=1) / math.sqrt(n))
    return {"mean": mean, "ci_low": mean - half, "ci_high": mean + half, "n": n}


def compare(export_dir: str | Path) -> dict[str, Any] | None:
    """Closed-loop against every condition of the export (None without closed_loop
    participants). JSON-ready."""
    d = Path(export_dir)
    if not has_closed_loop(d):
        return None
    parts = _read(d / "participants.csv")
    parts = parts[(parts["status"] == "completed") & (parts["is_preview"].astype(int) == 0)]
    cond_of = parts.set_index("participant_id")["condition"]
    conditions = [c for c in dict.fromkeys(parts["condition"])]
    tests = _read(d / "test_responses.csv")
    tests = tests[tests["participant_id"].isin(cond_of.index)].copy()
    tests["regret"] = (tests["optimal_reward"] - tests["reward"]).clip(lower=0.0)
    by_difficulty = []
    for cond in conditions:
        for level in (*DIFFICULTIES, "all"):
            t = tests[tests["condition"] == cond]
            if level != "all":
                t = t[t["difficulty"] == level]
            per = t.groupby("participant_id")[["regret", "optimal"]].mean()
            by_difficulty.append({"condition": cond, "difficulty": level,
                                  "regret": _ci(per["regret"]),
                                  "proportion_optimal": _ci(per["optimal"])})
    items = _read(d / ITEMS) if (d / ITEMS).is_file() else pd.DataFrame(
        columns=["participant_id", "domain", "kind", "time_ms"])
    items = items[items["participant_id"].isin(cond_of.index)]
    views = _read(d / "demo_views.csv")
    views = views[views["participant_id"].isin(cond_of.index)]
    shown = []
    for cond in conditions:
        if cond == CLOSED_LOOP:
            per = items.groupby(["participant_id", "domain"])
            counts = per["kind"].value_counts().unstack(fill_value=0)
            total = counts.sum(axis=1)
            teach_ms = per["time_ms"].sum()
            kinds = {k: float(counts[k].mean()) if k in counts else 0.0
                     for k in ("demonstration", "test", "feedback")}
        else:
            v = views[views["condition"] == cond]
            per = v.groupby(["participant_id", "domain"])
            total = per["demo_index"].nunique()
            teach_ms = per["watch_ms"].sum()
            kinds = {"demonstration": float(total.mean()) if len(total) else 0.0,
                     "test": 0.0, "feedback": 0.0}
        shown.append({"condition": cond, "items_per_domain": _ci(total),
                      "max_items": int(total.max()) if len(total) else 0, **kinds,
                      "teaching_minutes_per_domain": _ci(teach_ms / 60000.0)})
    started = pd.to_datetime(parts["started_at"], utc=True)
    ended = pd.to_datetime(parts["completed_at"], utc=True)
    minutes = (ended - started).dt.total_seconds() / 60.0
    time_on_task = []
    for cond in conditions:
        sel = parts["condition"] == cond
        t = tests[tests["condition"] == cond]
        time_on_task.append({"condition": cond, "session_minutes": _ci(minutes[sel]),
                             "test_seconds": _ci(t.groupby("participant_id")["time_ms"]
                                                 .mean() / 1000.0)})
    return {"participants": {c: int((parts["condition"] == c).sum()) for c in conditions},
            "by_difficulty": by_difficulty, "items_shown": shown,
            "time_on_task": time_on_task}


def _fmt(x: dict[str, Any], digits: int = 3) -> str:
    if x["mean"] is None:
        return "-"
    if x["ci_low"] is None:
        return f"{x['mean']:.{digits}f}"
    return f"{x['mean']:.{digits}f} [{x['ci_low']:.{digits}f}, {x['ci_high']:.{digits}f}]"


def tables(summary: dict[str, Any]) -> list[tuple[str, list[str], list[list[str]]]]:
    """The comparison as (caption, header, rows) tables."""
    by = summary["by_difficulty"]
    out = [("Regret (optimal reward minus the answer's) and proportion optimal on the "
            "post-teaching tests, mean over participants [95% CI]",
            ["condition", "difficulty", "n", "regret", "proportion optimal"],
            [[r["condition"], r["difficulty"], str(r["regret"]["n"]), _fmt(r["regret"]),
              _fmt(r["proportion_optimal"])] for r in by])]
    out.append(("Items shown per domain (open-loop: demonstrations; closed-loop: "
                "demonstrations + diagnostic tests + feedback) and teaching time per domain "
                "(open-loop: demonstration play time; closed-loop: time on its items)",
                ["condition", "items [95% CI]", "max", "demos / tests / feedback",
                 "teaching minutes"],
                [[r["condition"], _fmt(r["items_per_domain"], 1), str(r["max_items"]),
                  f"{r['demonstration']:.1f} / {r['test']:.1f} / {r['feedback']:.1f}",
                  _fmt(r["teaching_minutes_per_domain"], 2)]
                 for r in summary["items_shown"]]))
    out.append(("Time on task: whole session (start to completion) and mean time per "
                "post-teaching test",
                ["condition", "session minutes", "seconds per test"],
                [[r["condition"], _fmt(r["session_minutes"], 1), _fmt(r["test_seconds"], 1)]
                 for r in summary["time_on_task"]]))
    return out


def markdown(summary: dict[str, Any]) -> str:
    parts = ", ".join(f"{c}: {n}" for c, n in summary["participants"].items())
    lines = [f"## {SECTION}", "", f"Completed participants compared: {parts}. The paper's "
             "statistics above leave the closed_loop participants out.", ""]
    for caption, header, rows in tables(summary):
        lines += [caption + ":", "", "| " + " | ".join(header) + " |",
                  "|" + "---|" * len(header)]
        lines += ["| " + " | ".join(r) + " |" for r in rows]
        lines.append("")
    return "\n".join(lines)


def add_to_report(summary: dict[str, Any] | None, out_dir: str | Path) -> None:
    """Append the comparison to report.md and report.html in `out_dir` (if any)."""
    if summary is None:
        return
    out = Path(out_dir)
    md = out / "report.md"
    if md.is_file():
        md.write_text(md.read_text(encoding="utf-8").rstrip("\n") + "\n\n" + markdown(summary),
                      encoding="utf-8")
    page = out / "report.html"
    if page.is_file():
        body = [f"<h2>{SECTION}</h2>"]
        for caption, header, rows in tables(summary):
            body.append(f"<p>{html.escape(caption)}:</p><table><thead><tr>"
                        + "".join(f"<th>{html.escape(h)}</th>" for h in header)
                        + "</tr></thead><tbody>"
                        + "".join("<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in r)
                                  + "</tr>" for r in rows) + "</tbody></table>")
        text = page.read_text(encoding="utf-8")
        cut = text.rfind("</body>")
        cut = len(text) if cut < 0 else cut
        page.write_text(text[:cut] + "\n".join(body) + text[cut:], encoding="utf-8")
