"""The closed loop: measured TE -> residual -> the effects the model lacks -> the updated model.

One estimator over the whole library at once (:mod:`rvcalib.sparse`), iterated with re-linearisation of the
reducer model through rvdyn (:mod:`rvcalib.reducer_model`); the method is written up in docs/calibration.md.

1. The measured TE of every reading, ``y``; the rig's zero of each test is an unknown constant (a nuisance,
   projected out of everything, estimated at the end and reported as such).
2. The library (:mod:`rvcalib.library`) for the dataset's reducer and readings.
3. At the current state ``theta`` of the solved candidates (start: nothing but what the runs declare), the model
   TE ``f(theta)`` and its Jacobian ``J``; the reading-error and empirical columns ``R`` are exact and fixed.
4. The linearised data ``z = y - f(theta) + J theta``, ``z = [J R] b + e``: the sparse estimator's posterior
   over ``b`` (every candidate at once; the prior scale of each is its tolerance class).
5. The chosen parameters (the always-estimated block, and the candidates of pure credible sets) are estimated
   through the reducer model itself (their nonlinear MAP, :mod:`rvcalib.refine`, started from where they are or
   from the linearised estimate, whichever fits better); the others leave the model (zero). That is a proposal;
   after the first linearisation the posterior with the current set held in the model proposes too (what the
   data add to the current set, :func:`_held_fit`), and the lower criterion of the two is taken (:func:`criterion`:
   the likelihood at its best noise variance, the tolerance prior, the risk inflation criterion's price per
   parameter). Where neither lowers it, the union of the current and the chosen sets, started from the current
   state, is the third; the best swaps of one chosen parameter for another are the last. A proposal is accepted
   only when it lowers the criterion (a swap: by more than chi2(1) at 95 %), so the loop never goes back: the
   estimator proposes, the criterion decides.
6. Repeat from 3 until no proposal lowers the criterion, or the chosen set no longer changes and the model TE
   moves by less than ``step_tolerance`` times the noise (or ``max_linearisations``). The empirical block joins
   only once the physical candidates have converged: what the physics cannot give is judged against the best
   physical model, not against a linearisation far from it. The posterior of the linearisation whose proposal
   was accepted last is the answer: named effects, groups the data cannot split, unexplained structure and the
   intervals (:mod:`rvcalib.result`).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass
from concurrent.futures import ProcessPoolExecutor
from contextlib import nullcontext
from typing import Callable

import numpy as np

from rvdyn.solver import law_from_model

from rvcalib.gaussian import estimate as tolerance_prior_estimate, measurement_columns
from rvcalib.library import Library, build_library
from rvcalib.readings import nuisance_columns, ramp_shown, reading_columns
from rvcalib.reducer_model import ReducerModel
from rvcalib.result import CalibrationResult, assemble
from rvcalib.settings import CalibrationSettings
from rvcalib.refine import refine
from rvcalib.sparse import Features, credible_sets, fit_sparse
from rvcalib.swaps import feature_columns, features_of, penalised_fit, swap_table
from rvcalib.twins import DELTA_CHI2, swap_twins


def resolved_order(dataset) -> int:
    """The highest harmonic order of the output angle every run's readings resolve (below half the readings per
    revolution of the sparsest run)."""
    per_rev = min(r.n / max(r.revolutions, 1e-9) for r in dataset.runs)
    return max(1, int(math.floor(per_rev / 2.0)) - 1)


class Projector:
    """Removes each test's constant: the projection onto the complement of the tests' indicator columns."""

    def __init__(self, N: np.ndarray) -> None:
        self.N = N
        self.counts = N.sum(axis=0)

    def __call__(self, v: np.ndarray) -> np.ndarray:
        means = (self.N.T @ v) / (self.counts[:, None] if v.ndim == 2 else self.counts)
        return v - self.N @ means

    def constants(self, r: np.ndarray) -> np.ndarray:
        """Each test's constant fitted to ``r``."""
        return (self.N.T @ r) / self.counts


