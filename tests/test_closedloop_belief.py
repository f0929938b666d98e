"""ParticleBelief: its updates equal a brute-force Bayesian update written out here from the
likelihood formulas, its resample-move keeps the posterior, its area/entropy match exact
region areas, and it is deterministic and picklable."""

from __future__ import annotations

import math
import pickle

import matplotlib
import numpy as np
import pytest

from cfteach.closedloop.belief import ParticleBelief
from cfteach.closedloop.noisy_belief import NoisyBelief
from cfteach.closedloop.steps import StepData
from cfteach.domains import load
from cfteach.geometry import Region
from cfteach.geometry.region import sphere_area

matplotlib.use("Agg")

DELIVERY = load("delivery")
PRIOR = DELIVERY.prior  # [[0, 0, -1]]: the lower hemisphere
W_STAR = DELIVERY.weights / np.linalg.norm(DELIVERY.weights)

# Candidate answers' feature counts (toll, hotswap, step), as a test's trajectories give them.
MU_OPT = [0.0, 1.0, 6.0]
MU_WRONG = [1.0, 0.0, 3.0]
ALTS = [[0.0, 0.0, 4.0], [1.0, 1.0, 5.0], [0.0, 1.0, 6.0]]  # the last repeats MU_OPT


def fibonacci_sphere(n: int) -> list[tuple[float, float, float]]:
    """n nearly evenly spread unit vectors (the golden-angle spiral)."""
    golden = math.pi * (3.0 - math.sqrt(5.0))
    out = []
    for i in range(n):
        z = 1.0 - (2.0 * i + 1.0) / n
        r = math.sqrt(1.0 - z * z)
        out.append((r * math.cos(golden * i), r * math.sin(golden * i), z))
    return out


def prior_grid(n: int) -> list[tuple[float, float, float]]:
    """The grid points inside the delivery prior (-w_step >= 0)."""
    return [g for g in fibonacci_sphere(n) if -g[2] >= -1e-12]


def dot(a, b) -> float:
    return sum(x * y for x, y in zip(a, b, strict=True))


def brute_posterior(grid, observations, p_learn, temperature) -> list[float]:
    """Normalised posterior weights on the grid from the likelihood formulas, point by point.

    observations: ("demo", rows) or ("answer", candidates, target, complement) with the
    candidate list already free of duplicates."""
    weights = []
    for g in grid:
        like = 1.0
        for obs in observations:
            if obs[0] == "demo":
                ok = all(dot(c, g) >= -1e-12 for c in obs[1])
                like *= p_learn * (1.0 if ok else 0.0) + (1.0 - p_learn)
            else:
                _, cands, target, complement = obs
                expo = [math.exp(dot(g, mu) / temperature) for mu in cands]
                p_target = expo[target] / sum(expo)
                like *= (1.0 - p_target) if complement else p_target
        weights.append(like)
    total = sum(weights)
    return [w / total for w in weights]


def grid_posterior(grid: np.ndarray, observations, p_learn, temperature) -> np.ndarray:
    """brute_posterior vectorised over the grid (for fine grids)."""
    loglik = np.zeros(len(grid))
    for obs in observations:
        if obs[0] == "demo":
            ok = np.all(grid @ np.array(obs[1], dtype=float).T >= -1e-12, axis=1)
            loglik += np.log(p_learn * ok + (1.0 - p_learn))
        else:
            _, cands, target, complement = obs
            logits = grid @ np.array(cands, dtype=float).T / temperature
            top = logits.max(axis=1, keepdims=True)
            p_target = np.exp(logits[:, target] - top[:, 0]) / np.exp(logits - top).sum(axis=1)
            loglik += np.log((1.0 - p_target) if complement else p_target)
    w = np.exp(loglik - loglik.max())
    return w / w.sum()


