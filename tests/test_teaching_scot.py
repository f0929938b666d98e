"""SCOT's working memory stays bounded whatever the size of its groups (issue 16, item 4:
`teach` on 16 environments of a 256-instance taxi domain peaked above the run on all 256,
because SCOT built a dissimilarity matrix over every demo sharing a policy-level
constraint), and scoring in blocks picks exactly what scoring everything at once picks."""

from __future__ import annotations

import tracemalloc
from pathlib import Path

import pytest

from cfteach.bec.demos import demo_set
from cfteach.domains import load, subset
from cfteach.teaching import baseline as B
from cfteach.teaching.common import one_step_sets
from cfteach.teaching.visual_arrays import visual_arrays

TAXI256 = Path(__file__).resolve().parents[1] / "bench" / "domains" / "taxi256.toml"


def _prepared(domain, profile: str):  # noqa: ANN001, ANN202
    ds = demo_set(domain, profile)
    B.bec_areas(ds)
    one_step_sets(ds)
    visual_arrays(ds)
    return ds


@pytest.mark.parametrize("profile", ["default", "reference"])
def test_scot_memory_does_not_follow_the_size_of_its_groups(profile: str) -> None:
    ds = _prepared(subset(load(str(TAXI256)), "0::16"), profile)  # 1600 demos
    tracemalloc.start()
    try:
        B.scot(ds)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 64 * 2**20, f"SCOT peaked at {peak / 2**20:.0f} MiB"  # was 313 MiB


@pytest.mark.parametrize("profile", ["default", "reference"])
@pytest.mark.parametrize("where", ["delivery", "taxi16"])
def test_small_blocks_pick_what_one_block_picks(profile: str, where: str,
                                                monkeypatch: pytest.MonkeyPatch) -> None:
    dom = load("delivery") if where == "delivery" else subset(load(str(TAXI256)), "0::16")
    ds = _prepared(dom, profile)
    whole = B.scot(ds)
    monkeypatch.setattr(B, "_SCOT_CHUNK", 997)
    monkeypatch.setattr(B, "_PAIR_CHUNK", 61)
    assert B.scot(ds) == whole
