"""The forward model of a measured run: rvdyn TE at the readings, or on a uniform grid.

The model TE is solved by :func:`rvdyn.te.run_te` (analytic contacts). TE is periodic in one output
revolution (input N turns, N the ratio of the case's design; see :mod:`rvcalib.orders`), so angles
are taken modulo it. Every design constant comes from the case (its ``design`` object). :func:`grid_te` solves a uniform grid of ``steps`` input angles over one output
revolution (the screening and the coarse fits of :mod:`rvcalib.identify`); :func:`te_at` solves
exactly at given angles (every reading of a run: interpolating a grid is not exact, see there). Solutions are cached by the case's content hash (which holds the
load and the direction) and the angles, so identical conditions and repeated trial values are
solved once per process; the cache is bounded by :data:`CACHE_BYTES`.

The measurement effects (encoder eccentricities) and empirical harmonic terms are not physics of
the reducer; they are added to the model TE here as reading errors, see :mod:`rvcalib.effects`.
"""
from __future__ import annotations

import copy
import hashlib
import math
import time
from collections import OrderedDict
from typing import Any

import numpy as np

from rvcad.errors import Case
from rvdyn.te import run_te

from rvcalib.orders import period_deg

#: Maximum number of cached solutions.
CACHE_SIZE = 20000
#: Maximum bytes of cached solutions (least recently used ones go first).
CACHE_BYTES = 256 * 2 ** 20

_CACHE: "OrderedDict[tuple, np.ndarray]" = OrderedDict()
_STATS = {"solves": 0, "hits": 0, "seconds": 0.0, "bytes": 0}


def _store(key: tuple, value: np.ndarray) -> None:
    value.setflags(write=False)
    _CACHE[key] = value
    _STATS["bytes"] += value.nbytes
    while len(_CACHE) > CACHE_SIZE or (_STATS["bytes"] > CACHE_BYTES and len(_CACHE) > 1):
        _, old = _CACHE.popitem(last=False)
        _STATS["bytes"] -= old.nbytes


class ModelEvaluationError(ValueError):
    """The reducer model cannot be evaluated at these parameters (interference, no convergence)."""


def cache_stats() -> dict[str, float]:
    """Solver calls, cache hits and solver seconds of this process."""
    return dict(_STATS)


def clear_cache() -> None:
    """Forget all cached solutions."""
    _CACHE.clear()
    _STATS["bytes"] = 0


def grid_angles_deg(steps: int, period: float) -> np.ndarray:
    """Input angles of the uniform grid over one output revolution, deg (``k * period / steps``;
    ``period`` = N * 360 deg, see :func:`rvcalib.orders.period_deg`)."""
    return np.arange(steps) * (float(period) / steps)


def case_period_deg(case_dict: dict[str, Any]) -> float:
    """Input angle of one output revolution of a case JSON's design, deg."""
    try:
        case = Case.from_dict(case_dict)
    except ValueError as exc:
        raise ModelEvaluationError(str(exc)) from None
    return period_deg(case.design)


def grid_te(case_dict: dict[str, Any], steps: int, solver: str = "analytic") -> np.ndarray:
    """Model TE (arcsec) on the uniform grid of one output revolution, ascending input angle
    (:func:`te_at` at :func:`grid_angles_deg`).

    Parameters
    ----------
    case_dict : dict
        Case JSON (``errors``, ``model``, ``load_Nm``, ``direction``).
    steps : int
        Grid points per output revolution.
    solver : str
        rvdyn contact provider.

    Raises
    ------
    ModelEvaluationError
        If rvdyn refuses the case (interference beyond the contact law) or does not converge.
    """
    return te_at(case_dict, grid_angles_deg(int(steps), case_period_deg(case_dict)), solver)


def te_at(case_dict: dict[str, Any], input_deg: np.ndarray, solver: str = "analytic") -> np.ndarray:
    """Model TE (arcsec) exactly at given input angles (deg, any revolution), in their order.

    TE is periodic in one output revolution, so each angle is reduced modulo it and equal angles
    (to 1e-9 deg) are solved once. This is the forward model for readings that are not on a
    uniform grid: the TE has kinks where pins pick up or drop load and content up to many times
    the input order N, so interpolating a grid solution is not exact (a single-pin pitch error
    of 0.02 deg interpolated from 1440 points per revolution is off by 0.18 arcsec RMS, 1.3 arcsec
    at the worst sample).

    Raises
    ------
    ModelEvaluationError
        If rvdyn refuses the case (interference beyond the contact law) or does not converge.
    """
    try:
        case = Case.from_dict(case_dict)
    except ValueError as exc:
        raise ModelEvaluationError(str(exc)) from None
    period = period_deg(case.design)
    x = np.mod(np.asarray(input_deg, dtype=float), period)
    xr = np.round(x, 9)
    u, inv = np.unique(xr, return_inverse=True)
    u_run = u[::-1] if case.direction == -1 else u  # in the order of motion
    key = (case.key(), "at", hashlib.blake2b(u.tobytes(), digest_size=16).hexdigest(), solver)
    hit = _CACHE.get(key)
    if hit is None:
        t0 = time.perf_counter()
        pts = u_run if u_run.size >= 2 else np.append(u_run, u_run + period / 2)
        try:
            res = run_te(case, solver=solver, theta_in_deg=pts)
        except (ValueError, RuntimeError) as exc:
            raise ModelEvaluationError(f"rvdyn could not evaluate the case: {exc}") from None
        _STATS["solves"] += 1
        _STATS["seconds"] += time.perf_counter() - t0
        te = res.table["te_arcsec"].to_numpy()[:u_run.size]
        hit = (te[::-1] if case.direction == -1 else te).copy()
        _store(key, hit)
    else:
        _CACHE.move_to_end(key)
        _STATS["hits"] += 1
    return hit[inv]


def merge_case(base: dict[str, Any], errors: list[tuple[str, dict]] | None = None,
               model: dict[str, float] | None = None) -> dict[str, Any]:
    """A copy of a case JSON with additional error instances and model options.

    Parameters
    ----------
    base : dict
        Case JSON; its ``errors`` values may be numbers (default instance), objects or lists.
    errors : list of (key, item)
        Error instances to add, each an object ``{"value": v, <instance keys>, "angle_deg": a}``.
    model : dict
        Model options to set (they replace the base's).
    """
    d = copy.deepcopy(base)
    errs: dict[str, Any] = d.setdefault("errors", {})
    for key, item in errors or []:
        cur = errs.get(key)
        if cur is None:
            errs[key] = [item]
            continue
        if isinstance(cur, list) and cur and not isinstance(cur[0], dict):
            # pin-wise list of numbers: add to the right pin(s)
            cur = list(cur)
            pins = range(len(cur)) if item.get("pin") is None else [item["pin"]]
            for p in pins:
                cur[p] = float(cur[p]) + float(item["value"])
            errs[key] = cur
            continue
        items = cur if isinstance(cur, list) else [cur]
        items = [x if isinstance(x, dict) else {"value": x} for x in items]
        errs[key] = items + [item]
    if model:
        m = d.setdefault("model", {})
        m.update(model)
    return d


def fmt_angle(deg: float) -> float:
    """An angle wrapped to (-180, 180] deg."""
    a = math.fmod(deg + 180.0, 360.0)
    if a <= 0:
        a += 360.0
    return a - 180.0
