"""`analyze(export_dir, out_dir)`: load, exclude, compute every statistic, plot, report."""

from __future__ import annotations

import json
import sys
import warnings
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from cfteach.analysis.aggregate import Frames, build_frames
from cfteach.analysis.exclusions import ExclusionConfig, apply_exclusions, quality_flags
from cfteach.analysis.io import CONDITIONS, LIKERT_ITEMS, StudyExport, load_export
from cfteach.jsonable import to_jsonable

PADJUST_METHODS = ("holm", "bonf", "sidak", "fdr_bh", "fdr_by", "none")


@dataclass(frozen=True)
class AnalysisConfig:
    """Options of the whole analysis."""

    exclusions: ExclusionConfig = field(default_factory=ExclusionConfig)
    padjust: str = "holm"  # correction of the within-subjects post hocs and pairwise MWUs
    authors_tukey: bool = True  # also report the authors' between-groups Tukey for H1
    keep_sessions: tuple[str, ...] = ()  # the session to keep of a participant with several
    figures: bool = True
    nagq: int = 1  # GLMM: 1 = glmer's Laplace fit; 0 = lme4's faster nAGQ = 0 scheme

    def __post_init__(self) -> None:
        if self.nagq not in (0, 1):
            raise ValueError(f"nagq must be 0 or 1, got {self.nagq!r}")
        if self.padjust not in PADJUST_METHODS:
            raise ValueError(
                f"padjust must be one of {', '.join(PADJUST_METHODS)}, got {self.padjust!r}"
            )


def compute_results(
    export: StudyExport,
    config: AnalysisConfig | None = None,
    export_dir: str = "",
    note: str | None = None,
) -> tuple[dict[str, Any], Frames]:
    """Every statistic of the paper on an export, as one JSON-ready dict (plus the frames)."""
    import pingouin
    import scipy

    from cfteach import __version__
    from cfteach.analysis import stats
    from cfteach.analysis.sensitivity import sensitivity

    cfg = config or AnalysisConfig()
    kept, excluded = apply_exclusions(export, cfg.exclusions)
    if kept.participants.empty:
        raise ValueError(_nobody_left(export, excluded))
    if kept.tests.empty:
        raise ValueError("the retained participants have no test responses; nothing to analyse")
    frames = build_frames(kept)
    with warnings.catch_warnings():
        # pingouin 0.7 calls pandas APIs that pandas 3.1 deprecates; not ours to fix
        warnings.filterwarnings("ignore", module=r"pingouin(\..*)?$")
        results = _all_statistics(frames, cfg, stats)
    by_cond = kept.participants["condition"].value_counts()
    summary: dict[str, Any] = {
        "meta": {
            "export_dir": str(export_dir),
            "note": note,
            "cfteach_version": __version__,
            "pingouin_version": pingouin.__version__,
            "scipy_version": scipy.__version__,
        },
        "config": {
            "exclusions": asdict(cfg.exclusions),
            "padjust": cfg.padjust,
            "authors_tukey": cfg.authors_tukey,
        },
        "participants": {
            "n_sessions": int(len(export.participants)),
            "n_excluded": int(len(excluded)),
            "n_retained": int(len(kept.participants)),
            "retained_by_condition": {c: int(by_cond.get(c, 0)) for c in CONDITIONS},
            "n_test_responses": int(len(kept.tests)),
            "conditions_missing": [c for c in CONDITIONS if not by_cond.get(c, 0)],
        },
        "exclusions": excluded.to_dict(orient="records"),
        "sensitivity": guarded("sensitivity", sensitivity, export, cfg.exclusions),
        "quality_flags": quality_flags(kept.participants).to_dict(orient="records"),
        **results,
    }
    return to_jsonable(summary), frames