def feed(belief: ParticleBelief) -> list[tuple]:
    """A demonstration, a correct, a wrong and an unfinished answer; returns the same
    observations in brute_posterior's form (candidates de-duplicated by hand)."""
    demo = [[-1, 0, 0], [0, 1, 0]]
    belief.observe_demonstration(np.array(demo))
    belief.observe_answer(MU_OPT, MU_OPT, ALTS)  # correct (answer equals the optimum)
    belief.observe_answer(MU_OPT, MU_WRONG, ALTS)  # finished, wrong
    belief.observe_answer(MU_OPT, None, ALTS, finished=False)
    distinct = [MU_OPT, ALTS[0], ALTS[1]]
    with_wrong = [MU_OPT, MU_WRONG, ALTS[0], ALTS[1]]
    return [("demo", demo), ("answer", distinct, 0, False), ("answer", with_wrong, 1, False),
            ("answer", distinct, 0, True)]


def test_update_equals_brute_force_bayes_on_a_grid():
    grid = prior_grid(3000)
    belief = ParticleBelief(PRIOR, 3, particles=np.array(grid), resample=False, n_reference=50)
    observations = feed(belief)
    expected = brute_posterior(grid, observations, 0.8, 0.5)
    assert belief.n_resamples == 0 and len(belief.history) == 4
    np.testing.assert_allclose(belief.particles, np.array(grid), rtol=0, atol=1e-15)
    np.testing.assert_allclose(belief.weights, expected, rtol=1e-9, atol=0)
    assert math.isclose(float(np.exp(belief.log_weights).sum()), 1.0, rel_tol=1e-12)
    # The observations really moved the belief (so the comparison is not trivially uniform).
    assert max(expected) / min(expected) > 10


def test_each_answer_kind_matches_its_own_formula():
    grid = prior_grid(400)
    for temperature in (0.5, 2.0):
        b = ParticleBelief(PRIOR, 3, particles=np.array(grid), resample=False,
                           temperature=temperature, n_reference=50)
        b.observe_answer(MU_OPT, MU_WRONG, ALTS, correct=False)
        expected = brute_posterior(grid, [("answer", [MU_OPT, MU_WRONG, ALTS[0], ALTS[1]], 1,
                                           False)], 0.8, temperature)
        np.testing.assert_allclose(b.weights, expected, rtol=1e-9)


def test_large_logits_stay_finite():
    """|w . mu| / T of several thousand: the log-space update neither overflows nor gives
    NaN, and the unfinished answer's 1 - P(mu*) keeps its (tiny) ordering."""
    grid = np.array(prior_grid(500))
    b = ParticleBelief(PRIOR, 3, particles=grid, resample=False, temperature=0.01,
                       n_reference=50)
    b.observe_answer([0, 0, -40], None, [[0, 0, -39], [40, 0, 0]], finished=False)
    b.observe_answer([0, 0, -40], [0, 0, -40], [[40, 0, 0]])
    assert np.all(np.isfinite(b.log_weights)) and np.all(np.isfinite(b.reference_loglik))
    assert math.isclose(b.weights.sum(), 1.0, rel_tol=1e-12)


def grid_expectations(grid, weights, region_rows):
    g = np.array(grid)
    w = np.array(weights)
    inside = np.all(g @ np.array(region_rows, dtype=float).T >= -1e-12, axis=1)
    mean = w @ g
    sd = np.sqrt(np.maximum(w @ (g - mean) ** 2, 0))
    return mean, sd, float(w[inside].sum())


