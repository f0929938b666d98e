"""cfteach.teaching: the four conditions, tie-breaks, test selection, JSON.

Expected values come from the reference spec (§6.1 human models, §8.1 masking orders, §5.1
policy BEC) or from brute-force recomputation with plain Region operations."""

from __future__ import annotations

import json

import numpy as np
import pytest

from cfteach.bec import counterfactual_rows, demo_set, knowledge_gains
from cfteach.domains import load
from cfteach.geometry import Region
from cfteach.teaching import CONDITIONS, select_tests, teach
from cfteach.teaching.common import masking_order
from cfteach.teaching.counterfactual import candidate_set
from cfteach.teaching.visual import (
    default_dissimilarity,
    reference_dissimilarity,
    tie_break,
    typical_dissimilarity,
)
from cfteach.teaching.visual_arrays import (
    dissimilarity_matrix,
    dissimilarity_pairs,
    typical_dissimilarities,
)
from test_geometry_human_models import PRIOR_SAMPLES as SPEC_MODELS  # the authors' eight

MASKS = {"delivery": ["hotswap", "toll", "step"], "tiles": ["B", "A", "step"],
         "skateboard": ["path_step", "base_step", "skateboard_step"]}
COUNTS = {"delivery": [9480, 1763, 15979], "tiles": [10875, 8927, 21526],
          "skateboard": [2631, 1012, 2328]}
BEC_AREA = {}


def bec_area(name: str) -> float:
    if name not in BEC_AREA:
        from cfteach.bec import policy_bec

        BEC_AREA[name] = Region(policy_bec(name)).area()
    return BEC_AREA[name]


@pytest.mark.parametrize("name", ["delivery", "tiles", "skateboard"])
def test_masking_order_from_spec_counts(name: str) -> None:
    names = load(name).feature_names
    assert [names[i] for i in masking_order(np.array(COUNTS[name]))] == MASKS[name]


@pytest.fixture(scope="module")
def skate_ref() -> dict[str, object]:
    return {c: teach("skateboard", c, profile="reference") for c in CONDITIONS}


def test_reference_first_round_uses_spec_models(skate_ref) -> None:  # noqa: ANN001
    for c in ("counterfactual_only", "proposed"):
        W = np.array(skate_ref[c].log[0]["human_models"])
        assert np.allclose(W, SPEC_MODELS, atol=1e-8, rtol=0)


def test_proposed_masks_follow_spec_order(skate_ref) -> None:  # noqa: ANN001
    seq = [e["masked_feature"] for e in skate_ref["proposed"].log]
    order = [*MASKS["skateboard"], None]
    pos = [order.index(m) for m in seq]
    assert pos == sorted(pos) and seq[0] == "path_step"
    assert all(e["masked_feature"] is None for e in skate_ref["counterfactual_only"].log)


def test_skateboard_reference_lengths_and_final_beliefs(skate_ref) -> None:  # noqa: ANN001
    # the study showed 7 demonstrations per condition in skateboard
    for c in CONDITIONS:
        cur = skate_ref[c]
        assert len(cur) == 7, c
        assert cur.final_belief.area() == pytest.approx(bec_area("skateboard"), rel=1e-9), c
        areas = [r.belief_area_after for r in cur.records]
        assert all(a >= b - 1e-12 for a, b in zip(areas, areas[1:], strict=False))


@pytest.mark.slow
@pytest.mark.parametrize("name", ["delivery", "tiles"])
def test_all_conditions_reach_the_bec(name: str) -> None:
    lengths = {}
    for c in CONDITIONS:
        cur = teach(name, c, profile="reference",
                    max_demos=10 if c == "counterfactual_only" else None)
        lengths[c] = len(cur)
        assert cur.final_belief.area() == pytest.approx(bec_area(name), rel=1e-9), c
    # the study's lists: 5 demonstrations; counterfactual_only stops by itself at 5
    assert lengths == {c: 5 for c in CONDITIONS}


