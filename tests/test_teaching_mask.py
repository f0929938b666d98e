"""The feature mask is checked only as far down the gains as the selection can see, with
the same curricula and logs as checking every demonstration."""

from __future__ import annotations

import json

import numpy as np
import pytest

import cfteach.teaching.counterfactual as cf
from cfteach.bec.demos import demo_set
from cfteach.domains import load, random_gridworld
from cfteach.geometry import clear_cache
from cfteach.teaching import teach


def _check_all(joint, gains_all, feature, proportion, executor=None, *, errors=None):
    """The rule before: every live demo checked against the mask."""
    live = np.flatnonzero(gains_all > 1)
    gains = gains_all.copy()
    gains[live[cf.blocked(joint, live, feature, executor)]] = 0.0
    return gains


def _teach(dom, profile, seed):
    demo_set(dom, profile).cache.clear()
    clear_cache()
    cur = teach(dom, "proposed", profile=profile, seed=seed)
    return json.dumps(cur.to_json(), sort_keys=True), json.dumps(cur.log, sort_keys=True)


@pytest.mark.parametrize("name, profile, seeds", [
    ("skateboard", "reference", (0, 1)), ("skateboard", "default", (0,)),
    ("random", "default", (0,)),
])
def test_same_curriculum_and_log_as_checking_every_demo(monkeypatch, name, profile,
                                                        seeds) -> None:
    dom = random_gridworld(6, 6, 4, 16, 0) if name == "random" else load(name)
    for seed in seeds:
        lazy = _teach(dom, profile, seed)
        with monkeypatch.context() as m:
            m.setattr(cf, "masked_gains", _check_all)
            full = _teach(dom, profile, seed)
        assert lazy == full


def test_checks_fewer_demos_than_every_live_one(monkeypatch) -> None:
    dom = random_gridworld(6, 6, 4, 16, 0)
    checked, live = [], []
    real_blocked, real_masked = cf.blocked, cf.masked_gains

    def counting_blocked(joint, demos, feature, executor=None):
        checked[-1] += len(demos)
        return real_blocked(joint, demos, feature, executor)

    def counting_masked(joint, gains_all, feature, proportion, executor=None, *, errors=None):
        checked.append(0)
        live.append(int(np.count_nonzero(gains_all > 1)))
        return real_masked(joint, gains_all, feature, proportion, executor, errors=errors)

    monkeypatch.setattr(cf, "blocked", counting_blocked)
    monkeypatch.setattr(cf, "masked_gains", counting_masked)
    demo_set(dom, "default").cache.clear()
    teach(dom, "proposed", profile="default", seed=0)
    assert live and sum(checked) < sum(live) / 2, (checked, live)


def test_estimated_gains_check_every_demo_refine_top_may_rerank(monkeypatch) -> None:
    """With standard errors (more than 3 features), a demo whose gain is well below the best
    unmasked one but whose upper bound reaches that one's lower bound is checked, so a
    masked demo can never win after `refine_top`; demos beyond that floor are not."""
    held_back = {1, 2, 3}
    seen: list[int] = []

    def fake_blocked(joint, demos, feature, executor=None):
        seen.extend(int(d) for d in demos)
        return np.array([int(d) in held_back for d in demos], dtype=bool)

    monkeypatch.setattr(cf, "blocked", fake_blocked)
    monkeypatch.setattr(cf, "_MASK_FIRST", 1)
    gains = np.array([10.0, 9.0, 5.0, 2.0, 1.5])
    errors = np.array([0.5, 0.5, 1.0, 0.1, 0.1])
    out = cf.masked_gains(None, gains, 0, 1.0, errors=errors)
    # best unmasked: demo 0, lower bound 10 - 3 * 0.5 = 8.5; demo 2 reaches 5 + 3 = 8 < 8.5,
    # demo 1 reaches 10.5: checked and held back; demos 2-4 are below the floor.
    assert out.tolist() == [10.0, 0.0, 5.0, 2.0, 1.5]
    assert sorted(seen) == [0, 1]
    seen.clear()
    errors[2] = 1.2  # now 5 + 3.6 = 8.6 >= 8.5: demo 2 may be re-ranked, so it is checked
    out = cf.masked_gains(None, gains, 0, 1.0, errors=errors)
    assert out.tolist() == [10.0, 0.0, 0.0, 2.0, 1.5]
    assert sorted(seen) == [0, 1, 2]
