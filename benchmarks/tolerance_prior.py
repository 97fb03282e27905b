"""A reference estimator for the linear coverage benchmark: the Gaussian posterior under the tolerance prior.

Every candidate of the stand-in (each Table 4 instance, each model option but the compliance) is a Gaussian
random effect ``N(0, prior_scale^2)``: a real reducer holds every error at some size within its tolerance class
(the library's prior scale, a third of the paper's Table 4 value). The compliance, a property of the reducer and
not an error within a class, has a flat prior. The tests' constants are projected out. With the stand-in's TE
linear in the parameters, the posterior is Gaussian and exact:

    precision  A = J' J / sigma^2 + diag(1 / prior_scale^2)   (0 for the flat block)
    mean       m = A^-1 J' (y - te0) / sigma^2,   covariance  A^-1

with ``sigma`` the noise of the greatest evidence (MacKay's fixed point from the records' second-difference
noise, :func:`noise_evidence`). There is no selection: a candidate is *named* where its 95 % posterior region
excludes zero (a one-component effect: its interval; two components: the chi-square(2) ellipse), with that
interval. It is what ``rv-calibrate --estimator tolerance-prior`` (:mod:`rvcalib.gaussian`) must give on an exactly
linear model, without its search, its bounds and its measurement candidates: the benchmark scores both on the same
draws.

Run through ``coverage_linear.py --method reference``.
"""
from __future__ import annotations

import math

import numpy as np
from scipy import stats

from rvcalib.gaussian import evidence_sigma


def posterior(J: np.ndarray, r: np.ndarray, sigma: float, prior_sd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean and covariance of ``b`` in ``r = J b + e``, ``e ~ N(0, sigma^2 I)``, ``b_j ~ N(0, prior_sd_j^2)``
    (``prior_sd_j = inf``: flat)."""
    prec = np.where(np.isfinite(prior_sd), 1.0 / np.square(prior_sd), 0.0)
    A = J.T @ J / sigma ** 2 + np.diag(prec)
    C = np.linalg.inv(A)
    return C @ (J.T @ r) / sigma ** 2, C


def noise_evidence(J: np.ndarray, r: np.ndarray, dof: int, prior_sd: np.ndarray, sigma0: float,
                   iterations: int = 50) -> float:
    """The noise standard deviation that maximises the evidence of ``r`` (MacKay's fixed point, D. J. C. MacKay,
    "Bayesian interpolation", Neural Computation 4 (1992) 415-447, eq. 4.10 with the prior fixed):
    ``sigma^2 = |r - J m|^2 / (dof - g)``, ``g = sum_j (1 - C_jj / prior_sd_j^2)`` the parameters the data
    determine (1 for a flat one); ``dof`` the readings less the constants projected out. Each iteration refits the
    posterior mean at the current noise, then takes one update of the product's own fixed point
    (:func:`rvcalib.gaussian.evidence_sigma`)."""
    s = sigma0
    for _ in range(iterations):
        m, _ = posterior(J, r, s, prior_sd)
        new = evidence_sigma(J, r - J @ m, prior_sd, dof, s, iterations=1)[0]
        if abs(new ** 2 - s ** 2) <= 1e-10 * s ** 2:
            return new
        s = new
    return s


def named_effects(candidates: list, mean: np.ndarray, cov: np.ndarray, level: float = 0.95) -> list[dict]:
    """The candidates whose level-``level`` posterior region excludes zero, in the loop's result schema (the two
    sides of one pin-wise error: the side with the larger evidence)."""
    out: dict[str, dict] = {}
    pos = 0
    z = stats.norm.ppf(0.5 + level / 2)
    for c in candidates:
        s = slice(pos, pos + c.n_params)
        pos += c.n_params
        m, S = mean[s], cov[s, s]
        d2 = float(m @ np.linalg.solve(S, m))
        if d2 <= stats.chi2.ppf(level, c.n_params):
            continue
        size, ang = c.size(m)
        sd = math.sqrt(S[0, 0])
        e = {"name": c.effect_name, "key": c.key, "family": c.family, "instance": dict(c.instance), "unit": c.unit,
             "value": float(size), "angle_deg": ang, "components": m.tolist(), "cov": S.tolist(),
             "ci95": [float(m[0] - z * sd), float(m[0] + z * sd)], "evidence_chi2": d2}
        if c.effect_name not in out or out[c.effect_name]["evidence_chi2"] < d2:
            out[c.effect_name] = e
    return list(out.values())


def calibrate_gaussian(fm, dataset, N: np.ndarray) -> dict:
    """The result (``rms_after``, ``effects``, ``groups``) of the tolerance-prior posterior on the frozen stand-in
    ``fm`` for ``dataset``; ``N`` the tests' indicator columns."""
    Q = np.linalg.qr(N)[0]

    def proj(a):
        return a - Q @ (Q.T @ a)

    y = np.concatenate([r.te_arcsec for r in dataset.runs])
    sd = np.array([np.inf if c.dense and c.family == "model" else c.prior_scale
                   for c in fm.candidates for _ in range(c.n_params)])
    J = proj(fm.J)
    r = proj(y - fm.te0)
    sigma = noise_evidence(J, r, r.size - N.shape[1], sd, float(dataset.noise_arcsec()))
    m, C = posterior(J, r, sigma, sd)
    res = r - J @ m
    return {"rms_after": float(np.sqrt(np.mean(res ** 2))), "effects": named_effects(fm.candidates, m, C),
            "groups": []}
