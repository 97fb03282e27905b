"""What the loop reports, read from the estimator's posterior: named effects with their intervals, groups the
data cannot split, unexplained structure, the tests' constants, and the fit before and after.

* A *named effect* is a pure credible set holding one physical candidate. Its value is the posterior mean of its
  parameters given that it is the effect; its 95 % interval is that of the marginal posterior of the parameter,
  a mixture of no effect (probability 1 - alpha) and the Gaussian posterior given the effect (alpha): the
  selection's uncertainty is in the interval. Two components (an eccentricity) are reported as a magnitude and an
  angle with the components' covariance; the magnitude's interval is the delta method's.
* A *group* is a pure credible set of several candidates: each would explain the same part of the data, with the
  size given (its posterior mean given that it is the one; a size beyond the candidate's physical bounds is
  reported as unbounded) and its probability. The two sides of one pin-wise error (its positive and its negative
  values, two candidates) are one member: the data point at that pin whichever side fits (:func:`merge_sides`).
* *Unexplained* structure is a pure credible set of empirical terms only (an order, a load- or direction-dependent
  term the physical library does not give); a set mixing both is a group "physical or unexplained".
* A *diffuse* set (members that do not explain the same signal) names nothing; its effect stays in the fit.
"""
from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field

import numpy as np
from scipy import optimize, stats

from rvcalib.robust import floored, score_covariance
from rvcalib.sparse import credible_sets
from rvrig.dataset import noise_estimate


@dataclass
class NamedEffect:
    """A physical effect the data name (see the module docstring)."""

    name: str
    key: str
    family: str
    instance: dict
    unit: str
    value: float
    angle_deg: float | None
    components: list
    cov: list
    ci95: list
    probability: float
    meaning: str
    prior_scale: float | None = None

    def to_dict(self) -> dict:
        return asdict(self)

    def line(self) -> str:
        ang = f" at {self.angle_deg:.1f} deg" if self.angle_deg is not None else ""
        return (f"{self.name} = {self.value:+.4g} {self.unit}{ang} [{self.ci95[0]:.4g}, {self.ci95[1]:.4g}] "
                f"(probability {self.probability:.3f}{scales_text(self.value, self.prior_scale)})")


def in_prior_scales(value: float, prior_scale: float | None) -> float | None:
    """The size of a named effect in its candidate's prior scale (the tolerance class the library assumes,
    docs/calibration.md section 2); None where the effect has none."""
    return abs(value) / prior_scale if prior_scale else None


def scales_text(value: float, prior_scale: float | None) -> str:
    """``; N prior scales`` (:func:`in_prior_scales`), empty where the effect has no prior scale."""
    n = in_prior_scales(value, prior_scale)
    return "" if n is None else f"; {n:.2g} prior scales"


@dataclass
class CalibrationResult:
    """The result of :func:`rvcalib.loop.calibrate` (:meth:`to_dict` is the JSON)."""

    effects: list
    groups: list
    unexplained: list
    diffuse: list
    nuisance: list
    rms_before: float
    rms_after: float
    noise_arcsec: float
    sigma_arcsec: float
    stopped_by: str
    cap_binds: bool
    seconds: float
    linearisations: int
    settings: dict
    notes: list
    reducer: dict
    calibrated_case: dict
    residuals: list = field(default_factory=list, repr=False)

    def to_dict(self) -> dict:
        d = {k: v for k, v in self.__dict__.items() if k != "residuals"}
        d["effects"] = [e.to_dict() for e in self.effects]
        return json.loads(json.dumps(d, default=_jsonable))

    @property
    def status(self) -> str:
        """``explained`` when the residual is at the noise (within 1.2 x), else ``residual left``."""
        return "explained" if self.rms_after <= 1.2 * self.noise_arcsec else "residual left"


def _jsonable(o):
    if isinstance(o, (np.floating, np.integer)):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise TypeError(f"{type(o).__name__} is not JSON serialisable")


def mixture_interval(alpha: float, m: float, s: float, level: float = 0.95) -> tuple[float, float]:
    """Central interval of the mixture (1 - alpha) delta_0 + alpha N(m, s^2)."""
    if s <= 0:
        return (min(0.0, m), max(0.0, m)) if alpha < 1 else (m, m)

    def cdf(x: float) -> float:
        return (1.0 - alpha) * (x >= 0.0) + alpha * stats.norm.cdf((x - m) / s)

    out = []
    for q in ((1 - level) / 2, (1 + level) / 2):
        lo, hi = min(0.0, m) - 10 * s, max(0.0, m) + 10 * s
        if cdf(0.0) >= q and cdf(-1e-300) < q:
            out.append(0.0)
            continue
        out.append(float(optimize.brentq(lambda x: cdf(x) - q, lo, hi)))
    return out[0], out[1]


