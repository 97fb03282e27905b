"""Columns of the effects that are not the reducer's physics: reading errors of the encoders and the empirical
block, as functions of the readings (analytic, exact), and the per-test constants of the rig's zero.

Every function returns the column block stacked over the dataset's runs in their order (rows = readings), per
unit parameter of the candidate (:mod:`rvcalib.library`):

* output encoder eccentricity (x, y): a scale mounted with eccentricity ``eps`` at radius ``R`` reads
  ``theta + (eps / R) sin(theta + phi)``; per um of ``(x, y) = eps (cos phi, sin phi)`` the TE changes by
  ``(1e-3 / R) (sin theta_out, cos theta_out)`` rad;
* input encoder eccentricity: the same on the input angle, entering the TE divided by the ratio N, with the
  opposite sign (TE = theta_out - theta_in / N);
* output encoder scale error s (ppm): the reading theta_out (1 + s) adds s theta_out to the TE;
* drift (arcsec per output revolution): the angle travelled since the run's first reading over 360 deg;
* empirical harmonics of order k: ``cos k theta_out, sin k theta_out`` times 1 (common), load / largest load
  (load) or the direction (direction); the empirical constants: the direction, or load / largest load times it.
"""
from __future__ import annotations

import math

import numpy as np

from rvcalib.library import ARCSEC_PER_DEG, ARCSEC_PER_RAD, INPUT_ENCODER_RADIUS_MM, OUTPUT_ENCODER_RADIUS_MM


def _stack(dataset, fn) -> np.ndarray:
    return np.concatenate([fn(r) for r in dataset.runs], axis=0)


def reading_columns(cand, dataset) -> np.ndarray:
    """The TE change (arcsec) per unit of each parameter of a reading or empirical candidate, (n, d)."""
    key = cand.key
    if key == "output_encoder_eccentricity":
        k = 1e-3 / OUTPUT_ENCODER_RADIUS_MM * ARCSEC_PER_RAD
        return _stack(dataset, lambda r: k * np.column_stack([np.sin(r.output_rad), np.cos(r.output_rad)]))
    if key == "input_encoder_eccentricity":
        k = -1e-3 / INPUT_ENCODER_RADIUS_MM * ARCSEC_PER_RAD / dataset.ratio

        def f(r):
            th = np.radians(r.input_deg)
            return k * np.column_stack([np.sin(th), np.cos(th)])
        return _stack(dataset, f)
    if key == "output_encoder_scale_error":
        return _stack(dataset, lambda r: (r.output_deg * ARCSEC_PER_DEG * 1e-6)[:, None])
    if key == "drift_arcsec_per_rev":
        return _stack(dataset, lambda r: (np.abs(r.output_deg - r.output_deg[0]) / 360.0)[:, None])
    if cand.family == "empirical":
        return _empirical(cand, dataset)
    raise ValueError(f"effect {cand.name!r} is solved by rvdyn, not a reading error")


def _empirical(cand, dataset) -> np.ndarray:
    lmax = max(abs(r.load_Nm) for r in dataset.runs) or 1.0

    def factor(r) -> float:
        return {"common": 1.0, "load": r.load_Nm / lmax, "direction": float(r.direction),
                "load_direction": r.direction * r.load_Nm / lmax}[cand.key]

    if cand.order == 0:
        return _stack(dataset, lambda r: np.full((r.n, 1), factor(r)))
    k = cand.order
    return _stack(dataset, lambda r: factor(r) * np.column_stack([np.cos(k * r.output_rad),
                                                                  np.sin(k * r.output_rad)]))


def test_ids(dataset) -> list[str]:
    """The test (one homing of the rig) of each run (:attr:`rvrig.dataset.MeasuredDataset.tests`)."""
    return [dataset.tests.of_run[r.run] for r in dataset.runs]


def nuisance_columns(dataset) -> tuple[np.ndarray, list[str]]:
    """Indicator columns (n, T) of the tests' unknown constants (the rig's zero of each test), and the test ids."""
    ids = test_ids(dataset)
    order = list(dict.fromkeys(ids))
    cols = np.zeros((sum(r.n for r in dataset.runs), len(order)))
    pos = 0
    for r, t in zip(dataset.runs, ids):
        cols[pos:pos + r.n, order.index(t)] = 1.0
        pos += r.n
    return cols, order


def ramp_shown(dataset, z: float = 4.0) -> tuple[bool, list[str]]:
    """Whether any run's record shows a ramp: a trend over the angle travelled that a periodic signal cannot
    give. Per run, the TE is regressed on a constant, the harmonics of the output angle up to order K and the
    angle travelled (a ramp); the record shows a ramp when the ramp's coefficient exceeds ``z`` standard errors.
    On a record of one revolution the ramp is told from the harmonics only by the TE not meeting itself where the
    revolution closes (a periodic signal of any shape meets itself); on a longer record by the revolutions
    drifting apart. K is the largest order with at least three readings per parameter (2K + 2 <= n / 3).

    Returns
    -------
    (bool, list of str)
        The verdict, and one line per run: the ramp over the record and its standard error, arcsec.
    """
    shown, lines = False, []
    for r in dataset.runs:
        if r.n < 12:
            continue
        K = max(1, (r.n // 3 - 2) // 2)
        th = r.output_rad
        travelled = np.abs(r.output_deg - r.output_deg[0]) / 360.0
        A = np.column_stack([np.ones(r.n), travelled] + [f(k * th) for k in range(1, K + 1) for f in (np.cos, np.sin)])
        coef, res, rank, _ = np.linalg.lstsq(A, r.te_arcsec, rcond=None)
        dof = r.n - rank
        if rank < A.shape[1] or dof < 1:
            continue
        s2 = float(np.sum((r.te_arcsec - A @ coef) ** 2)) / dof
        cov = s2 * np.linalg.pinv(A.T @ A)
        ramp = float(coef[1]) * float(travelled[-1])
        se = math.sqrt(max(float(cov[1, 1]), 0.0)) * float(travelled[-1])
        lines.append(f"run {r.run}: ramp {ramp:+.3g} arcsec over the record (standard error {se:.2g}, harmonics to "
                     f"order {K})")
        shown |= abs(ramp) > z * se
    return shown, lines
