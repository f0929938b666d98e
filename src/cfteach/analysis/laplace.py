"""The numerical core of the trial-level GLMM: a binomial (logit) mixed model with crossed
random intercepts, fitted on the Laplace approximation of the marginal likelihood the way
lme4's `glmer` does with nAGQ = 1.

lme4's parametrisation (Bates et al. 2015, J. Stat. Softw. 67(1)): the random effects are
b = Lambda(theta) u with spherical u ~ N(0, I), and Lambda = diag(theta_k) for random
intercepts, so theta_k is the SD of factor k and may sit exactly at 0 (a "singular fit").
For given (theta, beta), penalised IRLS finds the conditional mode u*, and the Laplace
deviance is

    d(theta, beta) = -2 log p(y | u*, beta) + |u*|^2 + log det(Lambda'Z'W Z Lambda + I).

glmer minimises d jointly over (theta, beta). Here beta is *profiled*: for each theta an
inner Newton iteration solves grad_beta d = 0 exactly (the gradient includes the log det
term's dependence on beta through the weights W; the approximate Hessian is the PIRLS one),
and scipy's L-BFGS-B minimises the profiled deviance over theta >= 0. nAGQ = 0 (lme4's
fast stage: beta and u as one penalised IRLS, the log det term ignored for beta) is the
same iteration without that gradient term.

Why structured algebra rather than a sparse LU: every observation has one level of each
factor, so the participant block of the u-Hessian is diagonal; the rest (test items, a few
dozen) is handled by a dense Schur complement. Cost is linear in participants.

Standard errors follow lme4's `vcov.merMod`: the fixed-effect block of the inverse of the
finite-difference Hessian of d over (theta, beta), i.e. the theta uncertainty is included.
lme4 cannot difference at a bound and then falls back to the PIRLS curvature; here a theta
at 0 is held fixed (left out of the Hessian) instead, which is the same model.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.linalg import cho_factor, cho_solve
from scipy.special import expit

#: lme4's isSingular() tolerance: a theta below this is reported as a variance of 0.
SINGULAR_TOL = 1e-4
_FD_STEP = 1e-4  # lme4's deriv12 step for the Hessian


@dataclass
class Data:
    """y (0/1), fixed-effect matrix x, and one integer code array per random-intercept
    factor (the first factor should be the one with the most levels)."""

    y: np.ndarray
    x: np.ndarray
    codes: list[np.ndarray]
    prior_precision: np.ndarray | None = None  # 1/sd^2 of independent normal priors on beta
    n0: int = field(init=False)
    rest: np.ndarray = field(init=False)  # n x (K-1): column of each observation in block 2
    qr: int = field(init=False)

    def __post_init__(self) -> None:
        self.codes = [np.asarray(c, dtype=np.intp) for c in self.codes]
        self.n0 = int(self.codes[0].max()) + 1
        sizes = [int(c.max()) + 1 for c in self.codes[1:]]
        offsets = np.cumsum([0, *sizes])
        self.rest = np.column_stack(
            [c + o for c, o in zip(self.codes[1:], offsets[:-1], strict=True)]
            or [np.zeros((len(self.y), 0), np.intp)]
        ).astype(np.intp)
        self.qr = int(offsets[-1])


class _Factor:
    """Solver of H = M'WM + I with M = Z Lambda: every observation has one level of each
    factor, so the first factor's block is diagonal and the rest (qr columns) is a small
    dense Schur complement. Built with bincount, no sparse matrices."""

    def __init__(self, data: Data, theta: np.ndarray, w: np.ndarray) -> None:
        self.theta0 = float(theta[0])
        self.th = np.asarray(theta[1:], float)  # SD of each later factor
        self.code0, self.rest, n0, qr = data.codes[0], data.rest, data.n0, data.qr
        self.d1 = self.theta0**2 * np.bincount(self.code0, w, n0) + 1.0
        b = np.zeros(n0 * qr)
        c = np.zeros(qr * qr)
        for k, tk in enumerate(self.th):
            b += self.theta0 * tk * np.bincount(self.code0 * qr + self.rest[:, k], w, n0 * qr)
            for m, tm in enumerate(self.th):
                c += tk * tm * np.bincount(self.rest[:, k] * qr + self.rest[:, m], w, qr * qr)
        self.b = b.reshape(n0, qr)
        self.e = self.b / self.d1[:, None]
        s = c.reshape(qr, qr) + np.eye(qr) - self.b.T @ self.e
        self.chol = cho_factor(s, lower=True) if qr else None
        diag = np.diag(self.chol[0]) if self.chol else np.zeros(0)
        self.logdet = float(np.sum(np.log(self.d1)) + 2 * np.sum(np.log(diag)))
        self.qr = qr

    def _s_solve(self, r: np.ndarray) -> np.ndarray:
        return cho_solve(self.chol, r) if self.chol else r

    def solve(self, r0: np.ndarray, rr: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """H^{-1} [r0; rr] for vector or matrix right-hand sides."""
        xr = self._s_solve(rr - self.e.T @ r0)
        x0 = (r0 - self.b @ xr) / (self.d1 if r0.ndim == 1 else self.d1[:, None])
        return x0, xr

    def mt(self, g: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """M' g for a vector or an (n x p) matrix, split by block."""
        if g.ndim == 1:
            g0 = self.theta0 * np.bincount(self.code0, g, len(self.d1))
            gr = np.zeros(self.qr)
            for k, tk in enumerate(self.th):
                gr += tk * np.bincount(self.rest[:, k], g, self.qr)
            return g0, gr
        cols = [self.mt(g[:, j]) for j in range(g.shape[1])]
        return np.column_stack([c[0] for c in cols]), np.column_stack([c[1] for c in cols])

    def mr(self, ur: np.ndarray) -> np.ndarray:
        """The later factors' part of M u (vector or matrix u)."""
        out = np.zeros(())  # a 0-d zero: the sum is an array from its first term on
        for k, tk in enumerate(self.th):
            out = out + tk * ur[self.rest[:, k]]
        return out if self.th.size else np.zeros((len(self.code0), *ur.shape[1:]))

    def m(self, u0: np.ndarray, ur: np.ndarray) -> np.ndarray:
        """M u."""
        return self.theta0 * u0[self.code0] + self.mr(ur)

    def leverage(self) -> np.ndarray:
        """diag(M H^{-1} M'), one value per observation."""
        n = len(self.code0)
        if not self.qr:
            return self.theta0**2 / self.d1[self.code0]
        sinv = self._s_solve(np.eye(self.qr))
        f = self.e @ sinv  # -(H^{-1}) off-diagonal block
        diag0 = 1.0 / self.d1 + np.sum(f * self.e, axis=1)
        rr = np.zeros(n)
        cross = np.zeros(n)
        for k, tk in enumerate(self.th):
            cross += tk * f[self.code0, self.rest[:, k]]
            for m, tm in enumerate(self.th):
                rr += tk * tm * sinv[self.rest[:, k], self.rest[:, m]]
        return self.theta0**2 * diag0[self.code0] - 2 * self.theta0 * cross + rr


