"""Answers weighed by what was taught since (confusion "since"): an answer `k`
demonstrations back keeps the particle's own weights with chance ``(1 - u) ** k``."""

from __future__ import annotations

import math

import numpy as np
import pytest

from cfteach import teaching
from cfteach.closedloop import TeacherSettings, build_pool
from cfteach.closedloop.noisy_belief import NoisyBelief
from cfteach.closedloop.since import demos_after, log_shares, share
from cfteach.closedloop.steps import answer_steps
from cfteach.domains import load
from closedloop_fixtures import two_particles, walk


@pytest.fixture(scope="module")
def skate():
    cur = teaching.teach("skateboard", "proposed")
    tests = teaching.select_tests("skateboard", training=[cur], per_level=2)
    return build_pool("skateboard", human_models=16, held_out=tests)


def test_demonstrations_after_each_answer_are_counted():
    kinds = ["steps", "demonstration", "outcome", "demonstration", "demonstration", "steps"]
    steps, outcomes = demos_after([{"kind": k} for k in kinds])
    assert steps.tolist() == [3, 0] and outcomes.tolist() == [2]


def test_the_kept_share_is_one_minus_uptake_to_the_k():
    u, k = np.array([0.2, 0.6, 0.95]), np.array([0.0, 1.0, 3.0, 400.0])
    log_keep, log_c = log_shares("since", u, np.zeros(3), k)
    for p in range(3):
        for j in range(4):
            keep = (1 - u[p]) ** k[j]
            assert math.exp(log_keep[p, j]) == pytest.approx(keep, rel=1e-12, abs=0)
            if k[j]:
                assert math.exp(log_c[p, j]) == pytest.approx(1 - keep, rel=1e-12)
                assert share("since", u, np.zeros(3), k[j])[p, 0] == pytest.approx(1 - keep)
    assert np.all(np.isneginf(log_c[:, 0])) and np.all(np.isfinite(log_keep))
    # model "grid": the grid value whatever k
    grid = log_shares("grid", u, np.array([0.0, 0.25, 0.5]), k)
    assert np.allclose(np.exp(grid[1]), [[0.0], [0.25], [0.5]])
    assert share("grid", u, np.array([0.0, 0.25, 0.5]), 7.0).ravel().tolist() == [0, 0.25, 0.5]


def test_an_answer_fades_as_demonstrations_follow_it(skate):
    """Two fixed particles, no resampling: after an answer and then two demonstrations the
    weights are the posterior written out by hand, the answer's engaged likelihood being
    ``(1 - u)^2 pi_w + (1 - (1 - u)^2) pi_then`` and each demonstration's ``u 1[C w >= 0] +
    1 - u``; before the demonstrations the answer counts with the particle's own weights
    alone."""
    ds = skate.ds
    d = next(iter(sorted(skate.held_out)))
    e = int(ds.env[d])
    states, acts = walk(ds, d, ["up", "down", *ds.action_names(d)])
    w = two_particles()
    belief = NoisyBelief(load("skateboard").prior, 3, particles=w, lapse=0.02, resample=False,
                         rationality=(7.0, 40.0), uptake=(0.3, 0.8), disengaged=(0.1, 0.3),
                         confusion="since")
    belief.idx.update(beta=np.array([0, 1]), uptake=np.array([1, 0]),
                      disengaged=np.array([1, 0]))
    data = answer_steps(ds, e, states, acts)
    belief.observe_steps(data)
    entry = belief.history[-1]
    own = belief._answers_policy(belief._parts(w), np.array([7.0, 40.0]))[:, 0]
    rand = -len(acts) * math.log(ds.batch.A)
    lam, u = np.array([0.3, 0.1]), np.array([0.8, 0.3])
    fresh = np.log((1 - lam) * np.exp(own) + lam * math.exp(rand))
    np.testing.assert_allclose(belief.log_weights, fresh - np.logaddexp.reduce(fresh),
                               rtol=1e-9)
    rows = np.array([[1.0, -1.0, 0.0]])  # particle 0 satisfies it, particle 1 does not
    assert (w @ rows.T).ravel().tolist()[0] >= 0 > (w @ rows.T).ravel().tolist()[1]
    belief.observe_demonstration(rows)
    belief.observe_demonstration(np.zeros((0, 3)))
    keep = (1 - u) ** 2
    then = entry["confused_ll"][[0, 1]]  # the belief's likelihood per rationality, then
    engaged = keep * np.exp(own) + (1 - keep) * np.exp(then)
    want = (np.log((1 - lam) * engaged + lam * math.exp(rand))
            + np.log(np.where([True, False], 1.0, 1 - u)))
    np.testing.assert_allclose(belief.log_weights, want - np.logaddexp.reduce(want),
                               rtol=1e-9)
    # the reference points (behind expected_area) are scored by the same posterior
    again = belief._posterior_from(belief._parts(belief.reference), belief.ref_idx)
    np.testing.assert_allclose(belief.reference_loglik, again, rtol=1e-12)


def test_weights_after_resampling_are_the_posterior_over_the_one_drawn_at(skate):
    """With resample-move on, the particles' weights always equal the current posterior
    over the one they were drawn at (recomputed here from the whole history)."""
    from cfteach.closedloop import ClosedLoopTeacher
    from cfteach.simulate.closed_loop import run_session
    from cfteach.simulate.learners import Learners

    t = ClosedLoopTeacher(skate, TeacherSettings(n_particles=200, max_items=14), seed=3)
    run_session(t, Learners(skate.domain, "noisy", 1, rng=5))
    b = t.belief
    assert b.confusion == "since" and b.n_resamples >= 1
    lw = b.log_posterior(b.particles) - b._base
    np.testing.assert_allclose(b.log_weights, lw - np.logaddexp.reduce(lw), atol=1e-8)


def test_a_bad_confusion_model_is_refused():
    with pytest.raises(ValueError, match="confusion must be one of since, grid"):
        TeacherSettings(confusion="sometimes")
    with pytest.raises(ValueError, match="confusion must be one of since, grid"):
        NoisyBelief(load("delivery").prior, 3, n_particles=10, confusion="sometimes")


def test_a_study_file_without_the_model_keeps_the_grid():
    from cfteach.study.live import settings_of

    stored = TeacherSettings().to_json()
    assert settings_of({"settings": stored}).confusion == "since"
    del stored["confusion"]
    assert settings_of({"settings": stored}).confusion == "grid"
