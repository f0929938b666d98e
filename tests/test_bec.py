"""cfteach.bec: demonstrations, one-action constraints, counterfactual constraints, gains.

Numbers come from the reference spec (§5.1, §8.1) or from independent brute-force
recomputations (plain per-trajectory rollouts, a literal depth-first enumeration, plain
Region operations)."""

from __future__ import annotations

import numpy as np
import pytest

from cfteach.bec import (
    counterfactual_constraints,
    counterfactual_rows,
    demo_set,
    human_mu,
    human_values,
    knowledge_gains,
    one_action_constraints,
    one_action_rows,
    policy_bec,
    primitive,
)
from cfteach.domains import load
from cfteach.geometry import Region, sample_reference_grid
from cfteach.mdp import tied_actions, value_iteration
from cfteach.mdp.rollout import rollout
from cfteach.teaching.common import nonzero_counts, one_step_sets

DOMAINS = ["delivery", "tiles", "skateboard"]

POLICY_BEC = {
    "delivery": [[1, 1, 0], [0, -1, -4], [-1, 0, 2]],
    "tiles": [[1, -1, -2], [0, 1, -6], [-1, 0, 6]],
    "skateboard": [[8, 1, -2], [0, -2, 1], [-6, 4, -1]],
}
COUNTS = {"delivery": [9480, 1763, 15979], "tiles": [10875, 8927, 21526],
          "skateboard": [2631, 1012, 2328]}
N_DEMOS = {"delivery": 9312, "tiles": 12288, "skateboard": 1964}


def as_set(rows: np.ndarray) -> set[tuple[int, ...]]:
    return {tuple(int(x) for x in r) for r in np.asarray(rows)}


@pytest.mark.parametrize("name", DOMAINS)
@pytest.mark.parametrize("profile", ["reference", "default"])
def test_policy_level_bec_matches_spec(name: str, profile: str) -> None:
    assert as_set(policy_bec(name, profile=profile)) == as_set(POLICY_BEC[name])


@pytest.mark.parametrize("name", DOMAINS)
def test_demo_count_and_masking_counts(name: str) -> None:
    ds = demo_set(load(name), "reference")
    assert ds.D == N_DEMOS[name]
    counts = nonzero_counts(list(one_step_sets(ds).values()), ds.F)
    assert counts.tolist() == COUNTS[name]


def brute_one_action_rows(ds, d: int) -> set[tuple[int, ...]]:  # noqa: ANN001
    """Per-trajectory rollouts with `cfteach.mdp.rollout` (one at a time, real states)."""
    e = int(ds.env[d])
    traj = rollout(ds.batch, ds.policy, e, ds.start_state(d))
    out = set()
    for t in range(len(traj.actions)):
        mu_opt = traj.phi[t:].sum(axis=0)
        for b in range(ds.batch.A):
            if b == traj.actions[t]:
                continue
            dev = rollout(ds.batch, ds.policy, e, traj.states[t], first_action=b)
            row = primitive(np.rint(mu_opt - dev.mu).astype(np.int64)[None])[0]
            if row.any():
                out.add(tuple(int(x) for x in row))
    return out


@pytest.mark.parametrize("name", DOMAINS)
def test_one_action_rows_match_brute_force(name: str) -> None:
    ds = demo_set(load(name), "reference")
    rs = one_action_rows(ds)
    rng = np.random.default_rng(1)
    for d in rng.choice(ds.D, size=12, replace=False):
        assert as_set(rs.of(int(d))) == brute_one_action_rows(ds, int(d))
        # the demo itself is the reference rollout
        traj = rollout(ds.batch, ds.policy, int(ds.env[d]), ds.start_state(int(d)))
        assert [ds.batch.actions[a] for a in traj.actions] == ds.action_names(int(d))
        assert np.array_equal(np.rint(traj.mu), ds.mu[d])