def _nobody_left(export: StudyExport, excluded: Any) -> str:
    """Why no participant is left, by rule, so the user knows which rule to look at."""
    by_rule = excluded["rule"].value_counts()
    rules = ", ".join(f"{rule}: {n}" for rule, n in by_rule.items())
    return (
        f"no participant is left after the exclusions (all {len(export.participants)} "
        f"session(s) excluded; {rules or 'no rule'})"
    )


def guarded(step: str, fn: Callable[..., Any], *args: Any, **kwargs: Any) -> Any:
    """Run one analysis step; if it fails, record why instead of losing every other step.

    A pilot with a perfect cell used to abort the whole analysis in the GLMM (no
    results.json, no report); now the failing step becomes {"skipped": "failed: ..."} with
    the error named, a warning is issued, and the report says the step was not computed.
    """
    try:
        return fn(*args, **kwargs)
    except Exception as exc:  # noqa: BLE001 - one model failing never stops the others
        reason = f"failed: {type(exc).__name__}: {' '.join(str(exc).split()) or 'no message'}"
        warnings.warn(f"analysis step {step} {reason}", RuntimeWarning, stacklevel=2)
        return {"skipped": reason}


def _all_statistics(frames: Frames, cfg: AnalysisConfig, stats: Any) -> dict[str, Any]:
    from cfteach.analysis.descriptives import descriptives
    from cfteach.analysis.factorial import full_anova
    from cfteach.analysis.glmm import trial_glmm
    from cfteach.analysis.ordinal import ordinal_models

    full = guarded("full_anova", full_anova, stats.complete_cells(frames.cells))
    return {
        "full_anova": full.get("terms", []),
        "full_anova_participants": full.get("participants", []),
        "full_anova_skipped": full.get("skipped"),
        "full_anova_detail": {k: v for k, v in full.items() if k not in ("terms", "participants")},
        "glmm": guarded("glmm", trial_glmm, frames.tests, nagq=cfg.nagq),
        "descriptives": guarded("descriptives", descriptives, frames),
        "icc": guarded("icc", stats.icc_domains, frames),
        "h1": {
            "rm_anova": guarded("h1.rm_anova", stats.rm_anova_difficulty, frames),
            "posthoc": _posthoc(frames, cfg, stats),
            "spearman": guarded("h1.spearman", stats.spearman_confidence, frames),
            "rm_corr": guarded("h1.rm_corr", stats.rm_corr_confidence, frames),
        },
        "mixed": {
            f: guarded(f"mixed.{f}", stats.mixed_anova, frames, f) for f in stats.BETWEEN_FACTORS
        },
        "likert": _likert(frames, cfg, stats),
        "ordinal": guarded("ordinal", ordinal_models, frames),
        "exploratory": guarded("exploratory", stats.exploratory, frames),
    }


def _posthoc(frames: Frames, cfg: AnalysisConfig, stats: Any) -> dict[str, Any]:
    res = guarded(
        "h1.posthoc", stats.posthoc_difficulty, frames, cfg.padjust, cfg.authors_tukey
    )
    return {"paired": res} if set(res) == {"skipped"} else res


def _likert(frames: Frames, cfg: AnalysisConfig, stats: Any) -> dict[str, Any]:
    res = guarded("likert", stats.likert_tests, frames, cfg.padjust)
    if set(res) == {"skipped"}:  # the report reads one entry per item
        return {"padjust": cfg.padjust, **{item: res for item in LIKERT_ITEMS}}
    return res


def skipped_steps(results: dict[str, Any], prefix: str = "") -> list[str]:
    """Dotted names of every step that failed (skipped with 'failed: ...')."""
    out = []
    for k, v in results.items():
        if isinstance(v, dict):
            if str(v.get("skipped", "")).startswith("failed:"):
                out.append(prefix + k)
            else:
                out += skipped_steps(v, f"{prefix}{k}.")
    return out