def class_scales(candidates: list) -> np.ndarray:
    """Each parameter's prior scale, its candidate's tolerance class (in the candidate's unit), in order."""
    return np.array([c.prior_scale for c in candidates for _ in range(c.n_params)])


def prior_scales(library: Library, model: ReducerModel, J: np.ndarray, R: np.ndarray, readings: list,
                 dataset) -> tuple:
    """Prior scales of the solved and the reading parameters, with the two taken from the model's response: the
    compliance's (the model's own compliance at the runs: the TE per N m of friction torque, which is load) and
    the empirical terms' (the median RMS TE of a tolerance-class Table 4 effect)."""
    ts, tr = class_scales(model.candidates), class_scales(readings)
    names = [c.name for c in model.candidates for _ in range(c.n_params)]
    if "friction_torque_Nm" in names and "torsional_compliance_arcsec_per_Nm" in names:
        loaded = np.concatenate([np.full(r.n, r.load_Nm > 0) for r in dataset.runs])
        own = float(np.median(np.abs(J[loaded, names.index("friction_torque_Nm")])))
        if own > 0:
            ts[names.index("torsional_compliance_arcsec_per_Nm")] = own
    t4 = [i for i, c in enumerate(c for c in model.candidates for _ in range(c.n_params)) if c.family == "table4"]
    typical = float(np.median(np.sqrt(np.mean((J[:, t4] * ts[t4]) ** 2, axis=0)))) if t4 else 1.0
    emp = [i for i, c in enumerate(c for c in readings for _ in range(c.n_params)) if c.family == "empirical"]
    tr[emp] = typical if typical > 0 else 1.0
    return ts, tr


def _next_linearisation(fit, F: Features, n: int, ts: np.ndarray, width: float, share: float = 0.99,
                        most: int = 10) -> tuple[np.ndarray, np.ndarray]:
    """The spread and the columns to renew for the next statistical linearisation.

    Spread: a parameter's posterior standard deviation given that it is an effect where its inclusion probability
    is at least one half (at least 5 % of its prior scale), else ``width`` (``settings.secant_width``) times its
    prior scale (what it would be, were it the effect). Renewed: the parameters of the features that hold the first
    ``share`` of a supported effect's inclusion probability (at most ``most`` per effect): the ones the posterior
    may still choose."""
    spread = width * ts
    renew = np.zeros(n, dtype=bool)
    for e in fit.effects:
        if e.prior_variance <= 0:
            continue
        order = np.argsort(-e.alpha, kind="stable")
        k = min(int(np.searchsorted(np.cumsum(e.alpha[order]), share)) + 1, most)
        for f in order[:k]:
            a, b = F.starts[f], F.starts[f + 1]
            if b > n:
                continue
            renew[a:b] = True
            if e.alpha[f] >= 0.5:
                sd = np.sqrt(np.maximum(np.diag(e.cov_of(F, f)), 0.0))
                spread[a:b] = np.maximum(sd, 0.05) * ts[a:b]
    return spread, renew