def test_shown_demo_has_gain_one_and_greedy_is_argmax() -> None:
    """Round 1 of counterfactual_only (proportion 1): every candidate's gain recomputed with
    plain Region operations; the chosen one has the maximum; once shown its gain is 1."""
    dom = load("skateboard")
    cur = teach(dom, "counterfactual_only", profile="default", proportion=1.0, max_demos=2,
                seed=3)
    ds = demo_set(dom, "default")
    W = np.array(cur.log[0]["human_models"])
    joint, _, _ = counterfactual_rows(ds, W)
    prior = Region(dom.prior)
    brute = np.zeros(ds.D)
    for d in range(ds.D):
        rows = joint.of(d)
        if len(rows):
            C = Region(rows).reduced()
            brute[d] = prior.area() / Region(np.vstack([dom.prior, C])).area()
    first = cur.records[0]
    assert first.knowledge_gain == pytest.approx(brute.max(), rel=1e-9)
    assert brute[first.demo] == pytest.approx(brute.max(), rel=1e-9)
    after = Region(np.vstack([dom.prior, first.constraints]))
    assert knowledge_gains(after, joint, np.array([first.demo]))[0] == pytest.approx(1.0)
    assert after.area() == pytest.approx(first.belief_area_after)


def test_candidate_rules() -> None:
    g = np.array([0.0, 1.0, 3.0, 2.1, 3.0 + 1e-12, 1.5])
    assert candidate_set("default", g, 1.0, False) == [2, 4]
    assert candidate_set("reference", g, 1.0, False) == [2, 4]
    assert candidate_set("reference", g, 1.0, True) == [4]  # array branch: exact max only
    assert candidate_set("default", g, 0.7, False) == [3]  # closest to 2.1
    assert candidate_set("reference", g, 0.7, False) == [3]
    assert candidate_set("default", np.array([1.0, 0.0]), 1.0, False) == []
    from cfteach.teaching.counterfactual import _isclose

    for a, b in [(1.0, 1.0000001), (1.0, np.inf), (np.inf, np.inf), (2.0, 1.99999),
                 (0.0, 1e-9), (1.0, -np.inf), (3.0, 3.00003), (3.0, 3.0001)]:
        assert _isclose(a, b) == bool(np.isclose(a, b)), (a, b)


def test_dissimilarity_arrays_match_scalar_and_tie_break() -> None:
    ds = demo_set(load("delivery"), "reference")
    rng = np.random.default_rng(0)
    a, b = rng.choice(ds.D, 15), rng.choice(ds.D, 15)
    M = dissimilarity_matrix(ds, a, b)
    for i, x in enumerate(a):
        for j, y in enumerate(b):
            assert M[i, j] == reference_dissimilarity(ds.instance(x), ds.start_state(x),
                                                      ds.instance(y), ds.start_state(y))
    comp = np.array([ds.instance(d).complexity for d in a])
    pick = tie_break(ds, a.tolist(), previous=int(b[0]), rng=np.random.default_rng(1))
    assert ds.instance(pick).complexity == comp.min()
    simplest = [int(d) for d in a if ds.instance(d).complexity == comp.min()]
    dis = {d: reference_dissimilarity(ds.instance(d), ds.start_state(d),
                                      ds.instance(int(b[0])), ds.start_state(int(b[0])))
           for d in simplest}
    assert dis[pick] == min(dis.values())


def test_dissimilarity_pairs_match_scalar() -> None:
    for profile, scalar in [("reference", reference_dissimilarity),
                            ("default", default_dissimilarity)]:
        ds = demo_set(load("delivery"), profile)
        rng = np.random.default_rng(2)
        x, y = rng.choice(ds.D, 25), rng.choice(ds.D, 25)
        got = dissimilarity_pairs(ds, x, y)
        want = [scalar(ds.instance(p), ds.start_state(p), ds.instance(q), ds.start_state(q))
                for p, q in zip(x.tolist(), y.tolist(), strict=True)]
        assert got.tolist() == want
        typical = typical_dissimilarities(ds, x[:5])
        assert typical.tolist() == [
            typical_dissimilarity(profile, ds.instance(p), ds.start_state(p))
            for p in x[:5].tolist()]