def test_resample_move_keeps_the_posterior():
    """Demonstrations that cut the belief, and answers, twice over: several resample-moves;
    the weighted particles still estimate the exact posterior (on a fine grid)."""
    cuts = [[[-1, 0, 0]], [[0, 1, 0]], [[0, 1, 1]], [[0, 1, 3]], [[1, 1, 0]]]  # all hold at w*
    distinct = [MU_OPT, ALTS[0], ALTS[1]]
    n, p_learn = 2000, 0.9
    belief = ParticleBelief(PRIOR, 3, n_particles=n, seed=3, p_learn=p_learn)
    observations: list[tuple] = []
    for _ in range(2):
        for rows in cuts:
            belief.observe_demonstration(np.array(rows))
            observations.append(("demo", rows))
            check_particles(belief)
        belief.observe_answer(MU_OPT, MU_WRONG, ALTS)
        belief.observe_answer(MU_OPT, MU_OPT, ALTS)
        belief.observe_answer(MU_OPT, None, ALTS, finished=False)
        observations += [("answer", [MU_OPT, MU_WRONG, ALTS[0], ALTS[1]], 1, False),
                         ("answer", distinct, 0, False), ("answer", distinct, 0, True)]
        check_particles(belief)
    assert belief.n_resamples >= 3
    grid = np.array(prior_grid(400_000))
    small = prior_grid(1000)  # the vectorised reference agrees with the loop
    np.testing.assert_allclose(grid_posterior(np.array(small), observations, p_learn, 0.5),
                               brute_posterior(small, observations, p_learn, 0.5), rtol=1e-9)
    region = [[0, 1, 4]]  # a test question the belief is unsure about
    mean, sd, p_region = grid_expectations(grid, grid_posterior(grid, observations, p_learn, 0.5),
                                           region)
    assert 0.2 < p_region < 0.8
    # Monte-Carlo allowance: 5 standard errors with a quarter of the particles effective
    # (resampled particles are correlated; over 40 seeds the error's rms was <= 1.9
    # standard errors of n independent draws).
    n_eff = n / 4
    got_mean = belief.weights @ belief.particles
    assert np.all(np.abs(got_mean - mean) < 5 * sd / math.sqrt(n_eff)), (got_mean, mean)
    se_p = math.sqrt(p_region * (1 - p_region) / n_eff)
    assert abs(belief.p_optimal(np.array(region)) - p_region) < 5 * se_p
    # The comparison can fail: the posterior is far from the prior it started from.
    prior_mean = np.array([0.0, 0.0, -0.5])
    assert np.linalg.norm(mean - prior_mean) > 20 * np.max(sd) / math.sqrt(n_eff)


def test_resample_move_moves_particles_by_the_spread():
    """After resampling, MH moves give fresh points (not only copies of the old ones), and
    the proposal scale shrinks as the belief concentrates."""
    b = ParticleBelief(PRIOR, 3, n_particles=1000, seed=5, p_learn=0.999)
    before = {tuple(p) for p in b.particles.tolist()}
    b.observe_demonstration(np.array([[0, 1, 3]]))  # cuts most of the hemisphere
    assert b.n_resamples == 1 and 0.0 < b.acceptance < 1.0
    fresh = sum(tuple(p) not in before for p in b.particles.tolist())
    assert fresh > 0.3 * len(b.particles)
    broad = b.step_size
    for rows in ([[-1, 0, 0]], [[0, 1, 0]], [[1, 1, 0]], [[-3, -1, 0]], [[0, -1, -4]]):
        b.observe_demonstration(np.array(rows))  # down to a region of 0.03 sr around w*
    assert b.n_resamples >= 3
    assert b.step_size < 0.5 * broad
    check_particles(b)


def check_particles(belief: ParticleBelief) -> None:
    assert np.allclose(np.linalg.norm(belief.particles, axis=1), 1.0, atol=1e-12)
    assert Region(PRIOR).contains(belief.particles).all()


def test_expected_area_starts_at_the_prior_area_and_follows_a_hard_demonstration():
    b = ParticleBelief(PRIOR, 3, n_particles=200, n_reference=20000, p_learn=1 - 1e-9)
    assert math.isclose(b.expected_area(), Region(PRIOR).area(), rel_tol=1e-9)
    assert math.isclose(b.entropy(), math.log(b.expected_area()), rel_tol=1e-12)
    demo = np.array([[-1, 0, 0], [0, 1, 0], [-1, 2, 1]])
    b.observe_demonstration(demo)
    exact = Region(np.vstack([PRIOR, demo])).area()
    assert exact < 0.3 * Region(PRIOR).area()
    assert abs(b.expected_area() - exact) < 0.04 * exact
    assert math.isclose(b.entropy(), math.log(b.expected_area()), rel_tol=1e-12)


def test_expected_area_of_an_empty_prior_in_four_features():
    b = ParticleBelief(np.zeros((0, 4)), 4, n_particles=50, n_reference=500)
    assert math.isclose(b.expected_area(), sphere_area(4), rel_tol=1e-9)
    b.observe_demonstration(np.array([[1.0, 0, 0, 0]]))
    assert b.expected_area() < sphere_area(4)


