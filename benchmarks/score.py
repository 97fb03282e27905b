"""Score one calibration result against the answer of its realistic draw: the pass rule of the protocol.

Inputs
------
* a result in the loop's schema (``to_dict()`` of the new loop; :mod:`adapt_old` for the old one):
  ``rms_after``, ``effects`` (each ``name, key, family, instance, unit, value, angle_deg, components,
  cov, ci95``), ``groups``, ...;
* the draw's answer (:mod:`realistic`): ``expected_effects`` (each Table 4 error's ``key``, ``instance``,
  ``value`` and ``angle_deg``; the compliance), ``noise_te_arcsec`` (the true TE noise: the output
  encoder's and the input encoder's divided by the ratio, in quadrature).

Rules (all must hold for a pass)
--------------------------------
1. **Residual.** ``rms_after <= 1.2 * noise_te_arcsec``.
2. **Compliance.** A named ``torsional_compliance_arcsec_per_Nm`` within 10 % of the truth's. Not named
   is a fail.
3. **Named effects.** Each named effect is matched to the truth by ``(key, instance)`` (the instance as a
   dict of indices; ``{}`` for an error of all pins and for the errors without instances). A match must lie
   within ``max(1 um, 25 % of |truth|)`` of its truth (``max(0.002 deg, 25 %)`` for a ``deg`` effect; for
   another unit, 25 %). The distance is ``|value - truth|`` for a one-component effect and, for a
   two-component effect (eccentricities, the pin circle offset: ``value`` is the magnitude along
   ``angle_deg``), the length of the difference of the components, a truth's components being
   ``value * (cos a, sin a)``. The compliance is judged by rule 2 instead (its tolerance is 10 %).
4. **Nothing false named.** A named Table 4 effect the truth does not hold (no error of that key and
   instance) must be at most ``max(1 um, 25 % of the draw's largest um error)`` in size (for ``deg``:
   ``max(0.002 deg, 25 % of the largest deg error)``); the size of a two-component effect is the length of
   its components. A named model or measurement effect the truth does not hold is a false name whatever
   its size.
5. A result that is an error (the method raised) fails.

Groups (``groups``: members the data cannot split, the honest "cannot tell" answer) are not named effects:
they are listed and neither pass nor fail a draw.

Coverage (pooled over draws by :func:`pool`)
--------------------------------------------
For every named effect, its truth (``0`` for an effect the truth does not hold: the effect is absent) is
covered when it lies inside the 95 % interval ``ci95 = [lo, hi]`` (one component), or, for a two-component
effect, when the Mahalanobis distance of the truth's components from the named ones under ``cov`` is within
the chi-square(2) 95 % quantile (5.991). A two-component effect without a usable ``cov`` counts as not
covered.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import stats

RMS_FACTOR = 1.2                    # rule 1
COMPLIANCE_KEY = "torsional_compliance_arcsec_per_Nm"
COMPLIANCE_REL = 0.10               # rule 2
REL_TOL = 0.25                      # rules 3 and 4
ABS_TOL = {"um": 1.0, "deg": 0.002}  # rules 3 and 4, per unit
CHI2_2_95 = float(stats.chi2.ppf(0.95, 2))
Z95 = float(stats.norm.ppf(0.975))
TABLE4 = "table4"

_NAME = re.compile(r"^(?P<key>[^\[\]]+?)(?:\[(?P<inst>[^\]]*)\])?$")


def instance_key(inst: dict[str, Any] | None) -> tuple[tuple[str, int], ...]:
    """A hashable, order-free form of an instance dict (entries of None, i.e. all pins, left out)."""
    return tuple(sorted((str(k), int(v)) for k, v in (inst or {}).items() if v is not None))


def parse_name(name: str) -> tuple[str, dict[str, int]]:
    """Key and instance of a library name such as ``cam_phase[crank=1,disc=0]`` (``pin_radius``: ``{}``).

    Raises
    ------
    ValueError
        For a name not of that form.
    """
    m = _NAME.match(name.strip())
    if not m:
        raise ValueError(f"effect name {name!r} is not of the form key or key[index=n,...]")
    inst: dict[str, int] = {}
    for part in filter(None, (m.group("inst") or "").split(",")):
        k, eq, v = part.partition("=")
        if not eq or not v.strip().lstrip("-").isdigit():
            raise ValueError(f"effect name {name!r}: instance part {part!r} is not index=integer")
        inst[k.strip()] = int(v)
    return m.group("key"), inst


@dataclass(frozen=True)
class Truth:
    """One effect of the truth: key, instance, unit, value (magnitude of a two-component one) and angle."""

    key: str
    instance: tuple[tuple[str, int], ...]
    unit: str
    value: float
    angle_deg: float | None

    @property
    def components(self) -> np.ndarray | None:
        """``value * (cos a, sin a)`` of a two-component truth, else None."""
        if self.angle_deg is None:
            return None
        a = math.radians(self.angle_deg)
        return np.array([self.value * math.cos(a), self.value * math.sin(a)])


def truths(answer: dict[str, Any]) -> dict[tuple[str, tuple], Truth]:
    """The answer's effects keyed by ``(key, instance_key)``."""
    out = {}
    for e in answer["expected_effects"]:
        t = Truth(e["key"], instance_key(e.get("instance")), e["unit"], float(e["value"]), e.get("angle_deg"))
        out[(t.key, t.instance)] = t
    return out