def test_single_demo_api_matches_batch() -> None:
    dom = load("skateboard")
    ds = demo_set(dom, "default")
    d = 100
    e, s = int(ds.env[d]), ds.start_state(d)
    red = one_action_constraints(dom, e, s)
    assert as_set(red) == as_set(Region(brute_list(brute_one_action_rows(ds, d))).reduced())
    inst = ds.instance(d)
    assert as_set(one_action_constraints(dom, e, inst.state_to_json(s))) == as_set(red)
    W = sample_reference_grid(np.array([[0, 0, -1]]), 8)
    joint, _, _ = counterfactual_rows(ds, W)
    single = counterfactual_constraints(dom, e, s, W)
    assert as_set(single) == as_set(Region(joint.of(d)).reduced())
    with pytest.raises(ValueError, match="not a reachable"):
        one_action_constraints(dom, e, (6, 4, 0, 0, 0))


def brute_list(s: set[tuple[int, ...]]) -> np.ndarray:
    return np.array(sorted(s), dtype=np.int64)


@pytest.mark.parametrize("name", DOMAINS)
def test_reference_values_match_value_iteration(name: str) -> None:
    """The shortcut (skip positive-cycle pairs) gives value_iteration's reference answer."""
    dom = load(name)
    ds = demo_set(dom, "reference")
    W = sample_reference_grid(np.array([[0, 0, -1]]), 8)
    ref = value_iteration(ds.batch, W, method="reference")
    bounded, (pe, pm), Q = human_values(ds.batch, W, "reference")
    assert np.array_equal(bounded, ref.bounded)
    valid = ds.batch.valid[pe]
    assert np.array_equal(Q[valid], ref.Q[pe, pm][valid])


def dfs_reference(inst, state, tied_of, w, horizon=25, limit=10):  # noqa: ANN001, ANN201
    """The reference's recursion, literally: record at terminal or depth >= 25; return
    early once more than `limit` are recorded; best true reward, first on exact ties."""
    recorded: list[np.ndarray] = []

    def rec(s, depth, mu):  # noqa: ANN001, ANN202
        if len(recorded) > limit:
            return
        if inst.is_terminal(s) or depth >= horizon:
            recorded.append(mu)
            return
        for a in tied_of(s):
            s2, phi, _ = inst.step(s, a)
            rec(s2, depth + 1, mu + phi)

    rec(state, 0, np.zeros(len(w)))
    vals = [float(np.asarray(w).dot(m)) for m in recorded]
    return recorded[int(np.argmax(vals))], len(recorded)


@pytest.mark.parametrize("name,profile", [("tiles", "reference"), ("skateboard", "default"),
                                          ("delivery", "reference")])
def test_human_trajectories_match_depth_first_enumeration(name: str, profile: str) -> None:
    dom = load(name)
    ds = demo_set(dom, profile)
    W = sample_reference_grid(np.array([[0, 0, -1]]), 8)
    vals = value_iteration(ds.batch, W, method="exact" if profile == "default" else "reference")
    tied = tied_actions(vals.Q)
    mu_ref, bounded = human_mu(ds, W, reference_ties=True)
    mu_dp, _ = human_mu(ds, W, reference_ties=False)
    rng = np.random.default_rng(3)
    e_b, m_b = np.nonzero(bounded)
    big = small = 0
    for i in rng.permutation(len(e_b))[:40]:
        e, m = int(e_b[i]), int(m_b[i])
        inst = ds.batch.instances[e]
        idx = ds.batch.state_index[e]

        def tied_of(s, e=e, m=m, idx=idx):  # noqa: ANN001, ANN202
            return np.flatnonzero(tied[e, m, idx[s]]).tolist()

        for si in rng.choice(ds.batch.n_states[e], size=3, replace=False):
            s = ds.batch.states[e][si]
            best, n = dfs_reference(inst, s, tied_of, dom.weights)
            assert np.array_equal(mu_ref[e, m, si], np.rint(best)), (e, m, s)
            if n <= 10:  # complete enumeration: the DP's best is the same trajectory
                small += 1
                assert np.array_equal(mu_dp[e, m, si], np.rint(best))
            else:
                big += 1
    assert small > 0
    if name == "tiles":
        assert big > 0  # tiles has states with more than 10 tied shortest paths