@dataclass
class _State:
    """Warm starts carried between evaluations."""

    beta: np.ndarray
    u0: np.ndarray
    ur: np.ndarray


def _loglik(y: np.ndarray, eta: np.ndarray) -> float:
    return float(np.sum(y * eta - np.logaddexp(0.0, eta)))


def pirls(
    data: Data, theta: np.ndarray, beta: np.ndarray, st: _State
) -> tuple[float, _Factor, np.ndarray]:
    """Conditional mode of u given (theta, beta); returns (Laplace deviance, factor, mu)."""
    off = data.x @ beta
    u0, ur = st.u0.copy(), st.ur.copy()
    w = np.full(len(data.y), 0.25)
    fac = _Factor(data, theta, w)

    def pdev(u0: np.ndarray, ur: np.ndarray) -> float:
        eta = off + fac.m(u0, ur)
        return -2 * _loglik(data.y, eta) + float(u0 @ u0 + ur @ ur)

    cur = pdev(u0, ur)
    for _ in range(60):
        eta = off + fac.m(u0, ur)
        mu = expit(eta)
        w = mu * (1 - mu)
        fac = _Factor(data, theta, w)
        g0, gr = fac.mt(data.y - mu)
        d0, dr = fac.solve(g0 - u0, gr - ur)
        step = 1.0
        for _ in range(30):  # step halving keeps every step a descent step
            new = pdev(u0 + step * d0, ur + step * dr)
            if new <= cur + 1e-12 * abs(cur):
                break
            step /= 2
        u0, ur = u0 + step * d0, ur + step * dr
        done = (
            abs(cur - new) < 1e-11 * (1 + abs(cur))
            and step * max(np.max(np.abs(d0), initial=0), np.max(np.abs(dr), initial=0)) < 1e-8
        )
        cur = new
        if done:
            break
    eta = off + fac.m(u0, ur)
    mu = expit(eta)
    fac = _Factor(data, theta, mu * (1 - mu))
    st.u0, st.ur = u0, ur
    dev = -2 * _loglik(data.y, eta) + float(u0 @ u0 + ur @ ur) + fac.logdet
    if data.prior_precision is not None:
        dev += float(beta @ (data.prior_precision * beta))
    return dev, fac, mu