def components_of(e: dict[str, Any]) -> np.ndarray | None:
    """A named effect's two components (``components``, else ``value`` along ``angle_deg``); None for a
    one-component effect."""
    if e.get("components") is not None and len(e["components"]) == 2:
        return np.asarray(e["components"], dtype=float)
    if e.get("components") is not None:
        return None
    if e.get("angle_deg") is None:
        return None
    a = math.radians(float(e["angle_deg"]))
    return float(e["value"]) * np.array([math.cos(a), math.sin(a)])


def largest_error(tr: dict[tuple[str, tuple], Truth], unit: str) -> float:
    """The largest size of the truth's Table 4 errors in ``unit`` (0 if none)."""
    return max((abs(t.value) for t in tr.values() if t.unit == unit and t.key != COMPLIANCE_KEY), default=0.0)


def covered(e: dict[str, Any], truth_value: float, truth_comp: np.ndarray | None) -> bool:
    """Whether the named effect's 95 % interval (or region) holds the truth (module docstring)."""
    c = components_of(e)
    if c is not None:
        t = truth_comp if truth_comp is not None else np.zeros(2)
        cov = e.get("cov")
        if cov is None:
            return False
        C = np.asarray(cov, dtype=float)
        if C.shape != (2, 2) or not np.all(np.isfinite(C)):
            return False
        d = c - t
        try:
            m2 = float(d @ np.linalg.solve(C, d))
        except np.linalg.LinAlgError:
            return False
        return bool(np.isfinite(m2) and 0.0 <= m2 <= CHI2_2_95)
    lo, hi = (e.get("ci95") or [math.nan, math.nan])[:2]
    return bool(lo is not None and hi is not None and lo <= truth_value <= hi)


def judge_effect(e: dict[str, Any], tr: dict[tuple[str, tuple], Truth]) -> dict[str, Any]:
    """Rules 3 and 4 and the coverage for one named effect: a dict with ``name, key, instance, unit, value,
    truth, distance, tolerance, verdict`` (``ok``, ``off``, ``false name``, ``small extra``; the compliance
    by rule 2) and ``covered``."""
    key = e["key"]
    inst = instance_key(e.get("instance"))
    unit = e.get("unit", "")
    t = tr.get((key, inst))
    c = components_of(e)
    size = float(np.hypot(*c)) if c is not None else float(e["value"])
    rec: dict[str, Any] = {"name": e.get("name", key), "key": key, "instance": dict(inst), "unit": unit,
                           "value": float(e["value"]), "angle_deg": e.get("angle_deg"), "family": e.get("family"),
                           "truth": None if t is None else t.value,
                           "truth_angle_deg": None if t is None else t.angle_deg}
    if t is not None:
        tc = t.components
        dist = float(np.linalg.norm(c - tc)) if c is not None and tc is not None else abs(size - t.value)
        tol = COMPLIANCE_REL * abs(t.value) if key == COMPLIANCE_KEY else \
            max(ABS_TOL.get(unit, 0.0), REL_TOL * abs(t.value))
        verdict = "ok" if dist <= tol else "off"
        rec.update(distance=dist, tolerance=tol, verdict=verdict, covered=covered(e, t.value, tc))
        return rec
    if e.get("family") == TABLE4 and unit in ABS_TOL:
        tol = max(ABS_TOL[unit], REL_TOL * largest_error(tr, unit))
        verdict = "small extra" if abs(size) <= tol else "false name"
    else:
        tol, verdict = 0.0, "false name"
    rec.update(distance=abs(size), tolerance=tol, verdict=verdict, covered=covered(e, 0.0, None))
    return rec