class Laplace:
    """The joint Gaussian posterior of the chosen parameters at the final state (Laplace's approximation of the
    nonlinear MAP), in the scaled units of the last linearisation's columns, mean the refined state.

    The candidates not chosen are not taken as exactly zero: each is a Gaussian random effect whose variance is its
    posterior second moment under the estimator (``coef_var + coef^2`` of :class:`rvcalib.sparse.SparseFit`, what
    the data leave of it). The noise of the chosen parameters' regression is then ``sigma^2 I + X_B D_B X_B'`` and
    the precision ``X_A' (sigma^2 I + X_B D_B X_B')^-1 X_A + diag(1 / prior_sd^2)`` (Woodbury's identity keeps it
    to the size of B). A chosen effect that an unchosen candidate could stand in for gets the wider interval that
    uncertainty of the selection gives; correlations between chosen effects (a pin's pitch and the ring's fit, say)
    widen each one's interval, which the estimator's independent single effects do not. Given the final residual
    (``residual``, runs cut at ``offsets``), the white-noise information is replaced by the residual's own score
    covariance where that is larger (:mod:`rvcalib.robust`: a residual that still holds structure widens the
    intervals)."""

    def __init__(self, X: np.ndarray, idx: np.ndarray, prior_sd: np.ndarray, sigma2: float, values: np.ndarray,
                 tau: np.ndarray, background: np.ndarray | None = None, residual: np.ndarray | None = None,
                 offsets: np.ndarray | None = None) -> None:
        self.pos = {int(j): k for k, j in enumerate(idx)}
        Xa = X[:, idx]
        W = Xa / sigma2                                     # (sigma^2 I + X_B D_B X_B')^-1 X_A
        if background is not None:
            out = np.ones(X.shape[1], dtype=bool)
            out[idx] = False
            keep = out & (background > 1e-12 * np.max(background, initial=0.0)) & (background > 0)
            if keep.any():
                Xb = X[:, keep] * np.sqrt(background[keep])
                M = sigma2 * np.eye(Xb.shape[1]) + Xb.T @ Xb
                W = (Xa - Xb @ np.linalg.solve(M, Xb.T @ Xa)) / sigma2
        G = Xa.T @ W
        P = np.diag(1.0 / prior_sd[idx] ** 2)
        Hinv = np.linalg.pinv(G + P)
        if residual is None:
            cov = Hinv
        else:                                               # the sandwich of rvcalib.robust: never narrower
            S = floored(score_covariance(W, residual, offsets), G)
            cov = Hinv @ (S + P) @ Hinv
        self.cov = cov * np.outer(tau[idx], tau[idx])
        self.mean = values[idx]

    def block(self, a: int, b: int):
        """(mean, covariance) of the parameters a..b-1 in physical units, or None if they were not chosen."""
        if any(j not in self.pos for j in range(a, b)):
            return None
        k = [self.pos[j] for j in range(a, b)]
        return self.mean[k], self.cov[np.ix_(k, k)]


def group_member(c, mean: np.ndarray, tau: np.ndarray, prob: float) -> dict:
    """A group's member: candidate ``c`` at ``mean`` times its scales ``tau`` (physical units), its size or
    ``"unbounded"`` where the value lies beyond the candidate's physical bounds, with probability ``prob``."""
    v = mean * tau
    size, ang = c.size(v)
    bounded = all(c.lower <= x <= c.upper for x in v)
    return {"name": c.effect_name, "key": c.key, "family": c.family, "instance": dict(c.instance), "unit": c.unit,
            "value": float(size) if bounded else "unbounded", "angle_deg": ang, "probability": prob}