def _active(fit, F: Features, n: int, settings, fixed: tuple) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The parameters the posterior has chosen (the fixed features, and the features of pure credible sets with
    inclusion probability at least one half), split into solved and reading parameters, and every parameter's prior
    standard deviation (sqrt(V_l) in scaled units: the prior variance of the effect that chose it)."""
    sd = np.ones(F.X.shape[1])
    on = np.zeros(F.X.shape[1], dtype=bool)
    for f in fixed:
        on[F.starts[f]:F.starts[f + 1]] = True
    for cs in credible_sets(F, fit, settings.sparse()):
        if cs.effect < len(fixed):
            continue
        if not cs.pure(settings.sparse()):
            continue
        e = fit.effects[cs.effect]
        for f in cs.features:
            if e.alpha[f] >= 0.5:
                a, b = F.starts[f], F.starts[f + 1]
                on[a:b] = True
                sd[a:b] = math.sqrt(e.prior_variance)
    idx = np.nonzero(on)[0]
    return idx[idx < n], idx[idx >= n] - n, sd


def global_fit(pb, theta: np.ndarray, te: np.ndarray, pool, log,
               reading: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The always-estimated block's maximum a posteriori alone (no other effect), through the reducer model: the
    state the first linearisation starts from. A clearance or preload of the whole ring changes how every other
    error shows, so the other candidates' columns are taken where the ring's fit already is.

    ``reading`` are the reading columns estimated with the block, each at its prior scale (None: none). The
    tolerance-prior estimator gives its measurement effects (the encoders' eccentricities, and the scale error and
    drift where a record shows a ramp; :func:`rvcalib.gaussian.measurement_columns`), which it estimates at every
    step: left out, a ramp of tens of arcsec over the record is met by the ring's fit and the compliance."""
    m, dense = pb.model, pb.dense_params
    if dense.size == 0:
        return theta, te
    tau, tr = class_scales(m.candidates), class_scales(pb.readings)
    sigma = max(float(pb.dataset.noise_arcsec()), 1e-3)
    reading = np.zeros(0, int) if reading is None else reading
    theta, _, te, _ = refine(m, pb.y, pb.proj, pb.R, theta, np.zeros(pb.R.shape[1]), dense, reading,
                             np.concatenate([tau, tr]), sigma, pool=pool, log=log)
    return theta, te


class Problem:
    """What one calibration holds: data, library, model, columns, projection."""

    def __init__(self, dataset, settings: CalibrationSettings, model=None) -> None:
        self.dataset, self.settings = dataset, settings
        self.y = np.concatenate([r.te_arcsec for r in dataset.runs])
        self.ramps, self.ramp_lines = ramp_shown(dataset)
        self.max_order = settings.max_order or resolved_order(dataset)
        self.library = build_library(dataset, self.max_order, settings.families, self.ramps)
        self.solved = ([c for c in self.library if c.solved and c.dense] +
                       [c for c in self.library if c.solved and not c.dense])
        self.readings = [c for c in self.library if not c.solved]
        law = None if settings.contact is None else law_from_model({"contact": settings.contact})
        self.model = (model if model is not None else
                      ReducerModel(dataset, self.solved, law, settings.workers, secant_width=settings.secant_width))
        self.R = (np.column_stack([reading_columns(c, dataset) for c in self.readings]) if self.readings
                  else np.zeros((self.y.size, 0)))
        Nc, self.tests = nuisance_columns(dataset)
        self.proj = Projector(Nc)
        # features: the dense candidates together as one (always in the model), then one per candidate
        dense = [c for c in self.solved if c.dense]
        self.feature_cands = ([dense] if dense else []) + [[c] for c in self.solved + self.readings if not c.dense]
        self.fixed = (0,) if dense else ()
        self.starts = np.r_[0, np.cumsum([sum(c.n_params for c in fc) for fc in self.feature_cands])]
        w = Library(self.solved + self.readings).prior_weights(settings.empirical_weight)
        self.prior = np.r_[[1.0] if dense else [], w[len(dense):]]
        self.empirical = np.array([fc[0].family == "empirical" for fc in self.feature_cands], dtype=bool)
        #: the solved parameters of the always-estimated block (indices into the model's state)
        self.dense_params = np.array([i for i, c in enumerate(c for c in self.model.candidates
                                                               for _ in range(c.n_params)) if c.dense], dtype=int)

    def feature_name(self, f: int) -> str:
        """A feature's name (its candidates' names)."""
        return "+".join(c.name for c in self.feature_cands[f]) if f not in self.fixed else "the dense block"

    def features(self, J: np.ndarray, scales, empirical: bool) -> Features:
        """The scaled, projected columns as features; without ``empirical`` the empirical block's prior weight is
        zero (none of it can be chosen)."""
        ts, tr = scales
        prior = self.prior.copy()
        if not empirical:
            prior[self.empirical] = 0.0
        return Features(self.proj(np.column_stack([J * ts, self.R * tr])), self.starts, prior)


