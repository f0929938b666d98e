"""`analyze(export_dir, out_dir)`: load, exclude, compute every statistic, plot, report."""

from __future__ import annotations

import json
import sys
import warnings
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from cfteach.analysis.aggregate import Frames, build_frames
from cfteach.analysis.exclusions import ExclusionConfig, apply_exclusions, quality_flags
from cfteach.analysis.io import CONDITIONS, StudyExport, load_export
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

    def __post_init__(self) -> None:
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
        "sensitivity": sensitivity(export, cfg.exclusions),
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


def _all_statistics(frames: Frames, cfg: AnalysisConfig, stats: Any) -> dict[str, Any]:
    from cfteach.analysis.descriptives import descriptives
    from cfteach.analysis.factorial import full_anova
    from cfteach.analysis.glmm import trial_glmm
    from cfteach.analysis.ordinal import ordinal_models

    full = full_anova(stats.complete_cells(frames.cells))
    return {
        "full_anova": full.get("terms", []),
        "full_anova_participants": full.get("participants", []),
        "full_anova_skipped": full.get("skipped"),
        "full_anova_detail": {k: v for k, v in full.items() if k not in ("terms", "participants")},
        "glmm": trial_glmm(frames.tests),
        "descriptives": descriptives(frames),
        "icc": stats.icc_domains(frames),
        "h1": {
            "rm_anova": stats.rm_anova_difficulty(frames),
            "posthoc": stats.posthoc_difficulty(frames, cfg.padjust, cfg.authors_tukey),
            "spearman": stats.spearman_confidence(frames),
            "rm_corr": stats.rm_corr_confidence(frames),
        },
        "mixed": {f: stats.mixed_anova(frames, f) for f in stats.BETWEEN_FACTORS},
        "likert": stats.likert_tests(frames, cfg.padjust),
        "ordinal": ordinal_models(frames),
        "exploratory": stats.exploratory(frames),
    }


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

            figures = make_figures(frames, results, out / "figures")
        bar.update()
        bar.set_postfix_str("report")
        results["figures"] = {k: [f"figures/{n}" for n in v] for k, v in figures.items()}
        if (cl := closed_loop.compare(export_dir)) is not None:
            results["closed_loop"] = to_jsonable(cl)
        (out / "results.json").write_text(
            json.dumps(results, indent=2, allow_nan=False) + "\n", encoding="utf-8"
        )
        from cfteach.analysis.report import write_report

        write_report(results, figures, out)
        closed_loop.add_to_report(results.get("closed_loop"), out)
        bar.update()
    return results