def test_curriculum_json_is_consistent(skate_ref) -> None:  # noqa: ANN001
    cur = skate_ref["proposed"]
    j = json.loads(json.dumps(cur.to_json()))
    dom = load("skateboard")
    assert j["schema"] == "cfteach.curriculum/1" and j["condition"] == "proposed"
    assert j["feature_names"] == list(dom.feature_names)
    for demo in j["demos"]:
        inst = dom.instance(demo["env_code"])
        assert inst.index == demo["env_index"]
        s = inst.state_from_json(demo["start_state"])
        mu = np.zeros(3)
        for a, nxt in zip(demo["actions"], demo["states"][1:], strict=True):
            s, phi, _ = inst.step(s, dom.actions.index(a))
            mu += phi
            assert inst.state_to_json(s) == nxt
        assert mu.tolist() == demo["feature_counts"]
        assert demo["reward"] == pytest.approx(float(dom.weights @ mu))
        assert set(demo) >= {"constraints", "knowledge_gain", "belief_area_after",
                             "masked_feature"}
    assert j["final_belief"]["area"] == pytest.approx(bec_area("skateboard"))


def test_reproducible_from_seed() -> None:
    a = teach("skateboard", "counterfactual_only", profile="default", seed=7).to_json()
    b = teach("skateboard", "counterfactual_only", profile="default", seed=7).to_json()
    assert a == b
    c = teach("skateboard", "baseline", profile="default", seed=7).to_json()
    d = teach("skateboard", "baseline", profile="default", seed=7).to_json()
    assert c == d


def test_bad_input_is_named() -> None:
    with pytest.raises(ValueError, match="'nope'.*baseline"):
        teach("skateboard", "nope")
    with pytest.raises(ValueError, match="'best'.*reference"):
        teach("skateboard", "proposed", profile="best")
    with pytest.raises(ValueError, match="proportion.*1.5"):
        teach("skateboard", "proposed", proportion=1.5)
    with pytest.raises(ValueError, match="proportion.*0"):
        teach("skateboard", "proposed", proportion=0)
    with pytest.raises(ValueError, match="neither a built-in"):
        teach("no-such-domain", "proposed")
    from cfteach.teaching.testsel import training_keys

    ds = demo_set(load("skateboard"), "reference")
    start = {"agent": [2, 1], "skateboard": [1, 4], "carrying": False}
    code = list(ds.batch.instances[3].env_code)
    assert training_keys(ds, [{"demos": [{"env_code": code, "start_state": start}]}]) == \
        training_keys(ds, [{"demos": [{"env_index": 3, "start_state": start}]}])
    with pytest.raises(ValueError, match="env_code must be 3 bits"):  # was read as instance 1
        training_keys(ds, [{"demos": [{"env_code": [1], "start_state": start}]}])
    with pytest.raises(ValueError, match="training demo 0.*out of range"):  # was the last one
        training_keys(ds, [{"demos": [{"env_index": -1, "start_state": start}]}])


def test_tests_overlaps_levels_and_exclusion(skate_ref) -> None:  # noqa: ANN001
    dom = load("skateboard")
    training = [skate_ref[c] for c in CONDITIONS]
    ts = select_tests(dom, training=[t.to_json() for t in training[:2]] + training[2:],
                      profile="reference", per_level=6, include_candidates=True)
    np.testing.assert_allclose(ts.human_models, np.array(
        select_tests(dom, profile="reference", per_level=0).human_models))
    j = ts.to_json()
    train = {(d["env_index"], json.dumps(d["start_state"], sort_keys=True))
             for t in training for d in t.to_json()["demos"]}
    post = dom.posterior
    levels = j["tests"]
    for level, tests in levels.items():
        assert len(tests) == 6, level
        for t in tests:
            key = (t["env_index"], json.dumps(t["start_state"], sort_keys=True))
            assert key not in train
            stacked = Region(np.vstack([post, np.array(t["constraints"]).reshape(-1, 3)]))
            assert t["overlap"] == pytest.approx(stacked.area(), rel=1e-9)
            assert t["optimal_reward"] == pytest.approx(float(dom.weights @ t["feature_counts"]))
            assert t["actions"] in t["all_optimal_actions"]
    hi = max(t["overlap"] for t in levels["high"])
    assert hi < min(t["overlap"] for t in levels["medium"])
    assert max(t["overlap"] for t in levels["medium"]) < min(t["overlap"]
                                                             for t in levels["low"])
    assert len(j["candidates"]) == demo_set(dom, "reference").D - len(j["excluded"])
    assert j["cluster_centres"] == sorted(j["cluster_centres"])


@pytest.mark.parametrize("name,profile", [("skateboard", "reference"), ("delivery", "reference"),
                                          ("tiles", "default")])
