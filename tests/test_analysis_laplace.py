"""The GLMM's structured algebra against dense numpy, and its beta gradient against finite
differences of the Laplace deviance (checks that need no R)."""

from __future__ import annotations

import numpy as np
import pytest

from cfteach.analysis import laplace


def _data(seed: int = 0) -> laplace.Data:
    rng = np.random.default_rng(seed)
    n, n0, n1, n2 = 300, 30, 8, 3
    codes = [rng.integers(0, n0, n), rng.integers(0, n1, n), rng.integers(0, n2, n)]
    codes = [np.r_[np.arange(k), c[k:]] for k, c in zip((n0, n1, n2), codes, strict=True)]
    x = np.column_stack([np.ones(n), rng.normal(size=n), rng.integers(0, 2, n) - 0.5])
    eta = x @ [0.3, 0.8, -0.5] + 0.7 * rng.normal(size=n0)[codes[0]]
    y = (rng.random(n) < 1 / (1 + np.exp(-eta))).astype(float)
    return laplace.Data(y, x, codes)


def _dense_m(data: laplace.Data, theta: np.ndarray) -> np.ndarray:
    blocks = []
    for t, c in zip(theta, data.codes, strict=True):
        z = np.zeros((len(c), int(c.max()) + 1))
        z[np.arange(len(c)), c] = t
        blocks.append(z)
    return np.hstack(blocks)


def test_factor_matches_dense_algebra() -> None:
    data = _data()
    theta = np.array([0.9, 0.4, 0.2])
    w = np.random.default_rng(1).uniform(0.05, 0.25, len(data.y))
    fac = laplace._Factor(data, theta, w)
    m = _dense_m(data, theta)
    h = m.T @ (w[:, None] * m) + np.eye(m.shape[1])
    assert fac.logdet == pytest.approx(np.linalg.slogdet(h)[1], rel=1e-12)
    r = np.random.default_rng(2).normal(size=m.shape[1])
    x0, xr = fac.solve(r[: data.n0], r[data.n0 :])
    assert np.r_[x0, xr] == pytest.approx(np.linalg.solve(h, r), rel=1e-10, abs=1e-12)
    lev = np.einsum("ij,ji->i", m, np.linalg.solve(h, m.T))
    assert fac.leverage() == pytest.approx(lev, rel=1e-10, abs=1e-12)
    g = np.random.default_rng(3).normal(size=(len(data.y), 2))
    g0, gr = fac.mt(g)
    assert np.vstack([g0, gr]) == pytest.approx(m.T @ g, rel=1e-12, abs=1e-12)


@pytest.mark.parametrize("theta", [np.array([0.8, 0.3, 0.1]), np.array([1.2, 0.0, 0.5])])
def test_beta_gradient_is_the_laplace_deviance_gradient(theta: np.ndarray) -> None:
    data = _data(4)
    beta = np.array([0.2, 0.5, -0.3])
    st = laplace._State(beta, np.zeros(data.n0), np.zeros(data.qr))
    _, fac, mu = laplace.pirls(data, theta, beta, st)
    grad, _ = laplace.beta_gradient(data, fac, mu, beta, nagq=1)
    h = 1e-5
    fd = []
    for j in range(len(beta)):
        e = np.zeros(len(beta))
        e[j] = h
        up = laplace.deviance_at(data, theta, beta + e, laplace._State(beta, st.u0, st.ur))
        dn = laplace.deviance_at(data, theta, beta - e, laplace._State(beta, st.u0, st.ur))
        fd.append((up - dn) / (2 * h))
    assert grad == pytest.approx(np.array(fd), rel=1e-5, abs=1e-5)


def test_fit_is_a_minimum_and_reaches_zero_variance() -> None:
    data = _data(5)
    fit = laplace.fit(data)
    assert fit["converged"]
    # the third factor has no variance planted: its SD may sit at the boundary 0
    assert fit["theta"][2] < 0.3
    st = laplace._State(fit["beta"], np.zeros(data.n0), np.zeros(data.qr))
    best = laplace.deviance_at(data, fit["theta"], fit["beta"], st)
    rng = np.random.default_rng(6)
    for _ in range(10):  # no nearby point (theta >= 0) has a lower Laplace deviance
        th = np.maximum(fit["theta"] + rng.normal(scale=0.05, size=3), 0.0)
        b = fit["beta"] + rng.normal(scale=0.02, size=3)
        assert laplace.deviance_at(data, th, b, laplace._State(b, st.u0, st.ur)) >= best - 1e-7
