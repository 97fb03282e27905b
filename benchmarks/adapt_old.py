"""The current loop's result (:class:`rvcalib.results.CalibrationResult`) in the benchmark's result schema.

The schema (the new loop's ``to_dict()``)::

    {"rms_before", "rms_after", "noise_arcsec", "seconds",
     "effects": [{"name", "key", "family", "instance", "unit", "value", "angle_deg", "components", "cov",
                  "ci95"}],
     "groups": [{"members": [{"name", "key", "instance", "unit", "value", "probability"}], ...}],
     "nuisance", "unexplained", "settings", "stopped_by"}

How the old result maps onto it:

* ``instance`` is parsed from the effect's name (``cam_phase[crank=1,disc=0]``; ``pin_radius``: ``{}``);
* ``ci95`` is ``[ci_low, ci_high]`` (the loop's t interval, widened for residual autocorrelation; one-sided
  at a bound of the effect's range);
* a two-component effect's ``components`` are its fitted ``params`` ``(x, y)``. Its ``cov`` is the loop's
  2x2 covariance of ``(x, y)`` where the caller passes it (``covs``: the ``Active.cov`` of the final state,
  used only when that state's parameters are the reported ones), scaled so that its radial variance gives the
  reported half-width at the normal 95 % quantile (the loop's t quantile and autocorrelation widening kept).
  Without it (an effect named at the combined size of several instances, or no ``covs``), the old result
  has only the radial standard error, and ``cov`` is that variance in both directions (isotropic), which
  is an assumption about the tangential uncertainty the old result does not report;
* group members carry ``probability: None`` (the old loop gives none) and keep the group's ``kind``;
* ``nuisance`` is empty (the old loop has no nuisance block; its constant and direction offsets are
  ``unexplained`` terms).
"""
from __future__ import annotations

from typing import Any, Callable

import numpy as np

from score import Z95, parse_name

#: The old loop's default options (:func:`rvcalib.identify.calibrate`), echoed as the result's settings.
OLD_DEFAULTS = {"steps": None, "alpha": 0.01, "max_terms": 6, "top_k": 4, "screen_points": None,
                "time_budget_s": None, "joint": True, "joint_new": 6, "rescreen_every": 0}


def effect_dict(f: Any, covs: dict[str, tuple[np.ndarray, np.ndarray]] | None = None) -> dict[str, Any]:
    """One :class:`rvcalib.results.FittedEffect` in the schema. ``covs``: name -> (parameters, 2x2 covariance)
    of the loop's final state."""
    key, inst = parse_name(f.name)
    d: dict[str, Any] = {"name": f.name, "key": f.key or key, "family": f.family, "instance": inst, "unit": f.unit,
                         "value": float(f.value), "angle_deg": None if f.angle_deg is None else float(f.angle_deg),
                         "components": None, "cov": None, "ci95": [float(f.ci_low), float(f.ci_high)]}
    if f.angle_deg is not None and "x" in f.params:
        p = np.array([f.params["x"], f.params["y"]], dtype=float)
        d["components"] = [float(p[0]), float(p[1])]
        half = 0.5 * (float(f.ci_high) - float(f.ci_low))
        se = float(f.std_err)
        own = (covs or {}).get(f.name)
        if own is not None and se > 0 and np.allclose(own[0], p, rtol=1e-12, atol=0.0):
            C = np.asarray(own[1], dtype=float) * (half / (Z95 * se)) ** 2
        else:
            s = half / Z95
            C = np.diag([s * s, s * s])
        d["cov"] = [[float(x) for x in row] for row in C]
    return d


def group_dict(g: dict[str, Any]) -> dict[str, Any]:
    """One old group in the schema (members with key, instance and ``probability: None``)."""
    members = []
    for m in g.get("members") or []:
        name = str(m.get("name", ""))
        try:
            key, inst = parse_name(name)
        except ValueError:          # an empirical term's label
            key, inst = name, {}
        members.append({"name": name, "key": key, "instance": inst, "unit": m.get("unit"),
                        "value": m.get("value"), "probability": None})
    out = {k: v for k, v in g.items() if k != "members"}
    out["members"] = members
    return out


def from_old(res: Any, covs: dict[str, tuple[np.ndarray, np.ndarray]] | None = None,
             settings: dict[str, Any] | None = None) -> dict[str, Any]:
    """The old loop's result in the schema.

    Parameters
    ----------
    res : CalibrationResult
        The old loop's result (read only through its attributes).
    covs : dict or None
        Effect name -> (parameters, covariance of the parameters) of the loop's final state (``Active.p``,
        ``Active.cov``), for the two-component effects' ``cov``.
    settings : dict or None
        The options it ran with (default :data:`OLD_DEFAULTS`).
    """
    return {"rms_before": float(res.rms_before), "rms_after": float(res.rms_after),
            "noise_arcsec": float(res.noise_arcsec), "seconds": float(res.seconds),
            "effects": [effect_dict(f, covs) for f in res.effects],
            "groups": [group_dict(g) for g in res.groups], "nuisance": [],
            "unexplained": [u.to_dict() for u in res.unexplained],
            "settings": dict(OLD_DEFAULTS if settings is None else settings), "stopped_by": str(res.stopped_by),
            "status": res.status, "verdict": res.verdict, "notes": list(res.notes)}


def old_calibrate(dataset: Any, log: Callable[[str], None] | None = None) -> dict[str, Any]:
    """Run the old loop with its default options (as :func:`rvcalib.identify.calibrate`; ``log`` only prints its
    progress) and return the result in the schema, with the final state's covariances."""
    from threadpoolctl import threadpool_limits

    from rvcalib.identify import Calibrator

    cal = Calibrator(dataset, log=log, **OLD_DEFAULTS)
    with threadpool_limits(limits=1, user_api="blas"):
        res = cal.run()
    covs = {a.effect.name: (np.asarray(a.p, dtype=float), a.cov) for a in cal.active
            if a.cov is not None and a.effect.n_params == 2}
    return from_old(res, covs)

