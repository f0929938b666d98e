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


def _check_all(joint, gains_all, feature, proportion, executor=None):
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

    def counting_masked(joint, gains_all, feature, proportion, executor=None):
        checked.append(0)
        live.append(int(np.count_nonzero(gains_all > 1)))
        return real_masked(joint, gains_all, feature, proportion, executor)

    monkeypatch.setattr(cf, "blocked", counting_blocked)
    monkeypatch.setattr(cf, "masked_gains", counting_masked)
    demo_set(dom, "default").cache.clear()
    teach(dom, "proposed", profile="default", seed=0)
    assert live and sum(checked) < sum(live) / 2, (checked, live)