def analyze(
    export_dir: str | Path,
    out_dir: str | Path,
    config: AnalysisConfig | None = None,
    *,
    note: str | None = None,
    progress: bool | None = None,
) -> dict[str, Any]:
    """Analyse the study export in `export_dir`; write results.json, report.md/.html and
    figures/ into `out_dir`. Returns the results dict (the content of results.json).

    `note` (e.g. how a simulated export was made) is printed under the report's title.
    `progress`: a tqdm bar on stderr (None: only when stderr is a terminal).
    """
    from tqdm import tqdm

    cfg = config or AnalysisConfig()
    out = Path(out_dir)
    disable = None if progress is None else not progress
    with tqdm(total=4, desc="analyze", unit="step", file=sys.stderr, disable=disable) as bar:
        bar.set_postfix_str("load")
        from cfteach.analysis import closed_loop  # closed_loop participants: their own section

        by_condition = closed_loop.sessions(export_dir)
        n_closed = by_condition.get(closed_loop.CLOSED_LOOP, 0)
        if n_closed and n_closed == sum(by_condition.values()):
            return _closed_loop_only(export_dir, out, n_closed, note)
        with closed_loop.paper_only(export_dir) as paper_dir:
            export = load_export(paper_dir, keep_sessions=list(cfg.keep_sessions))
        bar.update()
        bar.set_postfix_str("statistics")
        results, frames = compute_results(export, cfg, str(export_dir), note)
        bar.update()
        out.mkdir(parents=True, exist_ok=True)
        figures: dict[str, list[str]] = {}
        bar.set_postfix_str("figures")
        if cfg.figures:
            from cfteach.analysis.figures import make_figures

            figures = guarded("figures", make_figures, frames, results, out / "figures")
            if set(figures) == {"skipped"}:
                results["figures_skipped"] = figures["skipped"]
                figures = {}
        bar.update()
        bar.set_postfix_str("report")
        results["figures"] = {k: [f"figures/{n}" for n in v] for k, v in figures.items()}
        results["participants"]["n_sessions"] = int(sum(by_condition.values()))
        results["participants"]["n_closed_loop"] = int(n_closed)
        if n_closed:
            cl = guarded("closed_loop", closed_loop.compare, export_dir)
            results["closed_loop"] = to_jsonable(cl)
        (out / "results.json").write_text(
            json.dumps(results, indent=2, allow_nan=False) + "\n", encoding="utf-8"
        )
        from cfteach.analysis.report import write_report

        write_report(results, figures, out)
        if "skipped" not in results.get("closed_loop", {"skipped": None}):
            closed_loop.add_to_report(results["closed_loop"], out)
        bar.update()
    return results


def _closed_loop_only(
    export_dir: str | Path, out: Path, n_closed: int, note: str | None
) -> dict[str, Any]:
    """An export of closed_loop sessions only: the paper's 2 x 2 statistics have nothing to
    work on, so the results and the report hold the sessions and the closed-loop section."""
    from cfteach import __version__
    from cfteach.analysis import closed_loop
    from cfteach.analysis.report import write_closed_loop_only_report

    why = (
        f"the export has only closed_loop sessions ({n_closed}); the paper's statistics "
        "compare its four conditions"
    )
    results: dict[str, Any] = {
        "meta": {"export_dir": str(export_dir), "note": note, "cfteach_version": __version__},
        "participants": {
            "n_sessions": n_closed,
            "n_closed_loop": n_closed,
            "n_retained": 0,
            "retained_by_condition": dict.fromkeys(CONDITIONS, 0),
        },
        "paper_analysis": {"skipped": why},
        "closed_loop": to_jsonable(guarded("closed_loop", closed_loop.compare, export_dir)),
    }
    out.mkdir(parents=True, exist_ok=True)
    (out / "results.json").write_text(
        json.dumps(results, indent=2, allow_nan=False) + "\n", encoding="utf-8"
    )
    write_closed_loop_only_report(results, out)
    if "skipped" not in results["closed_loop"]:
        closed_loop.add_to_report(results["closed_loop"], out)
    return results