@dataclass
class LoopState:
    """An accepted state of the loop: the solved parameters, the model TE there, the reading coefficients, the
    chosen parameters with their prior standard deviations, the posterior that chose them and the criterion."""

    theta: np.ndarray
    te: np.ndarray
    b_r: np.ndarray
    a_s: np.ndarray
    a_r: np.ndarray
    sd: np.ndarray
    phi: float
    fit: object = None
    F: Features | None = None


def criterion(pb, theta: np.ndarray, te: np.ndarray, b_r: np.ndarray, a_s: np.ndarray, a_r: np.ndarray,
              tau: np.ndarray) -> float:
    """The one number every state of the loop is judged by (lower is better):

        n ln(RSS / n) + sum_A (x_j / tau_j)^2 + 2 ln(p) |A|,   RSS = |P (y - f(theta) - R b)|^2

    minus twice the log-likelihood with the noise variance at its maximum (``RSS / n``, ``n`` the readings less the
    tests' constants: no noise figure has to be assumed), the tolerance prior of the chosen parameters ``A``
    (``tau`` their prior scales) and the risk inflation criterion's price of each chosen parameter among the ``p``
    the library holds (Foster and George 1994: a parameter is worth choosing among p candidates when it lowers the
    chi-square by more than 2 ln p)."""
    r = pb.proj(pb.y - te - pb.R @ b_r)
    n_s = theta.size
    n = r.size - len(pb.tests)
    x = np.concatenate([theta[a_s], b_r[a_r]])
    t = np.concatenate([tau[a_s], tau[n_s + a_r]])
    p = n_s + b_r.size
    rss = max(float(r @ r), 1e-300)
    return float(n * math.log(rss / n) + np.sum((x / t) ** 2) + 2.0 * math.log(max(p, 2)) * x.size)


def _swap_tries(pb, cur: LoopState, F: Features, z: np.ndarray, tau: np.ndarray, most: int) -> list:
    """The best ``most`` swaps of the current chosen set on the linearised model (:mod:`rvcalib.swaps`) among those
    that lower its chi-square by more than chi2(1) at 95 % (a smaller change is one the data cannot tell from
    chance: such a pair is a group, :mod:`rvcalib.twins`, not a move), each as a try for the reducer model: its
    solved and reading parameters, its linearised estimate (the penalised refit of the swapped set) as the second
    start, its prior standard deviations, its label and the criterion's drop it must reach to be accepted (the
    same chi2(1) margin, now on the reducer model)."""
    if most == 0:
        return []
    n = pb.model.n_params
    c = np.concatenate([cur.theta, cur.b_r]) / tau
    r = z - F.X @ c                                 # the current residual (J is taken at the current state)
    sigma = math.sqrt(max(float(r @ r), 1e-300) / max(r.size - len(pb.tests), 1))
    chosen = set(features_of(F.starts, np.concatenate([cur.a_s, n + cur.a_r]))) | set(pb.fixed)
    allowed = F.prior > 0
    tries = []
    table = swap_table(F.X, F.starts, z, chosen, allowed, sigma, pb.fixed, most=most)
    for sw in [sw for sw in table if sw.delta < -DELTA_CHI2][:most]:
        feats = sorted((chosen - {sw.out}) | {sw.into})
        cols = feature_columns(F.starts, feats)
        coef = penalised_fit(F.X[:, cols], z, sigma)[3]
        alt = np.zeros(n)
        s_cols = cols[cols < n]
        alt[s_cols] = coef[cols < n] * tau[s_cols]
        psd = cur.sd.copy()
        psd[feature_columns(F.starts, [sw.into])] = 1.0
        tries.append((s_cols, cols[cols >= n] - n, alt, psd, f"swap {pb.feature_name(sw.out)} -> "
                      f"{pb.feature_name(sw.into)} (linearised change {sw.delta:+.2f})", DELTA_CHI2))
    return tries