def beta_gradient(
    data: Data, fac: _Factor, mu: np.ndarray, beta: np.ndarray, nagq: int
) -> tuple[np.ndarray, np.ndarray]:
    """Gradient of d over beta (u at its mode, theta fixed) and the PIRLS approximation of
    its Hessian, 2 (X'WX - X'WM H^{-1} M'WX)."""
    x = data.x
    w = mu * (1 - mu)
    wx = x * w[:, None]
    g0, gr = fac.mt(wx)
    u0, ur = fac.solve(g0, gr)
    hess = 2 * (x.T @ wx - g0.T @ u0 - gr.T @ ur)
    grad = -2 * x.T @ (data.y - mu)
    if nagq > 0:
        deta = x - fac.theta0 * u0[fac.code0] - fac.mr(ur)
        wprime = w * (1 - 2 * mu)
        grad = grad + deta.T @ (fac.leverage() * wprime)
    if data.prior_precision is not None:
        grad = grad + 2 * data.prior_precision * beta
        hess = hess + 2 * np.diag(data.prior_precision)
    return grad, hess


def profiled(data: Data, theta: np.ndarray, st: _State, nagq: int = 1) -> float:
    """min over beta of d(theta, beta), by Newton steps from the warm start in `st`."""
    beta = st.beta.copy()
    dev = math.inf
    for _ in range(50):
        dev, fac, mu = pirls(data, theta, beta, st)
        grad, hess = beta_gradient(data, fac, mu, beta, nagq)
        step = np.linalg.solve(hess, grad)
        if np.max(np.abs(step)) < 1e-9:
            break
        beta = beta - step
    st.beta = beta
    return dev


def deviance_at(data: Data, theta: np.ndarray, beta: np.ndarray, st: _State) -> float:
    """d(theta, beta) with u at its conditional mode (for finite differences)."""
    return pirls(data, theta, beta, st)[0]