def merge_sides(members: list) -> list:
    """The members of a group with the two sides of one pin-wise error (:class:`rvcalib.library.Candidate`
    ``side``: its positive and its negative values are two candidates) as one member: the effect, its probability
    the sum of the sides', its size that of the most probable side whose size lies within that side's range
    (``"unbounded"`` where neither does), and each side's own size and probability under ``sides``. The order of
    first appearance is kept."""
    out: dict[str, dict] = {}
    for m in members:
        if m["name"] not in out:
            out[m["name"]] = dict(m)
            continue
        first = out[m["name"]]
        sides = first.pop("sides", None) or [{"value": first["value"], "probability": first["probability"]}]
        sides.append({"value": m["value"], "probability": m["probability"]})
        bounded = [sd for sd in sides if sd["value"] != "unbounded"]
        first.update(value=max(bounded, key=lambda sd: sd["probability"])["value"] if bounded else "unbounded",
                     probability=sum(sd["probability"] for sd in sides), sides=sides)
    return list(out.values())


def named_effect(c, alpha: float, m: np.ndarray, S: np.ndarray, level: float) -> NamedEffect:
    """A named effect from its parameters' posterior given the effect (mean m, covariance S, physical units) and
    the probability alpha that it is an effect at all."""
    size, ang = c.size(m)
    if c.polar:
        g = m / max(size, 1e-300)
        se = math.sqrt(max(float(g @ S @ g), 0.0))
        z = stats.norm.ppf(0.5 + level / 2)
        ci = [max(0.0, size - z * se), size + z * se]
    else:
        ci = list(mixture_interval(alpha, float(m[0]), math.sqrt(max(float(S[0, 0]), 0.0)), level))
    return NamedEffect(c.effect_name, c.key, c.family, dict(c.instance), c.unit, float(size), ang,
                       [float(x) for x in m], S.tolist(), ci, float(alpha), c.meaning, getattr(c, "prior_scale", None))


def _named(c, effects: list, f: int, F, tau: np.ndarray, level: float, laplace: Laplace | None) -> NamedEffect:
    """The named effect of candidate c (feature f) from every single effect that includes it; its value and
    covariance given the effect from the joint posterior of the chosen parameters where it was chosen."""
    sl = slice(F.starts[f], F.starts[f + 1])
    parts = [(e.alpha[f], e.mean[sl], e.cov_of(F, f)) for e in effects if e.prior_variance > 0 and e.alpha[f] > 1e-3]
    a_tot = min(1.0, sum(a for a, _, _ in parts))
    got = laplace.block(F.starts[f], F.starts[f + 1]) if laplace is not None else None
    if got is not None:
        return named_effect(c, a_tot, got[0], got[1], level)
    m = sum(a * mu for a, mu, _ in parts) / max(a_tot, 1e-300)
    S = sum(a * (cv + np.outer(mu, mu)) for a, mu, cv in parts) / max(a_tot, 1e-300) - np.outer(m, m)
    return named_effect(c, a_tot, m * tau, S * np.outer(tau, tau), level)


def twin_group(eff: NamedEffect, cands: list, f: int, twins: list, level: float) -> dict:
    """A named effect that a swap cannot tell from its twins, as a group: each member with its size (the named
    effect's, and each twin's size after the swap: a value, or a magnitude and an angle) and its probability of
    being the one, exp(-Delta chi^2 / 2) normalised (equal prior odds); the interval is the named effect's."""
    pairs = [(cands[f], 0.0, (eff.value, eff.angle_deg))] + [(cands[g], d, cands[g].size(np.asarray(p)))
                                                             for g, d, p in twins]
    w = np.exp(-0.5 * np.array([d for _, d, _ in pairs]))
    members = [{"name": c.effect_name, "key": c.key, "family": c.family, "instance": dict(c.instance),
                "unit": c.unit, "value": float(v), "angle_deg": a, "probability": float(p),
                "delta_chi2": d} for (c, d, (v, a)), p in zip(pairs, w / w.sum())]
    return {"kind": "physical", "coverage": level, "purity": None, "ci95": eff.ci95,
            "reason": "each fits the data as well in the others' place (delta chi2 below chi2(1) at 95 %)",
            "members": members}


def _unexplained(members: list, cands: list) -> dict:
    ms = [m for m in members if m["family"] == "empirical"]
    c = next(c for c in cands if c.effect_name == ms[0]["name"])
    return {"label": ms[0]["name"], "order": c.order, "kind": c.key, "amplitude_arcsec": ms[0]["value"],
            "phase_deg": ms[0]["angle_deg"], "probability": sum(m["probability"] for m in ms), "members": members}


def read_dense(fc: list, e, F, tau: np.ndarray, level: float, laplace: Laplace | None = None) -> tuple[list, list]:
    """The always-estimated candidates (one fixed effect over all of them) read from the estimator's effect ``e``
    or, where given, the joint posterior ``laplace``: :func:`read_block`."""
    m = e.mean[F.starts[0]:F.starts[1]] * tau
    S = e.cov_of(F, 0) * np.outer(tau, tau)
    got = laplace.block(F.starts[0], F.starts[1]) if laplace is not None else None
    if got is not None:
        m, S = got
    return read_block(fc, m, S, level)