@pytest.mark.parametrize("name", ["skateboard", "delivery"])
def test_fast_gains_equal_plain_region_ops(name: str) -> None:
    ds = demo_set(load(name), "default")
    W = sample_reference_grid(np.array([[0, 0, -1]]), 8)
    joint, _, _ = counterfactual_rows(ds, W, method="exact", reference_ties=False)
    rng = np.random.default_rng(5)
    for running_rows in ([[0, 0, -1]], POLICY_BEC[name], ds.domain.posterior,
                         np.vstack([ds.domain.prior, [[-1, 1, 0]]]), np.zeros((0, 3), int)):
        running = Region(np.array(running_rows).reshape(-1, 3), dim=3)
        demos = rng.choice(ds.D, size=60, replace=False)
        fast = knowledge_gains(running, joint, demos)
        for g, d in zip(fast, demos, strict=True):
            rows = joint.of(int(d))
            if not len(rows):
                assert g == 0
                continue
            new = Region(np.vstack([running.rows, Region(rows).reduced()]).astype(int))
            if new.area() == 0:
                assert g == 0  # contradicting constraints are never worth showing
                continue
            assert g == pytest.approx(running.area() / new.area(), rel=1e-12)


@pytest.mark.parametrize("name", DOMAINS)
def test_reference_values_match_for_random_models(name: str) -> None:
    """Also for models from smaller beliefs (later rounds), incl. cheap-no-op models whose
    reference sweeps hit the 1000 cap."""
    dom = load(name)
    ds = demo_set(dom, "reference")
    rng = np.random.default_rng(11)
    W = np.vstack([Region(dom.posterior).sample(6, rng), Region(dom.prior).sample(4, rng),
                   [[-0.00124, -0.788, -0.616], [-0.999, -0.003, -0.0016]]])
    ref = value_iteration(ds.batch, W, method="reference")
    bounded, (pe, pm), Q = human_values(ds.batch, W, "reference")
    assert np.array_equal(bounded, ref.bounded)
    valid = ds.batch.valid[pe]
    assert np.array_equal(Q[valid], ref.Q[pe, pm][valid])


@pytest.mark.parametrize("name", DOMAINS)
def test_loop_rows_match_brute_force_and_hold_for_true_weights(name: str) -> None:
    from cfteach.bec import loop_rows

    dom = load(name)
    ds = demo_set(dom, "default")
    rng = np.random.default_rng(8)
    W = np.vstack([Region(np.zeros((0, 3), int), dim=3).sample(6, rng), [[0.3, 0.4, -0.5]]])
    vals = value_iteration(ds.batch, W, method="exact")
    ue, um = np.nonzero(~vals.bounded)
    assert len(ue) > 0
    pick = rng.choice(len(ue), size=min(6, len(ue)), replace=False)
    got = loop_rows(ds.batch, W, ue[pick], um[pick])
    for rows, i in zip(got, pick, strict=True):
        e, m = int(ue[i]), int(um[i])
        inst = ds.batch.instances[e]
        want = set()
        for s in inst.states():
            for a in range(len(dom.actions)):
                s2, phi, t = inst.step(s, a)
                if t:
                    continue
                if s2 == s:
                    if W[m] @ phi > 0:
                        want.add(tuple(primitive(-np.rint(phi).astype(int)[None])[0]))
                    continue
                for b in range(len(dom.actions)):
                    s3, phi2, t2 = inst.step(s2, b)
                    if not t2 and s3 == s and W[m] @ (phi + phi2) > 0:
                        row = primitive(-np.rint(phi + phi2).astype(int)[None])[0]
                        want.add(tuple(row))
        want.discard((0, 0, 0))
        assert as_set(rows) == want, (e, m)
        assert np.all(rows @ dom.weights >= -1e-12)  # the true weights make no loop pay


def test_reduce_sets_does_not_estimate_areas(monkeypatch: pytest.MonkeyPatch) -> None:
    """Callers of reduce_sets only need rows; for > 3 features an area is a Monte Carlo
    estimate, so none may be computed (reduce_and_measure still measures)."""
    from cfteach.bec.rows import group_rows, reduce_and_measure, reduce_sets
    from cfteach.geometry import _highdim, clear_cache

    calls = []
    real = _highdim.area_nd
    monkeypatch.setattr(_highdim, "area_nd", lambda *a, **k: calls.append(1) or real(*a, **k))
    clear_cache()
    rows = np.array([[1, 0, 0, 0], [0, 1, 0, 0], [1, 1, 0, 0], [0, 0, 1, 1], [1, 2, 3, 1]])
    rs = group_rows(rows, np.array([0, 0, 0, 1, 1]), 2)
    red = reduce_sets(rs)
    assert red[0].tolist() == [[0, 1, 0, 0], [1, 0, 0, 0]] and calls == []
    _, areas = reduce_and_measure(rs)
    assert len(calls) > 0 and np.all(areas > 0)


