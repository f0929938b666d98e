"""The closed-loop teacher's backbone: an open-loop curriculum every session covers."""

from __future__ import annotations

import pytest

from cfteach import teaching
from cfteach.closedloop import ClosedLoopTeacher, TeacherSettings, build_pool
from cfteach.closedloop.pool import demo_indices

DOMAIN = "skateboard"
SMALL = TeacherSettings(n_particles=300, max_items=40)


@pytest.fixture(scope="module")
def material():
    cur = teaching.teach(DOMAIN, "proposed").to_json()
    tests = teaching.select_tests(DOMAIN, per_level=3)
    plain = build_pool(DOMAIN, human_models=16, held_out=tests)
    backed = build_pool(DOMAIN, human_models=16, held_out=tests, backbone=cur["demos"])
    return cur, plain, backed


def _optimal(pool, d: int) -> dict:
    return {"feature_counts": pool.ds.mu[d].tolist(), "finished": True}


def _run(pool, seed: int = 0) -> ClosedLoopTeacher:
    """A learner who answers every test optimally: the teacher stops as early as it may."""
    t = ClosedLoopTeacher(pool, SMALL, seed=seed)
    while (item := t.next()) is not None:
        t.observe(_optimal(pool, item.demo) if item.kind == "test" else {})
    return t


def test_backbone_is_the_curriculum_in_order(material):
    cur, _, backed = material
    ds = backed.ds
    expected = [ds.index(int(d["env_index"]),
                         ds.domain.instance(int(d["env_index"])).state_from_json(d["start_state"]))
                for d in cur["demos"]]
    assert list(backed.backbone) == expected == demo_indices(ds, cur["demos"])


def test_a_perfect_learner_still_sees_the_whole_backbone_in_order(material):
    _, plain, backed = material
    short = _run(plain)
    full = _run(backed)
    shown = [it.demo for it in full.items if it.purpose == "backbone"]
    assert shown == list(full._backbone) and len(shown) == len(backed.backbone)
    # the plain teacher stops sooner on the same answers: the backbone is what holds it
    assert len(short.items) < len(full.items)
    assert full.stop_reason is not None and "budget" not in full.stop_reason
    # each backbone lesson is followed by its diagnostic test when one discriminates
    for k, it in enumerate(full.items[:-1]):
        nxt = full.items[k + 1]
        if it.purpose == "backbone" and nxt.kind == "test":
            assert nxt.about == it.index


def test_a_backbone_demo_at_a_post_test_start_is_replaced_or_dropped(material):
    cur, plain, _ = material
    held = sorted(plain.held_out)
    pool = build_pool(DOMAIN, human_models=16, held_out=held,
                      backbone=[held[0], *demo_indices(plain.ds, cur["demos"])])
    t = ClosedLoopTeacher(pool, SMALL, seed=0)
    assert held[0] not in t._backbone
    s = int(pool.lessons.slot[held[0]])
    same = [int(m) for m in pool.lessons.members[s]] if s >= 0 else []
    if any(m not in t._no_lesson for m in same):
        assert t._backbone[0] in same and t._backbone[0] not in t._no_lesson
    else:
        assert len(t._backbone) == len(pool.backbone) - 1


def test_replay_with_a_backbone_restores_the_same_items(material):
    _, _, backed = material
    t = _run(backed, seed=4)
    again = ClosedLoopTeacher.replay(backed, t.responses, settings=SMALL, seed=4)
    assert [i.to_json(backed) for i in t.items] == [i.to_json(backed) for i in again.items]


def _run_failing(pool, seed: int = 0) -> ClosedLoopTeacher:
    """A learner who never finishes a test: every test fails, every failure gets feedback."""
    t = ClosedLoopTeacher(pool, SMALL, seed=seed)
    while (item := t.next()) is not None:
        t.observe({"feature_counts": [0.0] * pool.ds.F, "finished": False}
                  if item.kind == "test" else {})
    return t


@pytest.mark.parametrize("seed", [0, 3])
def test_a_learner_who_keeps_failing_still_sees_the_whole_backbone(material, seed):
    """Remedial lessons after failed tests once filled the item budget first (a noisy
    skateboard learner saw 1 of 7 backbone lessons in 40 items)."""
    _, _, backed = material
    t = _run_failing(backed, seed)
    shown = [it.demo for it in t.items if it.purpose == "backbone"]
    assert shown == list(t._backbone) and len(shown) >= 5
    assert any(it.purpose == "remedial" for it in t.items)  # remediation still happens
    # while backbone lessons remain, no remedial lesson for a test about a remedial lesson
    last_backbone = max(it.index for it in t.items if it.purpose == "backbone")
    for it in t.items[:last_backbone]:
        if it.purpose == "remedial":
            test = t.items[it.about]
            assert test.about is None or t.items[test.about].purpose != "remedial"


def test_a_failing_learner_without_backbone_is_remediated_as_before(material):
    """Without a backbone the remedial rule is unchanged: remedial lessons may chain."""
    _, plain, _ = material
    t = _run_failing(plain)
    chained = [it for it in t.items if it.purpose == "remedial" and it.about is not None
               and t.items[it.about].about is not None
               and t.items[t.items[it.about].about].purpose == "remedial"]
    assert chained