def propose(pb, cur: LoopState, fit, F, a_s, a_r, sd, sigma, linear, spread, tau, z, pool, log,
            held: tuple | None = None) -> LoopState | None:
    """The best of the proposals from one linearisation, if it lowers the criterion below the current state's:
    the posterior's chosen set (from where its parameters are, or from the linearised estimate) and, where given,
    ``held``: the chosen set of the posterior with the current set held in the model (:func:`_held_fit`'s tuple),
    both refined and the lower criterion taken; where neither lowers it with another set than the current one, the
    union of the current and the chosen sets started from the current state; where none does, the best swaps of
    the current set (:func:`_swap_tries`). A swap keeps the set's size, so its criterion drop is a likelihood
    ratio: it counts only beyond chi2(1) at 95 % (the swap is judged by its drop less that margin); below it the
    pair is one the data cannot split. The accepted state keeps the posterior that proposed it."""
    m = pb.model
    n = m.n_params
    best, best_key = None, math.inf
    tries = [(a_s, a_r, linear, sd, "chosen set", 0.0, fit, spread)]
    if held is not None:
        h_fit, h_s, h_r, h_sd, h_linear, h_spread, _ = held
        tries.append((h_s, h_r, h_linear, h_sd, "current set held, the posterior's additions", 0.0, h_fit, h_spread))
    primaries = len(tries)
    union_s, union_r = np.union1d(cur.a_s, a_s).astype(int), np.union1d(cur.a_r, a_r).astype(int)
    if union_s.size + union_r.size > cur.a_s.size + cur.a_r.size:
        tries.append((union_s, union_r, None, sd, "union with the current set", 0.0, fit, spread))

    def moves() -> bool:
        """Whether the best state lowers the criterion with another chosen set than the current one."""
        return (best is not None and best_key < cur.phi and
                (tuple(best.a_s), tuple(best.a_r)) != (tuple(cur.a_s), tuple(cur.a_r)))

    k, last, swapped = 0, None, False
    while k < len(tries):
        if k >= primaries and moves():
            break
        ps, pr, alt, psd, label, margin, t_fit, t_spread = tries[k]
        here = np.zeros(n)
        here[ps] = cur.theta[ps]
        b0 = np.zeros(cur.b_r.size)
        b0[pr] = cur.b_r[pr]
        th, b, te, _ = refine(m, pb.y, pb.proj, pb.R, here, b0, ps, pr, psd * tau, sigma, spread=t_spread,
                              pool=pool, log=log, feasible=cur.theta, alternative=alt)
        phi = criterion(pb, th, te, b, ps, pr, tau)
        log(f"  {label}: criterion {phi:.4f} (current {cur.phi:.4f}" +
            (f", to be accepted below {cur.phi - margin:.4f})" if margin else ")"))
        last = th
        if phi + margin < best_key:
            best, best_key = LoopState(th, te, b, ps, pr, psd, phi, t_fit, F), phi + margin
        k += 1
        if k == len(tries) and not swapped and not moves():
            tries += [t + (fit, spread) for t in _swap_tries(pb, cur, F, z, tau, pb.settings.swaps)]
            swapped = True
    if best is None or best_key >= cur.phi:
        return None
    if best.theta is not last:
        m.te(best.theta)                        # the model's states at the accepted state (the next Jacobian's)
    return best


def _held_fit(pb, cur: LoopState, F: Features, z: np.ndarray, ts: np.ndarray, free: tuple) -> tuple | None:
    """The posterior with the current chosen set held in the model, and its proposal: the sum of single effects
    on the linearised data with every feature of the current set a fixed effect (inclusion probability one, a
    Gaussian prior of its tolerance class), so its single effects are what the data add to the current set.

    The free posterior (its chosen solved and reading parameters ``free``) may trade a chosen candidate for
    another whose column at this state fits the linearised data as well: a chosen candidate's column is taken
    where it is, an unchosen one's at zero, and through the contacts they differ, so a twin or a stand-in can
    displace it while a small true effect goes unseen. Held, the chosen set's columns carry the current fit and
    the additions are judged on what is left. The criterion (:func:`criterion`) decides between the two
    proposals.

    Returns None when the current set is the always-estimated block alone (the free posterior is then the held
    one) or the held posterior chooses the free one's set; else ``(fit, a_s, a_r, sd, linear, spread, renew)``
    (:func:`_next_linearisation`'s spread and renewal for that posterior)."""
    m, settings = pb.model, pb.settings
    n = m.n_params
    held = tuple(sorted(set(pb.fixed) | set(features_of(F.starts, np.concatenate([cur.a_s, n + cur.a_r])))))
    if held == tuple(pb.fixed):
        return None
    h_fit = fit_sparse(F, z, settings.sparse(), fixed=held)
    chosen = _chosen(h_fit, F, pb, held, ts)
    if (tuple(chosen[0]), tuple(chosen[1])) == (tuple(free[0]), tuple(free[1])):
        return None
    return (h_fit,) + chosen