def test_p_optimal_counts_the_weight_inside():
    b = ParticleBelief(PRIOR, 3, n_particles=500, seed=7, resample=False)
    feed(b)
    tests = [np.array([[-1, 1, 0]]), np.array([[-1, 0, 0], [0, 1, -1]]), np.zeros((0, 3))]
    for rows in tests:
        direct = 0.0
        for p, w in zip(b.particles.tolist(), b.weights.tolist(), strict=True):
            if all(dot(r, p) >= -1e-12 for r in rows.tolist()):
                direct += w
        assert math.isclose(b.p_optimal(rows), direct, rel_tol=1e-12, abs_tol=1e-15)
        assert math.isclose(b.violation_mass(rows), 1.0 - direct, rel_tol=1e-9, abs_tol=1e-12)
    np.testing.assert_allclose(b.p_optimal_many(tests), [b.p_optimal(r) for r in tests],
                               rtol=1e-12)
    assert b.p_optimal_many([]).shape == (0,)
    assert 0.0 < b.p_optimal(tests[0]) < 1.0


def test_a_violating_particle_keeps_a_fifth_of_the_weight():
    inside, outside = [-0.6, 0.7, -0.3], [0.6, 0.7, -0.3]
    b = ParticleBelief(PRIOR, 3, particles=np.array([inside, outside]), p_learn=0.8,
                       n_reference=50)
    b.observe_demonstration(np.array([[-1, 0, 0]]))
    assert b.n_resamples == 0  # ESS 1.47 of 2 >= 1: no resampling yet
    w_in, w_out = b.weights
    assert math.isclose(w_out / w_in, 0.2 / 1.0, rel_tol=1e-12)


def observe_all(b: ParticleBelief) -> None:
    for _ in range(3):
        feed(b)


def test_same_seed_and_observations_give_the_same_state():
    a = ParticleBelief(PRIOR, 3, n_particles=300, seed=11)
    b = ParticleBelief(PRIOR, 3, n_particles=300, seed=11)
    observe_all(a)
    observe_all(b)
    assert a.n_resamples >= 1
    assert_same_state(a.state_dict(), b.state_dict())
    # A pickled copy, a copy(), and a replay of the history all continue identically.
    c = pickle.loads(pickle.dumps(a))
    d = a.copy()
    e = ParticleBelief(PRIOR, 3, n_particles=300, seed=11)
    for entry in a.history:
        e.observe(entry)
    assert_same_state(e.state_dict(), a.state_dict())
    for x in (a, c, d):
        x.observe_demonstration(np.array([[0, 1, 0]]))
    assert_same_state(a.state_dict(), c.state_dict())
    assert_same_state(a.state_dict(), d.state_dict())
    assert len(b.history) == len(a.history) - 1  # copies do not share state


def test_a_noisy_belief_copy_is_a_noisy_belief_that_continues_identically():
    """copy() keeps the class: a NoisyBelief's what-if copy scores answers by its per-step
    model (a ParticleBelief would not even have `observe_steps`)."""
    rng = np.random.default_rng(5)
    a = NoisyBelief(PRIOR, 3, n_particles=300, seed=4, n_reference=200)
    answer = StepData(rng.normal(size=(6, 4, 3)), counts=rng.integers(0, 3, size=(6, 4)))
    a.observe_demonstration(np.array([[1, 0, 0]]))
    d = a.copy()
    assert type(d) is NoisyBelief
    for x in (a, d):
        x.observe_steps(answer)
    assert_same_state(a.state_dict(), d.state_dict())
    d.observe_demonstration(np.array([[0, 1, 0]]))
    assert len(d.history) == len(a.history) + 1  # the original did not see it
    assert not np.array_equal(a.log_weights, d.log_weights)


def test_a_different_seed_gives_different_particles():
    a = ParticleBelief(PRIOR, 3, n_particles=300, seed=11)
    b = ParticleBelief(PRIOR, 3, n_particles=300, seed=12)
    assert not np.array_equal(a.particles, b.particles)
    assert not np.array_equal(a.reference, b.reference)