def test_gains_beyond_three_features_match_the_embedded_exact_gains() -> None:
    """A 3-feature problem embedded in 5 features has the same gains; the 5-feature ones are
    estimates on one shared sample, within their stated error, and a demo's gain does not
    depend on which other demos are asked with it (chunks across workers)."""
    from cfteach.bec.gain import gain_estimates
    from cfteach.bec.rows import group_rows

    rng = np.random.default_rng(3)
    w = np.array([0.3, -0.5, -0.8])
    rows, demo = [], []
    for d in range(40):
        c = rng.integers(-4, 5, size=(int(rng.integers(0, 4)), 3))
        s = np.sign(c @ w).astype(np.int64)
        s[s == 0] = 1
        rows.append(c * s[:, None])
        demo += [d] * len(c)
    r3 = np.vstack(rows)
    belief3 = Region([[0, 0, -1], [0, -1, 0]])
    exact = knowledge_gains(belief3, group_rows(r3, np.array(demo), 40))
    r5 = np.hstack([r3, np.zeros((len(r3), 2), dtype=np.int64)])
    rs5 = group_rows(r5, np.array(demo), 40)
    belief5 = Region([[0, 0, -1, 0, 0], [0, -1, 0, 0, 0]])
    g, se = gain_estimates(belief5, rs5)
    assert np.all(np.abs(g - exact) <= 5 * se + 1e-12)
    assert np.all((se == 0) == (exact <= 1))  # no cut, no error; every real cut measured
    assert np.any(exact > 1.5)
    part = np.array([31, 2, 17, 5])
    assert knowledge_gains(belief5, rs5, part).tolist() == g[part].tolist()


def test_refine_top_measures_the_contenders_on_their_own() -> None:
    """Small intersections (gains near 100) are known to a few percent on the shared sample;
    the contenders for the top get samples of their own and land within 2.5% of the exact
    (embedded 3-feature) gains; the rest keep their shared estimates; exact gains pass
    through unchanged."""
    from cfteach.bec.gain import gain_estimates, refine_top
    from cfteach.bec.rows import group_rows

    wedges = [[[1, 0, 0], [-k, 0, 1], [0, 1, 0], [0, -m, 1]]
              for k, m in [(5, 5), (5, 6), (6, 5), (2, 2), (1, 1)]]
    r3 = np.vstack(wedges)
    demo = np.repeat(np.arange(5), 4)
    belief3 = Region([[0, 0, 1]])
    exact = knowledge_gains(belief3, group_rows(r3, demo, 5))
    assert refine_top(belief3, group_rows(r3, demo, 5), exact, np.zeros(5)) is exact
    rs5 = group_rows(np.hstack([r3, np.zeros((len(r3), 2), dtype=np.int64)]), demo, 5)
    belief5 = Region([[0, 0, 1, 0, 0]])
    g, se = gain_estimates(belief5, rs5)
    top = refine_top(belief5, rs5, g, se)
    assert np.all(np.abs(top[:3] - exact[:3]) <= 0.025 * exact[:3])
    assert top[3:].tolist() == g[3:].tolist()
    assert exact[1] == pytest.approx(exact[2]) and exact[1] > 1.15 * exact[0]
    assert int(np.argmax(top)) in (1, 2)


def test_teaching_with_four_features_is_reproducible_from_the_seed() -> None:
    """Estimated gains (shared sample, refinement) are pure functions of the seed: a fresh
    process state (caches cleared) gives the same curriculum, gains and belief bits."""
    from cfteach.domains.random import random_gridworld
    from cfteach.geometry import clear_cache
    from cfteach.teaching import teach

    dom = random_gridworld(6, 6, 4, 16, 3)
    runs = []
    for _ in range(2):
        clear_cache()
        cur = teach(dom, "proposed", seed=0)
        runs.append([(r.demo, r.knowledge_gain, r.belief_area_after) for r in cur.records])
    assert runs[0] == runs[1] and len(runs[0]) >= 1
    assert any(g > 1 and g != int(g) for _, g, _ in runs[0])