def _chosen(fit, F: Features, pb, fixed: tuple, ts: np.ndarray) -> tuple:
    """What a posterior proposes: its chosen solved and reading parameters with their prior standard deviations
    (:func:`_active`), the solved ones' linearised estimate (in their units) and the spread and renewal of the next
    linearisation (:func:`_next_linearisation`)."""
    n, settings = pb.model.n_params, pb.settings
    a_s, a_r, sd = _active(fit, F, n, settings, fixed)
    linear = np.zeros(n)
    linear[a_s] = fit.coef[:n][a_s] * ts[a_s]
    spread, renew = _next_linearisation(fit, F, n, ts, settings.secant_width)
    return a_s, a_r, sd, linear, spread, renew


def sparse_search(pb, theta: np.ndarray, te: np.ndarray, pool, log, t0: float) -> tuple:
    """The sparse estimator's iteration from the always-estimated block's fit ``theta`` (model TE ``te``): at each
    linearisation the sum of single effects over the library's columns, its chosen set refined through the reducer
    model (:func:`propose`), until no proposal lowers the criterion or a step moves the TE by at most
    ``step_tolerance`` of the noise with the same chosen set; the empirical block joins once the physical
    candidates have converged.

    Returns (the last accepted :class:`LoopState` with the posterior that chose it, the prior scales, the first
    linearisation's feature columns, the last linearisation's features, what stopped it, the linearisations)."""
    m, settings, y, proj, R = pb.model, pb.settings, pb.y, pb.proj, pb.R
    fit = F = scales = spread = renew = X0 = J = None
    stopped = "max_linearisations"
    empirical = False
    dense = pb.dense_params
    cur = None
    for it in range(1, settings.max_linearisations + 1):
        if J is None:
            J = m.jacobian(theta, spread, renew, pool)
        scales = scales or prior_scales(pb.library, m, J, R, pb.readings, pb.dataset)
        ts, tr = scales
        tau = np.concatenate(scales)
        if cur is None:
            cur = LoopState(theta, te, np.zeros(R.shape[1]), dense, np.zeros(0, int), np.ones(tau.size),
                            criterion(pb, theta, te, np.zeros(R.shape[1]), dense, np.zeros(0, int), tau))
        F = pb.features(J, scales, empirical)
        X0 = F.X if X0 is None else X0
        z = proj(y - te + J @ theta)
        fit = fit_sparse(F, z, settings.sparse(), init=fit.effects if fit is not None else None, fixed=pb.fixed)
        sigma = math.sqrt(fit.sigma2)
        a_s, a_r, sd, linear, spread, renew = _chosen(fit, F, pb, pb.fixed, ts)
        held = _held_fit(pb, cur, F, z, ts, (a_s, a_r))
        new = propose(pb, cur, fit, F, a_s, a_r, sd, sigma, linear, spread, tau, z, pool, log, held)
        if new is None:
            m.te(cur.theta)                         # the model's states back at the current state
            log(f"linearisation {it}: no proposal lowers the criterion ({time.perf_counter() - t0:.0f} s)")
            if empirical or not pb.empirical.any():
                stopped = "converged"
                break
            empirical = True
            log("the physical candidates have converged; the empirical block joins")
            continue                                # the same state: its columns stand
        moved = float(np.sqrt(np.mean(proj(new.te - cur.te) ** 2)))
        same = (tuple(new.a_s), tuple(new.a_r)) == (tuple(cur.a_s), tuple(cur.a_r))
        log(f"linearisation {it}: {new.fit.n_supported} effects supported, {new.a_s.size + new.a_r.size} parameters "
            f"chosen, sigma {sigma:.4g} arcsec, criterion {cur.phi:.4f} -> {new.phi:.4f}, the model TE moved "
            f"{moved:.3g} arcsec RMS ({time.perf_counter() - t0:.0f} s)")
        if held is not None and new.fit is held[0]:         # the held posterior's proposal: its spreads
            spread, renew = held[5], renew | held[6]
        cur, theta, te, J = new, new.theta, new.te, None
        renew = renew | (m.column_kinds() != "pin")
        if same and moved <= settings.step_tolerance * sigma:
            if empirical or not pb.empirical.any():
                stopped = "converged"
                break
            empirical = True            # the physics has converged: now what it cannot give
            log("the physical candidates have converged; the empirical block joins")
    if cur.fit is None:                     # nothing accepted: the posterior of the last linearisation
        cur.fit, cur.F = fit, F
    return cur, scales, X0, F, stopped, it