def score(result: dict[str, Any] | None, answer: dict[str, Any], error: str | None = None) -> dict[str, Any]:
    """Score one result against its draw's answer (module docstring).

    Parameters
    ----------
    result : dict or None
        The result in the loop's schema; None when the method raised.
    answer : dict
        The draw's answer file.
    error : str or None
        The method's error message, if it raised (rule 5).

    Returns
    -------
    dict
        ``passed`` (bool), ``reasons`` (why not, one string each), ``rms_after``, ``noise``, ``rms_ratio``,
        ``compliance``, ``compliance_truth``, ``effects`` (:func:`judge_effect` of each named effect),
        ``groups`` (the result's groups as given), ``covered`` and ``n_intervals`` (for :func:`pool`).
    """
    noise = float(answer["noise_te_arcsec"])
    tr = truths(answer)
    comp_t = tr.get((COMPLIANCE_KEY, ()))
    out: dict[str, Any] = {"noise": noise, "compliance_truth": None if comp_t is None else comp_t.value,
                           "effects": [], "groups": [], "covered": 0, "n_intervals": 0, "reasons": []}
    if result is None or error is not None:
        out.update(passed=False, rms_after=None, rms_ratio=None, compliance=None,
                   reasons=[f"the method raised: {error or 'no result'}"])
        return out
    reasons = out["reasons"]
    rms = float(result["rms_after"])
    out.update(rms_after=rms, rms_ratio=rms / noise)
    if not rms <= RMS_FACTOR * noise:
        reasons.append(f"RMS after {rms:.4g} arcsec > {RMS_FACTOR:g} x noise {noise:.4g}")
    effects = [judge_effect(e, tr) for e in result.get("effects") or []]
    comp = [r for r in effects if r["key"] == COMPLIANCE_KEY]
    out["compliance"] = comp[0]["value"] if comp else None
    if comp_t is not None and not comp:
        reasons.append("the compliance is not named")
    for r in effects:
        if r["verdict"] in ("off", "false name"):
            reasons.append(f"{r['verdict']}: {r['name']} = {r['value']:+.4g} {r['unit']} (truth "
                           f"{'none' if r['truth'] is None else format(r['truth'], '+.4g')}, distance "
                           f"{r['distance']:.4g} > {r['tolerance']:.4g})")
    out.update(effects=effects, groups=list(result.get("groups") or []), n_intervals=len(effects),
               covered=sum(bool(r["covered"]) for r in effects), passed=not reasons)
    return out


def pool(scores: list[dict[str, Any]]) -> dict[str, Any]:
    """Pass count and pooled coverage over draws: ``draws, passed, covered, n_intervals, coverage`` (None
    when no interval was named)."""
    cov = sum(s["covered"] for s in scores)
    n = sum(s["n_intervals"] for s in scores)
    return {"draws": len(scores), "passed": sum(bool(s["passed"]) for s in scores), "covered": cov,
            "n_intervals": n, "coverage": cov / n if n else None}


def _num(x: Any) -> str:
    return f"{x:+.4g}" if isinstance(x, (int, float)) else str(x)


def _inst_text(inst: dict[str, int]) -> str:
    return "[" + ",".join(f"{k}={v}" for k, v in inst.items()) + "]" if inst else ""


def score_lines(s: dict[str, Any]) -> list[str]:
    """A human account of one score: each named effect against its truth, then the groups."""
    out = []
    for r in s["effects"]:
        tru = "none" if r["truth"] is None else f"{r['truth']:+.4g}"
        if r.get("truth_angle_deg") is not None:
            tru += f" at {r['truth_angle_deg']:.1f} deg"
        ang = f" at {r['angle_deg']:.1f} deg" if r.get("angle_deg") is not None else ""
        out.append(f"{r['key']}{_inst_text(r['instance'])} = {r['value']:+.4g} {r['unit']}{ang} vs truth {tru}: "
                   f"{r['verdict']} (distance {r['distance']:.3g}, tolerance {r['tolerance']:.3g}); "
                   f"interval {'covers' if r['covered'] else 'misses'}")
    for g in s["groups"]:
        mem = ", ".join(f"{m.get('name')} {_num(m.get('value'))}"
                        + (f" (p {_num(m['probability'])})" if m.get("probability") is not None else "")
                        for m in g.get("members") or [])
        out.append(f"group{' ' + g['kind'] if g.get('kind') else ''}: {mem}")
    return out