def read_block(fc: list, m: np.ndarray, S: np.ndarray, level: float, check=None, widen=None) -> tuple[list, list]:
    """The candidates ``fc`` with the joint posterior mean ``m`` and covariance ``S`` of their parameters
    (physical units): each named where its interval excludes zero, unless its posterior correlation with another
    is so strong (|r| > 0.95) that only their combination is determined: such a pair is a group with the size each
    would have alone. ``check(span, name)``, where given, is asked of each candidate about to be named (``span``
    its parameters' slice of ``m``) and may refuse it; ``widen(effect, candidate, span)``, where given, returns each
    named effect with its interval widened (:func:`rvcalib.regions.widener`)."""
    sd = np.sqrt(np.maximum(np.diag(S), 1e-300))
    corr = S / np.outer(sd, sd)
    named, groups = [], []
    pos, spans = 0, []
    for c in fc:
        spans.append(slice(pos, pos + c.n_params))
        pos += c.n_params
    tied = set()
    for i in range(len(fc)):
        for j in range(i + 1, len(fc)):
            if fc[i].n_params == fc[j].n_params == 1 and abs(corr[spans[i], spans[j]][0, 0]) > 0.95:
                tied |= {i, j}
                members = []
                for k, o in ((i, j), (j, i)):
                    a, b = spans[k].start, spans[o].start
                    alone = m[a] - S[a, b] / S[b, b] * m[b]      # its posterior mean were the other zero
                    inside = fc[k].lower <= alone <= fc[k].upper
                    members.append({"name": fc[k].effect_name, "key": fc[k].key, "family": fc[k].family,
                                    "instance": dict(fc[k].instance), "unit": fc[k].unit,
                                    "value": float(alone) if inside else "unbounded",
                                    "angle_deg": None, "probability": 1.0})
                groups.append({"kind": "physical", "coverage": level, "purity": float(abs(corr[a, b])),
                               "members": members})
    for i, c in enumerate(fc):
        if i in tied:
            continue
        eff = named_effect(c, 1.0, m[spans[i]], S[spans[i], spans[i]], level)
        if (eff.ci95[0] > 0 or eff.ci95[1] < 0 or (c.polar and eff.ci95[0] > 0)) and \
                (check is None or check(spans[i], c.effect_name)):
            named.append(eff if widen is None else widen(eff, c, spans[i]))
    return named, groups


def read_posterior(F, fit, feature_cands: list, tau: np.ndarray, settings, fixed: tuple,
                   laplace: Laplace | None = None, twins: dict | None = None) -> tuple:
    """Named effects, groups, unexplained structure and diffuse sets from a fit (see the module docstring)."""
    level = settings.coverage
    named, groups, unexplained, diffuse = [], [], [], []
    for f in fixed:
        n, g = read_dense(feature_cands[f], fit.effects[f], F, tau[F.starts[f]:F.starts[f + 1]], level, laplace)
        named += n
        groups += g
    cands = [fc[0] for fc in feature_cands]
    for cs in sorted(credible_sets(F, fit, settings.sparse()), key=lambda s: -s.log_bf):
        if cs.effect < len(fixed):
            continue
        eff = fit.effects[cs.effect]
        members = merge_sides([group_member(cands[f], eff.mean[F.starts[f]:F.starts[f + 1]],
                                       tau[F.starts[f]:F.starts[f + 1]], p)
                               for f, p in zip(cs.features, cs.probabilities)])
        info = {"members": members, "coverage": cs.coverage, "purity": cs.purity, "log_bf": cs.log_bf}
        if not cs.pure(settings.sparse()):
            if all(d["members"] != members for d in diffuse):
                diffuse.append(dict(info, reason="its members do not explain the same signal"))
            continue
        fams = {cands[f].family for f in cs.features}
        if cs.size == 1 and cands[cs.features[0]].physical:
            f = cs.features[0]
            if all(e.name != cands[f].effect_name for e in named):
                eff = _named(cands[f], fit.effects, f, F, tau[F.starts[f]:F.starts[f + 1]], level, laplace)
                if not (eff.ci95[0] > 0 or eff.ci95[1] < 0):   # the data cannot tell its size from zero
                    diffuse.append(dict(info, reason="its 95 % interval includes zero"))
                elif (twins or {}).get(f):      # another candidate fits as well in its place (rvcalib.twins)
                    groups.append(twin_group(eff, cands, f, twins[f], level))
                else:
                    named.append(eff)
        elif fams == {"empirical"}:
            unexplained.append(_unexplained(members, cands))
        else:
            info["kind"] = "physical" if "empirical" not in fams else "physical or unexplained"
            groups.append(info)
    return named, groups, unexplained, diffuse