def calibrate(dataset, settings: CalibrationSettings | None = None, log: Callable[[str], None] | None = None,
              model=None) -> CalibrationResult:
    """Calibrate the reducer model of a measured dataset.

    Parameters
    ----------
    dataset : MeasuredDataset
    settings : CalibrationSettings or None
        Defaults when None.
    log : callable or None
        Receives a line per step of progress.
    model : object or None
        The forward model (default :class:`rvcalib.reducer_model.ReducerModel` of the dataset); tests may give a
        stand-in with the same ``candidates``, ``n_params``, ``te``, ``jacobian``, ``statistical_jacobian``,
        ``case_dict`` and ``groups``.

    Returns
    -------
    CalibrationResult
    """
    settings = (settings or CalibrationSettings()).validate()
    log = log or (lambda s: None)
    t0 = time.perf_counter()
    pb = Problem(dataset, settings, model)
    m, y, proj, R = pb.model, pb.y, pb.proj, pb.R
    theta = np.zeros(m.n_params)
    te = m.te(theta)
    rms_before = float(np.sqrt(np.mean(proj(y - te) ** 2)))
    log(f"library: {len(pb.library)} candidates ({m.n_params} solved parameters, {R.shape[1]} reading columns); "
        f"residual RMS {rms_before:.4g} arcsec")
    pool_cm = ProcessPoolExecutor(settings.workers) if settings.workers > 1 else nullcontext()
    with pool_cm as pool:
        tolerance_prior = settings.estimator == "tolerance-prior"
        theta, te = global_fit(pb, theta, te, pool, log, measurement_columns(pb) if tolerance_prior else None)
        if tolerance_prior:
            J = m.statistical_jacobian(theta, pool)
            scales = prior_scales(pb.library, m, J, R, pb.readings, dataset)
            return tolerance_prior_estimate(pb, settings, theta, J, scales, pool, log, t0, rms_before,
                                            time.perf_counter)
        cur, scales, X0, F, stopped, it = sparse_search(pb, theta, te, pool, log, t0)
        twins = swap_twins(pb, X0, cur.theta, math.sqrt(cur.fit.sigma2), cur.a_s, cur.a_r, scales[0], F.X)
    return assemble(dataset, pb, cur.F, cur.fit, scales, cur.theta, cur.te, settings,
                    {"rms_before": rms_before, "stopped_by": stopped, "ramp_lines": pb.ramp_lines, "b_r": cur.b_r,
                     "active_s": cur.a_s, "active_r": cur.a_r, "prior_sd": cur.sd, "twins": twins,
                     "seconds": time.perf_counter() - t0, "linearisations": it, "max_order": pb.max_order,
                     "solves": getattr(m, "solves", 0)})
