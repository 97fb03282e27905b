"""Averaging a dense rig record down without aliasing (:func:`decimate`, used by :mod:`rvrig.rigimport`).

A record denser than ``samples_per_rev`` readings per output revolution is low-passed
by a linear-phase FIR filter (Kaiser window, :data:`STOP_ATTENUATION_DB` per pass, applied forward
and backward: zero phase, the attenuation doubled) whose pass band ends at :data:`PASS_FRACTION` of the
new Nyquist order and whose stop band starts at it, then evaluated by a cubic spline on an even grid of
output angle: every order above the new Nyquist order is removed before it could fold back. The filter
needs readings beyond each end: a record of at least one revolution lends its own readings one
revolution away (TE repeats every output revolution); the edges of a split gap, which have none, take
the odd reflection of the readings, which disturbs the readings within half a filter length of the gap.
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
from scipy import interpolate, signal

from rvcad.validation import DatasetError

if TYPE_CHECKING:
    from rvrig.rigimport import RigRecord

#: End of the filter's pass band as a fraction of the new Nyquist order (the stop band starts at it).
PASS_FRACTION = 0.8
#: Kaiser design attenuation per pass, dB; the forward-backward application makes it 120 dB in the stop
#: band with a pass-band ripple below 0.2 %.
STOP_ATTENUATION_DB = 60.0
#: Gaps of up to this many sample spacings are filled before the low-pass; longer ones split the record.
FILL_SPACINGS = 3


def default_samples_per_rev(ratio: float, z_pins: int | None = None) -> int:
    """Readings per output revolution kept by default.

    The orders a reducer shows reach the fourth harmonic of its input order with their sidebands (the
    RV-160N records: orders up to 321 at ratio 81) and the eighth of its pin order. The default is the
    smallest multiple of 360 whose flat pass band (:data:`PASS_FRACTION` of its Nyquist order) holds
    ``4 (N + 1)`` and ``8 Zp``: 1080 for ratio 81 with 40 pins, 1440 for the default ratio 121.
    """
    need = max(4.0 * (float(ratio) + 1.0), 8.0 * z_pins if z_pins else 0.0)
    return int(360 * math.ceil(2.0 * need / PASS_FRACTION / 360.0))


def antialias_filter(density: float, samples_per_rev: float) -> tuple[np.ndarray, dict]:
    """FIR low-pass taps for averaging a record of ``density`` readings per output revolution down to
    ``samples_per_rev``, and a description (pass band and stop band edges in orders, taps)."""
    nyq = 0.5 * samples_per_rev
    f_pass, f_stop = PASS_FRACTION * nyq, nyq
    width = (f_stop - f_pass) / (0.5 * density)               # fraction of the record's Nyquist
    ntaps, beta = signal.kaiserord(STOP_ATTENUATION_DB, width)
    ntaps |= 1                                                # odd: a type I linear-phase filter
    taps = signal.firwin(ntaps, 0.5 * (f_pass + f_stop), window=("kaiser", beta), fs=density)
    return taps, {"pass_band_to_order": f_pass, "stop_band_from_order": f_stop, "taps": int(ntaps),
                  "attenuation_dB": 2.0 * STOP_ATTENUATION_DB}


def _turns_away(at: np.ndarray, starts: np.ndarray, ends: np.ndarray, slack: float) -> np.ndarray:
    """For each angle ``at`` (deg), the nearest angle a whole number (not 0) of revolutions away that lies
    inside one of the segments ``[starts - slack, ends + slack]``; NaN where none does."""
    q = np.full(at.size, np.nan)
    turns = int(np.ceil((ends[-1] - starts[0]) / 360.0)) + 1
    lo, hi = starts[None, :] - slack, ends[None, :] + slack
    for m in sorted((m for m in range(-turns, turns + 1) if m), key=abs):
        c = at + 360.0 * m
        ok = np.isnan(q) & np.any((c[:, None] >= lo) & (c[:, None] <= hi), axis=1)
        q[ok] = c[ok]
    return q


def _lowpass(taps: np.ndarray, u: np.ndarray, x: np.ndarray, record: tuple) -> np.ndarray:
    """Zero-phase FIR low-pass of readings ``x`` at evenly spaced output angles ``u`` (deg, increasing).

    Each end is padded by one filter length: with the record's own readings whole revolutions away
    (TE repeats every output revolution) where the record holds them all (``record``: the segments'
    ``(starts, ends)`` angles and the record's readings as a function of angle); else by the odd
    reflection of the end (scipy's default), which keeps the end value and slope but not the curvature.
    """
    pad = min(taps.size, x.size - 1)          # a zero-state start disturbs at most taps - 1 readings per pass
    (starts, ends), value = record
    h = (u[-1] - u[0]) / (u.size - 1)
    j = np.arange(1, pad + 1)
    q = [_turns_away(at, starts, ends, 0.5 * h) for at in (u[0] - h * j[::-1], u[-1] + h * j)]
    left = value(q[0]) if not np.isnan(q[0]).any() else 2.0 * x[0] - x[pad:0:-1]
    right = value(q[1]) if not np.isnan(q[1]).any() else 2.0 * x[-1] - x[-2:-pad - 2:-1]
    return signal.filtfilt(taps, [1.0], np.concatenate([left, x, right]), padlen=0)[pad:pad + x.size]


def decimate(rec: RigRecord, samples_per_rev: int) -> tuple[dict[str, np.ndarray], dict]:
    """Average one record down to about ``samples_per_rev`` readings per output revolution without aliasing.

    The grid runs from the first to the last reading of the record in equal steps as close to
    ``360 / samples_per_rev`` deg as fit the span; no grid point is written inside a split gap.

    Returns
    -------
    (dict, dict)
        Arrays ``output_deg``, ``te_deg``, ``time_s``; and a description (``samples_per_rev`` kept,
        ``filter`` or None, ``dropped_segments``).
    """
    density = 360.0 / rec.step_deg
    if samples_per_rev <= 0 or samples_per_rev >= density:
        return ({"output_deg": rec.output_deg, "te_deg": rec.te_deg, "time_s": rec.time_s},
                {"samples_per_rev": density, "filter": None, "dropped_segments": []})
    taps, info = antialias_filter(density, samples_per_rev)
    u = (rec.output_deg - rec.output_deg[0]) * rec.direction          # increasing
    span = float(u[-1])
    n = int(round(span * samples_per_rev / 360.0)) + 1
    grid = np.linspace(0.0, span, n)
    segs = np.split(np.arange(u.size), np.flatnonzero(np.diff(rec.slot) > FILL_SPACINGS) + 1)
    bounds = (np.array([u[s[0]] for s in segs]), np.array([u[s[-1]] for s in segs]))
    record = (bounds, lambda q: np.interp(q, u, rec.te_deg))
    keep_u, keep_te, dropped = [], [], []
    for seg in segs:
        slots = np.arange(rec.slot[seg[0]], rec.slot[seg[-1]] + 1)
        if slots.size <= taps.size:
            dropped.append({"from_output_deg": float(rec.output_deg[seg[0]]), "readings": int(seg.size)})
            continue
        uf = np.interp(slots, rec.slot[seg], u[seg])                 # filled gaps: before the filter only
        tf = _lowpass(taps, uf, np.interp(slots, rec.slot[seg], rec.te_deg[seg]), record)
        g = grid[(grid >= uf[0]) & (grid <= uf[-1])]
        keep_u.append(g)
        keep_te.append(interpolate.make_interp_spline(uf, tf, k=3)(g))
    if not keep_u:
        raise DatasetError(f"every segment of the {'forward' if rec.direction > 0 else 'backward'} record is shorter "
                           f"than the anti-alias filter ({taps.size} readings); import it with --samples-per-rev 0")
    ug, teg = np.concatenate(keep_u), np.concatenate(keep_te)
    out = {"output_deg": rec.output_deg[0] + rec.direction * ug, "te_deg": teg, "time_s": np.interp(ug, u, rec.time_s)}
    return out, {"samples_per_rev": 360.0 * (n - 1) / span if span > 0 else float(samples_per_rev),
                 "filter": info, "dropped_segments": dropped}
