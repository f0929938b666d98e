"""Teaching spread over workers (`cfteach.teaching.distribute`) gives the one-process answer
bit for bit: on local processes and on a Dask LocalCluster, for a 4-feature random domain
(the > 3-feature geometry) and a 3-feature built-in."""

from __future__ import annotations

import json

import numpy as np
import pytest

from cfteach.bec.constraints import (
    concat_rowsets,
    counterfactual_rows,
    counterfactual_rowset,
    plan_chunks,
    sub_rowset,
)
from cfteach.bec.demos import demo_set
from cfteach.domains import load, random_gridworld
from cfteach.geometry import Region, clear_cache
from cfteach.parallel import Executor
from cfteach.teaching import select_tests, teach
from cfteach.teaching.sampling import sample_models


def _fresh(dom, profile):
    """Forget every memo so each run really computes."""
    demo_set(dom, profile).cache.clear()
    clear_cache()


def _models(ds, n=8, seed=1):
    prior = Region(np.asarray(ds.domain.prior, dtype=np.int64), dim=ds.F).reduced()
    return sample_models(ds.profile, prior, n, np.random.default_rng(seed), ds.F)


def _same_rowset(a, b) -> bool:
    return (np.array_equal(a.rows, b.rows) and np.array_equal(a.demo, b.demo)
            and np.array_equal(a.offsets, b.offsets))


def _run(dom, profile, **kw) -> tuple[str, str]:
    _fresh(dom, profile)
    cur = teach(dom, "proposed", profile=profile, **kw)
    tests = select_tests(dom, training=[cur], profile=profile, per_level=2, **kw)
    return (json.dumps(cur.to_json(), sort_keys=True),
            json.dumps(tests.to_json(), sort_keys=True))


@pytest.fixture(scope="module")
def small4():
    return random_gridworld(6, 6, 4, 16, 0)


@pytest.mark.parametrize("profile", ["default", "reference"])
@pytest.mark.parametrize("budget", [1, 300, 1 << 20])
def test_streamed_rows_equal_the_all_at_once_rows(small4, profile, budget) -> None:
    ds = demo_set(small4, profile)
    W = _models(ds)
    whole, bounded, _ = counterfactual_rows(ds, W)
    ds.cache.pop("counterfactual_rowset", None)
    streamed, b2 = counterfactual_rowset(ds, W, budget=budget)
    assert _same_rowset(whole, streamed)
    assert np.array_equal(bounded, b2)


def test_plan_chunks_cover_every_instance_and_demo_once(small4) -> None:
    ds = demo_set(small4, "default")
    chunks = plan_chunks(ds, 8, budget=500)
    assert len(chunks) > 1
    assert sum(c.batch.E for c in chunks) == ds.batch.E
    assert [c.demo0 for c in chunks] == sorted({c.demo0 for c in chunks})
    assert sum(c.n_demos for c in chunks) == ds.D
    assert len(plan_chunks(ds, 8, min_chunks=5)) == 5


def test_sub_rowset_and_concat_round_trip(small4) -> None:
    ds = demo_set(small4, "default")
    joint, _ = counterfactual_rowset(ds, _models(ds))
    cuts = [0, 7, 100, ds.D]
    parts = [sub_rowset(joint, np.arange(a, b)) for a, b in zip(cuts[:-1], cuts[1:], strict=True)]
    assert _same_rowset(concat_rowsets(parts, ds.D), joint)
    some = np.array([5, 2, 40])
    sub = sub_rowset(joint, some)
    for i, d in enumerate(some.tolist()):
        assert np.array_equal(sub.of(i), joint.of(d))
    with pytest.raises(ValueError, match="cover"):
        concat_rowsets(parts[:2], ds.D)


def test_two_local_processes_give_the_one_process_curriculum_and_tests(small4) -> None:
    one = _run(small4, "default")
    with Executor(backend="local", n_workers=2) as ex:
        two = _run(small4, "default", executor=ex)
    assert one == two
    assert _run(small4, "default", workers=2) == one  # a pool started by teach itself


def test_dask_local_cluster_gives_the_one_process_results(small4) -> None:
    pytest.importorskip("distributed")
    sk = load("skateboard")
    one = {"rg": _run(small4, "default"), "sk": _run(sk, "reference")}
    with Executor(backend="dask", n_workers=2) as ex:
        assert _run(small4, "default", executor=ex) == one["rg"]
        assert _run(sk, "reference", executor=ex) == one["sk"]


def test_bad_parallel_settings_are_named() -> None:
    with pytest.raises(ValueError, match="workers must be an integer"):
        teach("skateboard", "proposed", workers=0)
    with pytest.raises(ValueError, match="scheduler"):
        teach("skateboard", "proposed", scheduler="tcp://127.0.0.1:1")
    with pytest.raises(ValueError, match="unknown parallel backend"):
        select_tests("skateboard", backend="spark", workers=2)
    with Executor(backend="local", n_workers=2) as ex, \
            pytest.raises(ValueError, match="either an executor"):
        teach("skateboard", "baseline", executor=ex, workers=2)


@pytest.mark.parametrize("first_step_only", [False, True])
def test_one_action_rows_in_demo_chunks_equal_all_at_once(small4, monkeypatch,
                                                          first_step_only) -> None:
    import cfteach.bec.constraints as cons
    from cfteach.bec.constraints import one_action_rows

    ds = demo_set(small4, "reference")
    ds.cache.clear()
    monkeypatch.setattr(cons, "_ONE_ACTION_DEMOS", 10**9)
    whole = one_action_rows(ds, first_step_only=first_step_only)
    ds.cache.clear()
    monkeypatch.setattr(cons, "_ONE_ACTION_DEMOS", 37)
    assert _same_rowset(one_action_rows(ds, first_step_only=first_step_only), whole)


def test_demo_set_built_in_chunks_equals_all_at_once(monkeypatch) -> None:
    import cfteach.bec.demos as demos

    built = []
    for chunk in (10**9, 50):
        monkeypatch.setattr(demos, "_BUILD_CHUNK", chunk)
        built.append(demos._build(random_gridworld(6, 6, 4, 16, 0), "default"))
    for key in ("step_phi", "suffix_mu", "states", "actions", "length", "dev_mu"):
        a, b = getattr(built[0], key), getattr(built[1], key)
        assert a.dtype == b.dtype and np.array_equal(a, b), key


def test_baselines_on_two_workers_equal_one_process(small4) -> None:
    from cfteach.bec.constraints import one_action_rows
    from cfteach.bec.rows import reduce_and_measure
    from cfteach.teaching.distribute import one_step_cache

    for cond in ("baseline", "feature_only"):
        _fresh(small4, "default")
        one = teach(small4, cond).to_json()
        _fresh(small4, "default")
        assert teach(small4, cond, workers=2).to_json() == one
    ds = demo_set(small4, "default")
    ds.cache.clear()
    red, areas = reduce_and_measure(one_action_rows(ds))
    with Executor(backend="local", n_workers=2) as ex:
        one_step_cache(ds, ex)
    assert np.array_equal(ds.cache["bec_areas"], areas)
    assert all(np.array_equal(ds.cache["one_step_sets"][d], red[d]) for d in range(ds.D))
