"""Orders over the whole band the readings resolve, and what is locked to the order or to a frequency.

Order spectrum of a run (:func:`order_spectrum`): the measured TE over the largest whole number R of
output revolutions in the record, resampled by a cubic spline onto an even grid of the output angle
(as many points per revolution as the run has readings) and Fourier transformed: orders k / R up to
the readings' Nyquist order, amplitude A and phase phi of ``A cos(k theta + phi)`` with theta the
output angle reading (rad), so forward and backward runs share their phases.

Lines (:func:`find_lines`): local maxima of the amplitude above ``c`` times the running median of
the amplitudes around them (a noise floor). For noise alone the amplitudes are Rayleigh distributed,
``P(A > c median) = 2^(-c^2)``, so ``c = sqrt(log2(n / p_false))`` keeps the chance of one false line
among the n orders at ``p_false`` (0.01 by default; c = 4.4 for 5400 orders).

Order-locked or fixed-frequency (:func:`separate`):

* runs at two or more speeds (output revolutions per second from ``time_s``): a line of run A at order
  o has frequency ``o f_A``; in a run B at another speed an order-locked line stays at order o, a
  fixed-frequency line moves to order ``o f_A / f_B``. Each line is classed by what the other speeds
  show (both or neither: ambiguous; the two places closer than the resolution: not separable);
* one speed: a line at an order the reducer has (:func:`reducer_orders`: the output order, the lobe
  order Zc, the pin (crank) order Zp, the sun and input orders N - 1 and N, the stage I mesh
  ``Z1 (N - 1)``, their harmonics up to ``max_harmonic`` and sidebands at +-1, +-n_c and +-2 n_c,
  n_c the crank count) is taken as the reducer's; any other line is reported as a fixed-frequency
  line and not claimed for the reducer (or a design other than the one given, e.g. another crank count).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import interpolate, ndimage

from rvcad.params import Design
from rvrig.dataset import MeasuredDataset, RunRecord
from rvrig.orders import base_orders

#: Chance of one false line in a spectrum (see the module docstring).
P_FALSE = 0.01
#: Half-width of the running median that sets the noise floor, orders.
FLOOR_HALF_WIDTH = 25
#: Highest harmonic of each of the reducer's base orders taken as the reducer's with one speed.
MAX_HARMONIC = 8
#: Relative difference of two runs' speeds above which they count as two speeds.
SPEED_TOLERANCE = 1e-3


@dataclass
class OrderSpectrum:
    """Order spectrum of one run.

    Attributes
    ----------
    run : str
    orders : ndarray
        Orders, cycles per output revolution (k / R).
    amplitude_arcsec, phase_deg : ndarray
        ``A cos(order * theta + phi)``, theta the output angle reading (rad).
    revolutions : int
        Whole revolutions R used.
    rev_hz : float or None
        Output revolutions per second (from ``time_s``), None without times.
    mean_arcsec : float
        Mean TE over the R revolutions, evenly in angle.
    """

    run: str
    orders: np.ndarray
    amplitude_arcsec: np.ndarray
    phase_deg: np.ndarray
    revolutions: int
    rev_hz: float | None
    mean_arcsec: float

    @property
    def nyquist_order(self) -> float:
        """Highest order the readings resolve (half the points per revolution)."""
        return float(self.orders[-1])

    def at(self, order: float) -> tuple[float, float]:
        """Amplitude (arcsec) and phase (deg) at the bin nearest ``order``."""
        i = int(np.argmin(np.abs(self.orders - order)))
        return float(self.amplitude_arcsec[i]), float(self.phase_deg[i])


def order_spectrum(run: RunRecord) -> OrderSpectrum:
    """Order spectrum of a run's TE up to the readings' Nyquist order (module docstring)."""
    th = np.asarray(run.output_deg, dtype=float)
    te = run.te_arcsec
    o = np.argsort(th)
    th, te = th[o], te[o]
    keep = np.concatenate([[True], np.diff(th) > 0])
    th, te = th[keep], te[keep]
    revs = run.revolutions
    r = max(1, int(math.floor(revs + 1e-6)))
    per_rev = int(round(th.size / revs))
    m = r * per_rev
    grid = th[0] + np.arange(m) * (360.0 * r / m)
    x = interpolate.make_interp_spline(th, te, k=3)(np.clip(grid, th[0], th[-1]))
    spec = np.fft.rfft(x) / m
    k = np.arange(spec.size)
    amp = 2.0 * np.abs(spec)
    amp[0] = abs(spec[0].real)
    if m % 2 == 0:
        amp[-1] = abs(spec[-1])
    phase = np.angle(spec) - k / r * math.radians(th[0])
    rev_hz = None
    if run.time_s is not None:
        dt = float(np.max(run.time_s) - np.min(run.time_s))
        rev_hz = abs(float(run.output_deg[-1] - run.output_deg[0])) / 360.0 / dt if dt > 0 else None
    return OrderSpectrum(run=run.run, orders=k / r, amplitude_arcsec=amp,
                         phase_deg=np.degrees(np.angle(np.exp(1j * phase))), revolutions=r, rev_hz=rev_hz,
                         mean_arcsec=float(spec[0].real))


def threshold(spec: OrderSpectrum, p_false: float = P_FALSE) -> np.ndarray:
    """Amplitude a line must exceed at each order: ``c`` times the running median (module docstring)."""
    n = spec.orders.size - 1
    c = math.sqrt(math.log2(max(n, 2) / p_false))
    width = 2 * FLOOR_HALF_WIDTH * spec.revolutions + 1
    a = spec.amplitude_arcsec[1:]                       # the mean (order 0) is no part of the floor
    floor = ndimage.median_filter(a, size=min(width, a.size), mode="reflect")
    return c * np.concatenate([[np.inf], floor])


def find_lines(spec: OrderSpectrum, p_false: float = P_FALSE) -> list[dict]:
    """Lines of a spectrum: local maxima above :func:`threshold`, order 0 excluded.

    Returns
    -------
    list of dict
        ``order``, ``amplitude_arcsec``, ``phase_deg``, ``frequency_Hz`` (None without times), by order.
    """
    a = spec.amplitude_arcsec
    thr = threshold(spec, p_false)
    peak = np.zeros(a.size, dtype=bool)
    peak[1:-1] = (a[1:-1] >= a[:-2]) & (a[1:-1] >= a[2:])
    peak[1] = a.size > 2 and a[1] >= a[2]                # the mean (order 0) is no neighbour
    peak[-1] = a[-1] >= a[-2]
    idx = np.flatnonzero(peak & (a > thr))
    return [{"order": float(spec.orders[i]), "amplitude_arcsec": float(a[i]), "phase_deg": float(spec.phase_deg[i]),
             "frequency_Hz": float(spec.orders[i] * spec.rev_hz) if spec.rev_hz else None} for i in idx]


def reducer_orders(design: Design, max_order: float, max_harmonic: int = MAX_HARMONIC) -> dict[int, str]:
    """Orders the reducer has, up to ``max_order``, with a label each (module docstring)."""
    nc = int(design.n_cranks)
    bases = [(name, b) for name, b in base_orders(design).items() if name != "output"]
    out: dict[int, str] = {}
    for h in range(1, max_harmonic + 1):
        out.setdefault(h, f"output x{h}")
    for side in (0, 1, nc, 2 * nc):
        for name, b in bases:
            for h in range(1, max_harmonic + 1):
                c = h * b
                tag = f"{name} {b}" if h == 1 else f"{h} x {name} {b}"
                for s in ((0,) if side == 0 else (side, -side)):
                    k = c + s
                    if 0 < k <= max_order and k not in out:
                        why = "" if s == 0 else f" {'+' if s > 0 else '-'} {abs(s)}" + (
                            " (crank count)" if abs(s) == nc else " (2 x crank count)" if abs(s) == 2 * nc else "")
                        out[k] = tag + why
    return dict(sorted(out.items()))


def _present(spec: OrderSpectrum, order: float, half: float, thr: np.ndarray) -> bool | None:
    """True if ``spec`` has a line within ``order +- half`` (None: beyond its Nyquist order)."""
    if order + half < 0 or order - half > spec.nyquist_order:
        return None
    sel = np.abs(spec.orders - order) <= half
    if not sel.any():
        sel = np.abs(spec.orders - order) == np.min(np.abs(spec.orders - order))
    return bool(np.any(spec.amplitude_arcsec[sel] > thr[sel]))


def _class_by_speed(line: dict, spec: OrderSpectrum, others: list[tuple[OrderSpectrum, np.ndarray]]) -> str:
    """``order``, ``frequency``, ``ambiguous``, ``not separable`` or ``seen at one speed only`` for one line of ``spec`` (module docstring)."""
    o = line["order"]
    votes = {"order": 0, "frequency": 0, "both": 0}
    separable = False
    for other, thr in others:
        rho = spec.rev_hz / other.rev_hz
        half = 0.5 * rho / spec.revolutions + 1.0 / other.revolutions
        if abs(o * rho - o) < 2.0 * half:
            continue
        at_order, at_freq = _present(other, o, half, thr), _present(other, o * rho, half, thr)
        separable |= at_order is not None and at_freq is not None
        if at_order and at_freq:
            votes["both"] += 1
        elif at_order:
            votes["order"] += 1
        elif at_freq:
            votes["frequency"] += 1
    if not separable:
        return "not separable"
    if votes["order"] and not votes["frequency"] and not votes["both"]:
        return "order"
    if votes["frequency"] and not votes["order"] and not votes["both"]:
        return "frequency"
    return "seen at one speed only" if not any(votes.values()) else "ambiguous"


def _group(lines: list[dict], key: str, tol: float) -> list[dict]:
    """Lines of several runs merged when their ``key`` values lie within ``tol``: the largest kept, with
    ``runs`` (ids) and ``amplitudes_arcsec`` (per run)."""
    out: list[dict] = []
    for ln in sorted(lines, key=lambda x: x[key]):
        if out and abs(ln[key] - out[-1][key]) <= tol:
            g = out[-1]
            g["runs"].append(ln["run"])
            g["amplitudes_arcsec"][ln["run"]] = ln["amplitude_arcsec"]
            if ln["amplitude_arcsec"] > g["amplitude_arcsec"]:
                g.update({k: v for k, v in ln.items() if k != "run"})
        else:
            out.append({**{k: v for k, v in ln.items() if k != "run"}, "runs": [ln["run"]],
                        "amplitudes_arcsec": {ln["run"]: ln["amplitude_arcsec"]}})
    return sorted(out, key=lambda g: -g["amplitude_arcsec"])


def separate(dataset: MeasuredDataset, p_false: float = P_FALSE, max_harmonic: int = MAX_HARMONIC) -> dict:
    """Lines of every run, classed as locked to the order or at a fixed frequency (module docstring).

    Returns
    -------
    dict
        ``method`` (``"speeds"`` or ``"design orders"``), ``nyquist_order`` (lowest over the runs),
        ``order_locked`` (lines merged by order: ``order``, ``label`` (the reducer order it sits at, or
        None), ``amplitude_arcsec`` (largest), ``amplitudes_arcsec`` and ``runs``), ``fixed_frequency``
        (merged by frequency: ``frequency_Hz`` (None without times), ``order`` of the largest,
        ``amplitude_arcsec``, ``amplitudes_arcsec``, ``runs``), ``ambiguous`` (with ``why``),
        ``statements`` (what was done and what could not be told).
    """
    specs = [order_spectrum(r) for r in dataset.runs]
    thrs = [threshold(s, p_false) for s in specs]
    nyq = min(s.nyquist_order for s in specs)
    labels = reducer_orders(dataset.design, max(s.nyquist_order for s in specs), max_harmonic)
    speeds = [s.rev_hz for s in specs]
    two_speeds = all(v is not None for v in speeds) and max(speeds) / min(speeds) - 1.0 > SPEED_TOLERANCE
    locked, fixed, unclear = [], [], []
    for s, thr in zip(specs, thrs):
        for ln in find_lines(s, p_false):
            ln = {**ln, "run": s.run}
            near = int(round(ln["order"]))
            at_design = abs(ln["order"] - near) <= 0.5 / s.revolutions and near in labels
            ln["label"] = labels[near] if at_design else None
            if two_speeds:
                others = [(o, t) for o, t in zip(specs, thrs) if abs(o.rev_hz / s.rev_hz - 1.0) > SPEED_TOLERANCE]
                kind = _class_by_speed(ln, s, others)
            else:
                kind = "order" if at_design else "frequency"
            (locked if kind == "order" else fixed if kind == "frequency" else unclear).append(
                ln if kind in ("order", "frequency") else {**ln, "why": kind})
    res = 1.0 / min(s.revolutions for s in specs)
    f_tol = 1.5 * max((s.rev_hz or 0.0) / s.revolutions for s in specs)
    out = {"method": "speeds" if two_speeds else "design orders", "nyquist_order": nyq,
           "order_locked": _group(locked, "order", 0.5 * res),
           "fixed_frequency": _group(fixed, "frequency_Hz" if all(speeds) else "order", f_tol if all(speeds) else 0.5 * res),
           "ambiguous": _group(unclear, "order", 0.5 * res)}
    out["statements"] = _statements(out, dataset.design, two_speeds, max_harmonic)
    return out


def _statements(out: dict, design: Design, two_speeds: bool, max_harmonic: int) -> list[str]:
    if two_speeds:
        s = ["lines classed by the runs' speeds: a line that stays at its order at another speed is the reducer's, "
             "one that stays at its frequency is the rig's (or the environment's)"]
    else:
        s = [f"one speed: a line at an order of the design given (ratio {design.ratio:g}, {design.z_pins} pins, "
             f"{design.z_disc} lobes, {design.n_cranks} cranks; harmonics up to {max_harmonic}, sidebands +-1, "
             f"+-{design.n_cranks}, +-{2 * design.n_cranks}) is taken as the reducer's; the "
             f"{len(out['fixed_frequency'])} other line(s) are reported at a fixed frequency and not claimed for the "
             "reducer (one speed cannot tell a rig line from an order of a design other than the one given)"]
    if out["ambiguous"]:
        s.append(f"{len(out['ambiguous'])} line(s) could not be classed (seen at one speed only, at both places, or "
                 "the speeds too close to separate them at that order)")
    s.append(f"orders resolved up to {out['nyquist_order']:g} (half the readings per revolution)")
    return s
