"""Figures: within-subject CIs, proportion axes 0..1, readable condition labels, ratings
per participant, annotated exploratory panels (checked on the matplotlib objects)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy import stats as sps

from cfteach.analysis import SyntheticConfig, compute_results, generate
from cfteach.analysis import figures as F
from cfteach.analysis.io import DIFFICULTIES
from cfteach.analysis.stats import within_subject_ci


def test_within_subject_ci_ignores_between_person_offsets() -> None:
    rng = np.random.default_rng(1)
    pattern = np.array([0.8, 0.6, 0.3])
    rows = []
    for i in range(12):
        offset = rng.normal(0, 0.1)
        noise = rng.normal(0, 0.05, 3)
        for d, v in zip(DIFFICULTIES, pattern + offset + noise, strict=True):
            rows.append({"participant_id": f"p{i}", "difficulty": d, "optimal": v})
    cells = pd.DataFrame(rows)
    got = within_subject_ci(cells)
    wide = cells.pivot(index="participant_id", columns="difficulty", values="optimal")[
        list(DIFFICULTIES)
    ].to_numpy()
    centred = wide - wide.mean(axis=1, keepdims=True)  # Cousineau: remove each person's mean
    t = sps.t.ppf(0.975, 11)
    for k, d in enumerate(DIFFICULTIES):
        want = t * centred[:, k].std(ddof=1) / math.sqrt(12) * math.sqrt(3 / 2)  # Morey
        assert got[d]["half"] == pytest.approx(want, rel=1e-12)
        naive = t * wide[:, k].std(ddof=1) / math.sqrt(12)
        assert got[d]["half"] < naive  # offsets no longer widen the bars
    flat = cells.assign(
        optimal=cells["difficulty"].map(dict(zip(DIFFICULTIES, pattern, strict=True)))
    )
    flat["optimal"] += flat["participant_id"].str[1:].astype(int) * 0.01
    assert all(v["half"] == pytest.approx(0, abs=1e-12) for v in within_subject_ci(flat).values())


@pytest.fixture(scope="module")
def drawn(tmp_path_factory: pytest.TempPathFactory):
    figs = {}

    def keep(fig, out_dir: Path, stem: str):
        figs[stem] = fig
        return [f"{stem}.png"]

    r, frames = compute_results(generate(SyntheticConfig(n_participants=48, seed=2)))
    mp = pytest.MonkeyPatch()
    mp.setattr(F, "_save", keep)
    F.make_figures(frames, r, tmp_path_factory.mktemp("f"))
    mp.undo()
    return figs, r, frames


def test_proportion_axes_run_from_0_to_1(drawn) -> None:
    figs, _, _ = drawn
    for stem in ("difficulty", "interaction", "paper_bars"):
        for ax in figs[stem].axes:
            if ax.get_ylabel().startswith("Proportion") or stem == "interaction":
                assert ax.get_ylim() == (0.0, 1.0), stem


def test_readable_condition_labels(drawn) -> None:
    figs, _, _ = drawn
    texts = [t.get_text() for t in figs["likert"].axes[0].get_yticklabels()]
    assert "Counterfactual + feature scaffolding" in texts and "counterfactual_only" not in texts
    legend = [t.get_text() for t in figs["interaction"].axes[2].get_legend().get_texts()]
    assert "Counterfactual + feature scaffolding" in legend


def test_likert_figure_counts_participants(drawn) -> None:
    figs, r, frames = drawn
    ax = figs["likert"].axes[0]
    assert "% of participants" in ax.get_xlabel()
    # bar widths per condition add up to 100 % of that condition's participants
    widths = {}
    for patch in ax.patches:
        y = round(patch.get_y() + patch.get_height() / 2)
        widths[y] = widths.get(y, 0) + patch.get_width()
    assert all(v == pytest.approx(100) for v in widths.values())


def test_exploratory_has_labels_and_tests(drawn) -> None:
    figs, r, _ = drawn
    for ax, measure in zip(figs["exploratory"].axes, ("plays_completed", "time_norm"), strict=True):
        assert ax.get_xlabel().startswith("Condition")
        a = r["exploratory"][measure]["condition"]
        assert (
            ax.get_title()
            == f"one-way ANOVA: F({a['df1']:.0f}, {a['df2']:.0f}) = {a['F']:.2f}, "
            + ("p < .001" if a["p"] < 0.001 else f"p = {a['p']:.3f}".replace("0.", ".", 1))
        )


def test_difficulty_bars_use_within_subject_cis(drawn) -> None:
    figs, _, frames = drawn
    ax = figs["difficulty"].axes[0]
    assert "within-subject" in ax.get_ylabel()
    ci = within_subject_ci(frames.cells)
    caps = [c for c in ax.collections]  # the error bar line collection
    segs = caps[0].get_segments()
    for seg, d in zip(segs, DIFFICULTIES, strict=True):
        assert (seg[1][1] - seg[0][1]) / 2 == pytest.approx(ci[d]["half"], rel=1e-9)


def test_report_uses_readable_condition_names(tmp_path: Path) -> None:
    from cfteach.analysis.report import write_report

    r, _ = compute_results(generate(SyntheticConfig(n_participants=24, seed=3)))
    write_report(r, {}, tmp_path)
    md = (tmp_path / "report.md").read_text()
    assert "Counterfactual + feature scaffolding: 6" in md  # retained per condition
    for raw in ("proposed:", "counterfactual_only:", "| proposed |"):
        assert raw not in md.split("## Descriptives")[1], raw