def test_scot_broadcast_equals_generic_enumeration(name: str, profile: str) -> None:
    """The 3-constraint fast path vs the generic chunked enumeration (sorted indices), on
    sub-groups small enough for the generic path; the groups include shared demos."""
    from cfteach.teaching import baseline as B

    ds = demo_set(load(name), profile)
    rng = np.random.default_rng(2)
    sets = B.one_step_sets(ds)
    pol = Region(np.vstack([s for s in sets.values() if len(s)])).reduced()
    groups = []
    for c in pol:
        members = np.array([d for d in range(ds.D) if len(sets[d])
                            and np.any(np.all(sets[d] == c, axis=1))])
        groups.append(np.sort(rng.choice(members, size=min(25, len(members)), replace=False)))
    # force a few shared members so the duplicate-handling branch runs
    groups[1] = np.union1d(groups[1], groups[0][:2])
    groups[2] = np.union1d(groups[2], groups[0][:1])
    assert B._scot3(ds, groups) == B._scot_generic(ds, groups)


def test_default_profile_reaches_the_bec_despite_unbounded_models() -> None:
    """With 32 uniform models, most of skateboard's belief after one demonstration makes
    pickup/dropoff loops pay: skipping such models stopped teaching after one demonstration
    (area 1.72); their loop constraints let it reach the policy-level BEC."""
    skip = teach("skateboard", "counterfactual_only", human_models=32, seed=1,
                 unbounded_models="skip")
    assert len(skip) == 1 and skip.final_belief.area() > 1
    loops = teach("skateboard", "counterfactual_only", human_models=32, seed=1)
    assert loops.to_json()["settings"]["unbounded_models"] == "loops"
    assert loops.final_belief.area() == pytest.approx(bec_area("skateboard"), rel=1e-9)
    assert loops.final_belief.contains(load("skateboard").weights)
    with pytest.raises(ValueError, match="'maybe'.*skip"):
        teach("skateboard", "proposed", unbounded_models="maybe")


@pytest.mark.slow
@pytest.mark.parametrize("name", ["delivery", "tiles", "skateboard"])
def test_default_profile_conditions_reach_the_bec(name: str) -> None:
    for c in CONDITIONS:
        cur = teach(name, c, profile="default", seed=0)
        assert cur.final_belief.area() == pytest.approx(bec_area(name), rel=1e-9), c


def test_every_curriculum_writes_all_settings(skate_ref) -> None:  # noqa: ANN001
    """docs/schemas.md: the same settings keys in every curriculum, null where unused."""
    for c in CONDITIONS:
        s = skate_ref[c].to_json()["settings"]
        assert set(s) == {"human_models", "max_demos", "proportion", "unbounded_models"}, c
        assert s["max_demos"] == 7  # skateboard's [teaching] max_demos
        if c in ("baseline", "feature_only"):
            assert s["human_models"] is None and s["proportion"] is None, c
            assert s["unbounded_models"] is None
        else:
            assert s["human_models"] == 8 and s["unbounded_models"] == "skip", c
    assert skate_ref["counterfactual_only"].to_json()["settings"]["proportion"] == 0.7


def test_fewer_than_five_overlap_clusters_keep_the_extremes() -> None:
    from cfteach.teaching.testsel import level_clusters

    assert level_clusters(5) == {"high": 0, "medium": 2, "low": 4}
    assert level_clusters(4) == {"high": 0, "medium": 2, "low": 3}
    assert level_clusters(3) == {"high": 0, "medium": 1, "low": 2}
    assert level_clusters(2) == {"high": 0, "medium": None, "low": 1}
    assert level_clusters(1) == {"high": None, "medium": None, "low": 0}


def test_tests_json_does_not_depend_on_the_openmp_thread_count() -> None:
    """k-means' centres used to differ in the last digits with the OpenMP threads, so a
    machine with another core count (or a worker process) wrote different tests JSON."""
    import sklearn.cluster  # noqa: F401 - loads the OpenMP runtime the limits must reach
    from threadpoolctl import threadpool_limits

    out = []
    for threads in (1, 2):
        with threadpool_limits(limits=threads, user_api="openmp"):
            out.append(json.dumps(select_tests("delivery", seed=3).to_json(), sort_keys=True))
    assert out[0] == out[1]
