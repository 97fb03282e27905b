"""Residual = measured TE - model TE, and its diagnostics.

Per run: RMS and peak (max |r|), the order spectrum per output revolution (amplitudes of the
orders 0-3 and the orders that matter of the reducer (1, Zc, Zp, their doubles, the input orders
N - 1, N, N + 1; :func:`rvcalib.orders.key_orders`) with their neighbours by least squares on the
output angle; an
order at or above half the samples per revolution is aliased and flagged), the lag-1
autocorrelation and the Ljung-Box whiteness test (statsmodels). Over the runs: the dependence of
the mean residual on direction and load (least squares on ``1, d, d*L``: a common offset, a
lost-motion term and a load-proportional wind-up term).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from rvcalib.dataset import MeasuredDataset, RunRecord
from rvcalib.orders import key_orders


def order_spectrum(output_rad: np.ndarray, resid: np.ndarray, orders: list[int] | tuple[int, ...]) -> dict[int, float]:
    """Amplitude (arcsec) of each order of the output angle in a residual, by least squares.

    Parameters
    ----------
    output_rad : ndarray
        Output angle of each sample, rad.
    resid : ndarray
        Residual, arcsec.
    orders : sequence of int
        Orders (cycles per output revolution); 0 is the mean.

    Returns
    -------
    dict of int to float
        Amplitude ``sqrt(a^2 + b^2)`` of ``a cos(k th) + b sin(k th)`` fitted alone (the mean
        removed first); for order 0, the mean.
    """
    th = np.asarray(output_rad, dtype=float)
    r = np.asarray(resid, dtype=float)
    mean = float(r.mean())
    rc = r - mean
    out: dict[int, float] = {}
    for k in orders:
        if k == 0:
            out[0] = mean
            continue
        A = np.column_stack([np.cos(k * th), np.sin(k * th)])
        coef, *_ = np.linalg.lstsq(A, rc, rcond=None)
        out[int(k)] = float(math.hypot(*coef))
    return out


def ramp_fit(output_rad: np.ndarray, resid: np.ndarray, orders: int = 10) -> tuple[float, float]:
    """Non-periodic trend of a residual: ``c + s (th - mean th) + sum_k (a_k cos k th + b_k sin k th)``
    by least squares over the unwrapped output angle ``th`` (rad).

    A ramp is not periodic: over one revolution it is a sawtooth whose jump at the wrap the orders
    up to ``orders`` cannot take, so the slope stays identifiable beside them (a drift in time, an
    encoder scale error). Returns the trend over the record (``s * span``, arcsec) and its t value.
    """
    th = np.asarray(output_rad, dtype=float)
    r = np.asarray(resid, dtype=float)
    span = float(th.max() - th.min())
    cols = [np.ones_like(th), th - th.mean()]
    for k in range(1, orders + 1):
        cols += [np.cos(k * th), np.sin(k * th)]
    A = np.column_stack(cols)
    if r.size <= A.shape[1] + 2 or span <= 0:
        return 0.0, 0.0
    coef, *_ = np.linalg.lstsq(A, r, rcond=None)
    res = r - A @ coef
    s2 = float(res @ res) / (r.size - A.shape[1])
    try:
        var = s2 * float(np.linalg.inv(A.T @ A)[1, 1])
    except np.linalg.LinAlgError:
        return 0.0, 0.0
    se = math.sqrt(var) if var > 0 else float("inf")
    return float(coef[1] * span), float(coef[1] / se) if se > 0 else 0.0


def full_spectrum(output_rad: np.ndarray, resid: np.ndarray, max_order: int) -> np.ndarray:
    """Amplitudes of orders 0..max_order (arcsec), as :func:`order_spectrum`."""
    sp = order_spectrum(output_rad, resid, list(range(max_order + 1)))
    return np.array([abs(sp[k]) for k in range(max_order + 1)])


def samples_per_rev(run: RunRecord) -> float:
    """Samples per output revolution of a run."""
    return run.n / max(run.revolutions, 1e-12)


def ljung_box_p(resid: np.ndarray, lags: int | None = None) -> float:
    """Ljung-Box p-value of a residual (small = not white). ``lags`` default min(10, n/5)."""
    from statsmodels.stats.diagnostic import acorr_ljungbox

    r = np.asarray(resid, dtype=float)
    if r.size < 10 or np.allclose(r, r[0]):
        return float("nan")
    lags = lags or max(1, min(10, r.size // 5))
    res = acorr_ljungbox(r - r.mean(), lags=[lags], return_df=True)
    return float(res["lb_pvalue"].iloc[0])


def lag1_autocorr(resid: np.ndarray) -> float:
    """Lag-1 autocorrelation of a residual (mean removed)."""
    r = np.asarray(resid, dtype=float) - np.mean(resid)
    den = float(r @ r)
    return float(r[1:] @ r[:-1] / den) if den > 0 else 0.0


@dataclass
class RunDiagnostics:
    """Diagnostics of one run's residual.

    Attributes
    ----------
    run : str
    load_Nm : float
    direction : int
    n : int
        Samples.
    rms, peak, mean : float
        arcsec.
    orders : dict of int to float
        Amplitudes of the key orders (:func:`rvcalib.orders.key_orders`) (arcsec; order 0 is the signed mean); NaN for orders at or
        above ``nyquist_order`` (not resolved by the sampling).
    nyquist_order : float
        Half the samples per output revolution; orders at or above it are aliased.
    dominant : list of (int, float)
        The three largest orders (1 .. nyquist) and their amplitudes, arcsec.
    lag1 : float
        Lag-1 autocorrelation.
    ljung_box_p : float
        Ljung-Box p-value (lags min(10, n/5)).
    noise_arcsec : float
        The run's noise estimate (from second differences of the measured TE).
    ramp_arcsec, ramp_t : float
        Non-periodic trend of the residual over the record (arcsec from first to last sample) and
        its t value, fitted beside the orders 1..10 (:func:`ramp_fit`).
    """

    run: str
    load_Nm: float
    direction: int
    n: int
    rms: float
    peak: float
    mean: float
    orders: dict[int, float]
    nyquist_order: float
    dominant: list[tuple[int, float]]
    lag1: float
    ljung_box_p: float
    noise_arcsec: float
    ramp_arcsec: float = 0.0
    ramp_t: float = 0.0

    def to_dict(self) -> dict:
        """JSON-ready form."""
        return {"run": self.run, "load_Nm": self.load_Nm, "direction": self.direction, "n": self.n,
                "rms_arcsec": self.rms, "peak_arcsec": self.peak, "mean_arcsec": self.mean,
                "orders_arcsec": {str(k): v for k, v in self.orders.items()},
                "nyquist_order": self.nyquist_order,
                "dominant_orders": [{"order": k, "amplitude_arcsec": a} for k, a in self.dominant],
                "lag1_autocorr": self.lag1, "ljung_box_p": self.ljung_box_p, "noise_arcsec": self.noise_arcsec,
                "ramp_arcsec": self.ramp_arcsec, "ramp_t": self.ramp_t}


@dataclass
class Diagnostics:
    """Diagnostics of a residual over all runs.

    Attributes
    ----------
    runs : list of RunDiagnostics
    rms : float
        Pooled RMS, arcsec.
    peak : float
        Largest |residual|, arcsec.
    dependence : dict
        Least squares of the run means on ``1, d, d*L``: ``offset_arcsec``, ``direction_arcsec``
        (half the residual lost motion, sign as TE for direction +1: negative = output lags in +1),
        ``direction_load_arcsec_per_Nm`` and ``note``.
    white : bool
        True if no run's Ljung-Box p-value is below 0.01 / runs.
    spectrum : ndarray
        Sample-weighted mean amplitude of orders 0..max over the runs, arcsec.
    """

    runs: list[RunDiagnostics]
    rms: float
    peak: float
    dependence: dict
    white: bool
    spectrum: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def to_dict(self) -> dict:
        """JSON-ready form (without the full spectrum)."""
        return {"rms_arcsec": self.rms, "peak_arcsec": self.peak, "white": self.white,
                "dependence": self.dependence, "runs": [r.to_dict() for r in self.runs]}


def diagnose(dataset: MeasuredDataset, residuals: list[np.ndarray], max_order: int | None = None) -> Diagnostics:
    """Diagnostics of residuals (one array per run, arcsec, in the order of the samples).

    Parameters
    ----------
    dataset : MeasuredDataset
    residuals : list of ndarray
    max_order : int or None
        Highest order of the pooled spectrum (default: the smallest Nyquist order over the runs).
    """
    rds: list[RunDiagnostics] = []
    nyq_all = []
    korders = key_orders(dataset.design)
    for run, r in zip(dataset.runs, residuals):
        th = np.radians(run.input_deg / run.ratio)
        nyq = samples_per_rev(run) / 2.0
        nyq_all.append(nyq)
        orders = order_spectrum(th, r, list(korders))
        for k in orders:
            if k > 0 and k >= nyq:
                orders[k] = float("nan")  # not resolved by the sampling (aliased)
        upper = int(min(nyq - 1, 200))
        sp = full_spectrum(th, r, upper) if upper >= 1 else np.zeros(1)
        idx = np.argsort(sp[1:])[::-1][:3] + 1
        dom = [(int(k), float(sp[k])) for k in idx]
        ramp, ramp_t = ramp_fit(th, r, int(max(1, min(10, nyq - 1))))
        rds.append(RunDiagnostics(run.run, run.load_Nm, run.direction, int(r.size),
                                  float(np.sqrt(np.mean(r ** 2))), float(np.max(np.abs(r))), float(np.mean(r)),
                                  orders, nyq, dom, lag1_autocorr(r), ljung_box_p(r), run.noise_arcsec,
                                  ramp, ramp_t))
    allr = np.concatenate(residuals)
    mo = int(max_order if max_order is not None else max(1, min(200, int(min(nyq_all)) - 1)))
    spec = np.zeros(mo + 1)
    wsum = 0.0
    for run, r in zip(dataset.runs, residuals):
        spec += r.size * full_spectrum(np.radians(run.input_deg / run.ratio), r, mo)
        wsum += r.size
    spec /= wsum
    dep = direction_load_dependence(dataset, residuals)
    pmin = min((d.ljung_box_p for d in rds if np.isfinite(d.ljung_box_p)), default=1.0)
    return Diagnostics(rds, float(np.sqrt(np.mean(allr ** 2))), float(np.max(np.abs(allr))), dep,
                       bool(pmin >= 0.01 / len(rds)), spec)


def direction_load_dependence(dataset: MeasuredDataset, residuals: list[np.ndarray]) -> dict:
    """Least-squares split of the run means into offset, direction and direction x load terms.

    Returns
    -------
    dict
        ``offset_arcsec``, ``direction_arcsec``, ``direction_load_arcsec_per_Nm`` (NaN where the
        runs do not separate the term) and ``note``.
    """
    m = np.array([float(np.mean(r)) for r in residuals])
    d = np.array([float(r.direction) for r in dataset.runs])
    L = np.array([float(r.load_Nm) for r in dataset.runs])
    cols = [np.ones_like(m)]
    names = ["offset_arcsec"]
    if np.ptp(d) > 0:
        cols.append(d)
        names.append("direction_arcsec")
    if np.ptp(L) > 0 and np.linalg.matrix_rank(np.column_stack(cols + [d * L])) == len(cols) + 1:
        cols.append(d * L)
        names.append("direction_load_arcsec_per_Nm")
    A = np.column_stack(cols)
    coef, *_ = np.linalg.lstsq(A, m, rcond=None)
    out = {"offset_arcsec": float("nan"), "direction_arcsec": float("nan"),
           "direction_load_arcsec_per_Nm": float("nan")}
    for n_, c in zip(names, coef):
        out[n_] = float(c)
    missing = [n_ for n_ in ("direction_arcsec", "direction_load_arcsec_per_Nm") if n_ not in names]
    out["note"] = ("run means = offset + direction * (direction_arcsec + load * direction_load_arcsec_per_Nm)"
                   + (f"; not separable from these runs: {', '.join(missing)}" if missing else ""))
    out["run_means_arcsec"] = {r.run: float(v) for r, v in zip(dataset.runs, m)}
    return out


def structured_noise(dataset: MeasuredDataset, residuals: list[np.ndarray], low_orders: int = 10) -> float:
    """Noise of residuals that leftover structure at the orders that matter cannot inflate, arcsec.

    Per run, the residual is fitted by least squares with a constant, a ramp over the record, orders
    1..``low_orders`` and every key order of the reducer (:func:`rvcalib.orders.key_orders`: 1, Zc,
    Zp, their doubles, the input orders, neighbours) at the measured output angles; the noise
    variance is the pooled residual sum of squares over the pooled degrees of freedom
    (``n - rank``). Unlike second differences (:func:`rvcalib.dataset.noise_estimate`), which count
    leftover orders 39/40/80 as noise, this estimate is unbiased for white noise whatever structure
    is left at those orders.
    """
    orders = sorted(set(range(1, low_orders + 1)) | {k for k in key_orders(dataset.design) if k > 0})
    rss, dof = 0.0, 0
    for run, r in zip(dataset.runs, residuals):
        r = np.asarray(r, dtype=float)
        th = np.radians(run.input_deg / run.ratio)
        t = (th - th.mean()) / max(float(np.ptp(th)), 1e-12)
        cols = [np.ones_like(th), t]
        for k in orders:
            cols += [np.cos(k * th), np.sin(k * th)]
        A = np.column_stack(cols)
        coef, _, rank, _ = np.linalg.lstsq(A, r, rcond=1e-10)
        e = r - A @ coef
        if r.size - rank < 5:
            continue
        rss += float(e @ e)
        dof += int(r.size - rank)
    if dof == 0:
        return float("nan")
    return math.sqrt(rss / dof)