def _noise(dataset, r: np.ndarray, offs: np.ndarray) -> float:
    """The noise the verdict compares with, arcsec: the smaller of two upper bounds on white reading noise, the
    second differences of the records (:func:`rvrig.dataset.noise_estimate`, pooled over the runs) and the same
    estimate on the residual after the fit. A sharp signature the records hold (one pin's error sampled a few times
    per pin pitch) inflates the first; what the model explains leaves the second."""
    w = np.diff(offs).astype(float)
    s = np.array([noise_estimate(r[offs[i]:offs[i + 1]]) for i in range(len(w))])
    ok = np.isfinite(s)
    resid = float(np.sqrt(np.sum(w[ok] * s[ok] ** 2) / np.sum(w[ok]))) if ok.any() else float("inf")
    return min(float(dataset.noise_arcsec()), resid)


def assemble(dataset, pb, F, fit, scales, theta, te, settings, info: dict) -> CalibrationResult:
    """The result of a finished loop (see :func:`rvcalib.loop.calibrate`); ``pb`` the calibration's problem."""
    tau = np.concatenate(scales)
    n_s = theta.size
    idx = np.concatenate([info["active_s"], n_s + info["active_r"]]).astype(int)
    r = pb.proj(pb.y - te - pb.R @ info["b_r"])
    offs = np.cumsum([0] + [run.n for run in dataset.runs])
    laplace = Laplace(F.X, idx, info["prior_sd"], fit.sigma2, np.concatenate([theta, info["b_r"]]), tau,
                      background=fit.coef_var + fit.coef ** 2, residual=r, offsets=offs) if idx.size else None
    named, groups, unexplained, diffuse = read_posterior(F, fit, pb.feature_cands, tau, settings, pb.fixed, laplace,
                                                         info.get("twins"))
    cap = fit.n_supported - len(pb.fixed) >= settings.max_effects
    return assemble_common(pb, theta, te, info["b_r"], named, groups, unexplained, diffuse, math.sqrt(fit.sigma2),
                           settings, dict(info, cap_binds=cap))


def assemble_common(pb, theta: np.ndarray, te: np.ndarray, b_r: np.ndarray, named: list, groups: list,
                    unexplained: list, diffuse: list, sigma: float, settings, info: dict) -> CalibrationResult:
    """The result from what an estimator read: the state (``theta``, the model TE ``te`` there, the reading
    coefficients ``b_r``), its named effects, groups, unexplained structure and diffuse sets, the noise standard
    deviation it estimated (arcsec), and ``info`` (``rms_before``, ``stopped_by``, ``cap_binds``, ``seconds``,
    ``linearisations``; ``notes``, optional: the estimator's own notes)."""
    dataset = pb.dataset
    resid = pb.y - te - pb.R @ b_r
    consts = pb.proj.constants(resid)
    r = pb.proj(resid)
    offs = np.cumsum([0] + [run.n for run in dataset.runs])
    m = pb.model
    case = m.case_dict(m.groups[0], theta) if hasattr(m, "groups") and m.groups else {}
    return CalibrationResult(
        effects=named, groups=groups, unexplained=unexplained, diffuse=diffuse,
        nuisance=[{"test": t, "constant_arcsec": float(c)} for t, c in zip(pb.tests, consts)],
        rms_before=info["rms_before"], rms_after=float(np.sqrt(np.mean(r ** 2))),
        noise_arcsec=_noise(dataset, r, offs), sigma_arcsec=float(sigma),
        stopped_by=info["stopped_by"], cap_binds=bool(info["cap_binds"]),
        seconds=float(info["seconds"]), linearisations=info["linearisations"], settings=settings.to_dict(),
        notes=list(pb.library.notes) + list(pb.ramp_lines) + list(info.get("notes", [])),
        reducer=dataset.reducer(), calibrated_case=case,
        residuals=[r[offs[i]:offs[i + 1]] for i in range(len(dataset.runs))])