def _hessian(data: Data, theta: np.ndarray, beta: np.ndarray, st: _State) -> np.ndarray:
    """Hessian of d over the free thetas and beta: central differences (step 1e-4, as lme4)
    of the exact beta gradient, and second differences of d for the theta-theta block."""
    free = np.flatnonzero(theta >= SINGULAR_TOL)
    nf, p = len(free), len(beta)
    h = _FD_STEP

    def at(th: np.ndarray, b: np.ndarray) -> tuple[float, np.ndarray]:
        s = _State(b, st.u0.copy(), st.ur.copy())
        dev, fac, mu = pirls(data, th, b, s)
        return dev, beta_gradient(data, fac, mu, b, 1)[0]

    hess = np.empty((nf + p, nf + p))
    for j in range(p):
        e = np.zeros(p)
        e[j] = h
        hess[nf:, nf + j] = (at(theta, beta + e)[1] - at(theta, beta - e)[1]) / (2 * h)
    fx = at(theta, beta)[0]

    def th_plus(*steps: tuple[int, float]) -> np.ndarray:
        th = theta.copy()
        for k, s in steps:
            th[free[k]] += s
        return th

    for k in range(nf):
        dp, gp = at(th_plus((k, h)), beta)
        dm, gm = at(th_plus((k, -h)), beta)
        hess[nf:, k] = hess[k, nf:] = (gp - gm) / (2 * h)
        hess[k, k] = (dp - 2 * fx + dm) / h**2
        for i in range(k):
            hess[i, k] = hess[k, i] = (
                at(th_plus((i, h), (k, h)), beta)[0]
                - at(th_plus((i, h), (k, -h)), beta)[0]
                - at(th_plus((i, -h), (k, h)), beta)[0]
                + at(th_plus((i, -h), (k, -h)), beta)[0]
            ) / (4 * h**2)
    bb = hess[nf:, nf:]
    hess[nf:, nf:] = (bb + bb.T) / 2
    return hess


def fit(
    data: Data,
    *,
    nagq: int = 1,
    theta_start: np.ndarray | None = None,
    beta_start: np.ndarray | None = None,
    se: str = "hessian",
) -> dict[str, Any]:
    """Fit the GLMM; returns beta, se, theta (the SDs), deviance, convergence, singular.

    `se`: "hessian" (lme4's default for GLMMs, theta uncertainty included; about 2 (p + 3)
    PIRLS runs) or "pirls" (the PIRLS curvature at the fitted theta; nAGQ = 0 uses it).
    """
    from scipy.optimize import minimize

    p = data.x.shape[1]
    k = len(data.codes)
    st = _State(
        np.zeros(p) if beta_start is None else beta_start.copy(),
        np.zeros(data.n0),
        np.zeros(data.qr),
    )
    theta0 = np.ones(k) if theta_start is None else np.asarray(theta_start, float)

    def obj(th: np.ndarray) -> float:
        return profiled(data, th, st, nagq)

    def grad(th: np.ndarray) -> np.ndarray:
        out = np.empty_like(th)
        for j in range(len(th)):
            h = 1e-5 * max(1.0, th[j])
            up, dn = th.copy(), th.copy()
            up[j] += h
            if th[j] - h >= 0:
                dn[j] -= h
                out[j] = (obj(up) - obj(dn)) / (2 * h)
            else:  # at the bound: forward difference
                out[j] = (obj(up) - obj(th)) / h
        return out

    res = minimize(
        obj,
        theta0,
        jac=grad,
        method="L-BFGS-B",
        bounds=[(0.0, None)] * k,
        options={"ftol": 1e-13, "gtol": 1e-7, "maxiter": 200},
    )
    theta = np.where(res.x < SINGULAR_TOL, 0.0, res.x)
    dev = profiled(data, theta, st, nagq)
    _, fac, mu = pirls(data, theta, st.beta, st)
    g, approx = beta_gradient(data, fac, mu, st.beta, nagq)
    cov = None
    if se == "hessian" and nagq > 0:
        hess = _hessian(data, theta, st.beta, st)
        try:
            inv = np.linalg.inv(hess)
            nfree = hess.shape[0] - p
            cov = 2 * inv[nfree:, nfree:]
            if np.any(np.diag(cov) <= 0) or not np.all(np.isfinite(cov)):
                cov = None
        except np.linalg.LinAlgError:
            cov = None
    if cov is None:  # lme4's fallback as well
        cov = 2 * np.linalg.inv(approx)
    return {
        "beta": st.beta.copy(),
        "se": np.sqrt(np.diag(cov)),
        "cov": cov,
        "theta": theta,
        "deviance": float(dev),
        "converged": bool(res.success and np.max(np.abs(g)) < 1e-4),
        "singular": [bool(t < SINGULAR_TOL) for t in theta],
        "optimizer": str(res.message),
    }