def assert_same_state(x: object, y: object, where: str = "state") -> None:
    """Equal, key by key and item by item, arrays exactly (a NoisyBelief's state holds
    dicts of arrays: its grids and each particle's grid indices)."""
    if isinstance(x, dict):
        assert isinstance(y, dict) and x.keys() == y.keys(), where
        for key in x:
            assert_same_state(x[key], y[key], f"{where}.{key}")
    elif isinstance(x, list):
        assert isinstance(y, list) and len(x) == len(y), where
        for i, (ex, ey) in enumerate(zip(x, y, strict=True)):
            assert_same_state(ex, ey, f"{where}[{i}]")
    elif isinstance(x, np.ndarray):
        np.testing.assert_array_equal(x, y, err_msg=where)
    else:
        assert x == y, where


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"p_learn": 0.0}, "p_learn"),
        ({"p_learn": 1.0}, "p_learn"),
        ({"temperature": 0.0}, "temperature"),
        ({"temperature": -1.0}, "temperature"),
        ({"n_particles": 0}, "n_particles"),
        ({"particles": np.array([[0.0, 0.0, 1.0]])}, "particles"),  # outside the prior
        ({"particles": np.zeros((3, 4))}, "particles"),
    ],
)
def test_bad_constructor_arguments_are_named(kwargs, name):
    with pytest.raises(ValueError, match=name):
        ParticleBelief(PRIOR, 3, **kwargs)


def test_bad_prior_and_observation_shapes_are_named():
    with pytest.raises(ValueError, match="prior"):
        ParticleBelief(np.array([[0, 0, -1, 0]]), 3)
    with pytest.raises(ValueError, match="prior"):
        ParticleBelief(np.array([[0, 0, -1], [0, 0, 1]]), 3)  # empty region
    b = ParticleBelief(PRIOR, 3, n_particles=20, n_reference=20)
    with pytest.raises(ValueError, match="constraints"):
        b.observe_demonstration(np.array([[1, 0, 0, 0]]))
    with pytest.raises(ValueError, match="constraints"):
        b.p_optimal(np.array([[1, 0]]))
    with pytest.raises(ValueError, match="optimal_mu"):
        b.observe_answer([1, 2], [1, 2, 3], ALTS)
    with pytest.raises(ValueError, match="alternatives"):
        b.observe_answer(MU_OPT, MU_WRONG, [[1, 2]])
    with pytest.raises(ValueError, match="alternatives"):
        b.observe_answer(MU_OPT, None, [MU_OPT], finished=False)  # 1 - P(mu*) would be 0
    with pytest.raises(ValueError, match="answer_mu"):
        b.observe_answer(MU_OPT, None, ALTS)
    assert b.history == []  # rejected observations leave no trace


def test_plot_particles_sphere():
    from cfteach.render.belief import plot_particles_sphere

    b = ParticleBelief(PRIOR, 3, n_particles=200, resample=False)
    feed(b)
    fig = plot_particles_sphere(b.particles, b.weights, w_true=W_STAR, prior=PRIOR,
                                feature_names=DELIVERY.feature_names, title="belief")
    assert isinstance(fig, matplotlib.figure.Figure)
    ax = fig.axes[0]
    dots = [c for c in ax.collections if type(c).__name__ == "Path3DCollection"]
    assert dots  # the particles (and the star) were drawn
    matplotlib.pyplot.close(fig)
    with pytest.raises(ValueError, match="3 features"):
        plot_particles_sphere(np.ones((5, 4)), np.full(5, 0.2))
    with pytest.raises(ValueError, match="weights"):
        plot_particles_sphere(b.particles, b.weights[:-1])


def test_doc_example_runs(tmp_path):
    from doc_examples import code_blocks, run_script

    blocks = code_blocks("closed-loop.md")
    example = [b for b in blocks if "ParticleBelief(" in b]
    assert len(example) == 1
    done = run_script(example[0], tmp_path)
    assert "P(optimal on a test)" in done.stdout and "expected area" in done.stdout
