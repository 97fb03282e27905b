"""The TE figure of a set of cases as an engineer reads it: one output revolution, one crank period, orders.

One row per case group (a case and its mirror, e.g. ``screen-B+`` and ``screen-B-``, share a row), three
panels a row, every column on shared axes so the rows compare at a glance:

* TE over one output revolution, its mean removed (the mean is a constant offset, given in the row title),
  one thin line per case;
* the same curves zoomed on the first crank period (``360 / crank_order`` degrees of output; the crank turns
  ``Zp`` times relative to the carrier per output revolution, so ``crank_order`` is the pin count), with the
  computed points marked;
* the order spectrum: the amplitude of each harmonic of the output revolution (order ``k`` = ``k`` periods
  per output revolution) on a logarithmic axis, the multiples of the crank order marked.

The amplitude of order ``k`` is ``2 |c_k|`` with ``c_k`` the discrete Fourier coefficient of the TE samples
over one revolution (``numpy.fft.rfft / N``): a TE ``a cos(k theta_out + phi)`` has amplitude ``a``, its
peak-to-peak ``2 a``. Orders above ``N / 2`` alias and are not shown.
"""
from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from matplotlib.figure import Figure

#: Colours of the cases of one row: the case at +value, at -value, and a case without a sign.
SIGN_COLOURS = {"+": "tab:blue", "-": "tab:red", "": "black"}


def order_spectrum(te: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Amplitude of each harmonic order of a TE curve sampled uniformly over one output revolution.

    Parameters
    ----------
    te : ndarray
        TE at ``N`` equally spaced output angles of one revolution (any unit; the amplitudes share it).

    Returns
    -------
    orders : ndarray of int
        ``1 .. N // 2`` (periods per output revolution).
    amplitude : ndarray
        Amplitude of each order (``2 |c_k|``; at the Nyquist order of an even ``N``, ``|c_k|``).
    """
    te = np.asarray(te, dtype=np.float64)
    if te.ndim != 1 or te.size < 4 or not np.all(np.isfinite(te)):
        raise ValueError(f"te must be a 1-D array of at least 4 finite values, got shape {te.shape}")
    c = np.fft.rfft(te - te.mean()) / te.size
    amp = 2.0 * np.abs(c)
    if te.size % 2 == 0:
        amp[-1] /= 2.0
    return np.arange(1, amp.size), amp[1:]


def _groups(curves: Mapping[str, np.ndarray]) -> dict[str, list[tuple[str, np.ndarray]]]:
    """Case name -> row: a trailing ``+`` / ``-`` is the sign of the case within its row."""
    rows: dict[str, list[tuple[str, np.ndarray]]] = {}
    for name, te in curves.items():
        sign = name[-1] if name[-1:] in ("+", "-") else ""
        rows.setdefault(name[: len(name) - len(sign)], []).append((sign, np.asarray(te, dtype=np.float64)))
    return rows


def _share(axes: np.ndarray) -> None:
    """Shared axes of the (rows, 3) grid: each column's x; one TE scale for the revolution and zoom columns;
    one amplitude scale for the spectra."""
    for col in range(3):
        for ax in axes[1:, col]:
            ax.sharex(axes[0, col])
    for ax in list(axes[1:, 0]) + list(axes[:, 1]):
        ax.sharey(axes[0, 0])
    for ax in axes[1:, 2]:
        ax.sharey(axes[0, 2])


def plot_te_figure(curves: Mapping[str, np.ndarray], path: str | Path, crank_order: int = 40,
                   titles: Mapping[str, str] | None = None, suptitle: str | None = None) -> Path:
    """Draw the TE figure of ``curves`` (:func:`te_figure`) to ``path`` (PNG, written atomically); returns it."""
    from rvstudy.screen import save_figure_atomic

    return save_figure_atomic(te_figure(curves, crank_order, titles, suptitle), path)


def te_figure(curves: Mapping[str, np.ndarray], crank_order: int = 40, titles: Mapping[str, str] | None = None,
              suptitle: str | None = None) -> Figure:
    """The TE figure of ``curves`` (see the module docstring) as a matplotlib ``Figure`` (Agg, pyplot untouched).

    Parameters
    ----------
    curves : mapping
        Case name -> TE (arcsec) at equally spaced output angles over one revolution, starting at 0 deg.
        Names ending in ``+`` / ``-`` share a row with the name without the sign.
    crank_order : int
        Crank turns relative to the carrier per output revolution (the pin count ``Zp``, 40 by default).
    titles : mapping or None
        Row name (case name without its sign) -> row title; default the row name.
    suptitle : str or None
        Title of the figure.

    Returns
    -------
    matplotlib.figure.Figure
        One row of three axes per case group: revolution, zoom, spectrum.
    """
    from matplotlib.figure import Figure

    if not curves:
        raise ValueError("curves is empty: no TE curve to draw")
    if not (isinstance(crank_order, (int, np.integer)) and crank_order >= 1):
        raise ValueError(f"crank_order {crank_order!r} must be an integer >= 1 (crank turns per output revolution)")
    rows = _groups(curves)
    fig = Figure(figsize=(13.0, 0.45 + 1.25 * len(rows)), layout="constrained")
    axes = fig.subplots(len(rows), 3, squeeze=False, gridspec_kw={"width_ratios": [2.4, 1.0, 1.6]})
    _share(axes)
    period = 360.0 / crank_order
    top_order = max(te.size for members in rows.values() for _, te in members) // 2
    peak = 0.0
    for r, (row, members) in enumerate(rows.items()):
        rev, zoom, spec = axes[r]
        notes = []
        for sign, te in members:
            x = np.arange(te.size) * 360.0 / te.size
            col = SIGN_COLOURS[sign]
            ripple = te - te.mean()
            rev.plot(x, ripple, color=col, lw=0.6)
            inside = x <= period + 1e-9
            zoom.plot(x[inside], ripple[inside], color=col, lw=0.8, marker="o", ms=2)
            orders, amp = order_spectrum(te)
            spec.vlines(orders + (0.25 if sign == "-" else 0.0), 0.0, amp, color=col, lw=0.8)
            peak = max(peak, float(amp.max()))
            notes.append(f"{sign or 'case'}: pp {np.ptp(te):.3g}\", mean {te.mean():+.3g}\"")
        rev.set_title(f"{(titles or {}).get(row, row)}   ({'; '.join(notes)})", fontsize=8, loc="left")
        for k in range(crank_order, top_order + 1, crank_order):
            spec.axvline(k, color="0.8", lw=0.6, zorder=0)
        for ax in (rev, zoom, spec):
            ax.tick_params(labelsize=7)
            ax.grid(True, lw=0.3, color="0.9")
        rev.set_ylabel("TE - mean\n[arcsec]", fontsize=7)
    floor = peak * 1e-5 if peak > 0 else 1e-6
    axes[0, 0].set_xlim(0.0, 360.0)
    axes[0, 1].set_xlim(0.0, period)
    axes[0, 2].set_yscale("log")
    axes[0, 2].set_ylim(floor, max(peak, floor) * 2.0)
    axes[0, 2].set_xlim(0.0, top_order)
    axes[-1, 0].set_xlabel("output angle [deg], one revolution", fontsize=8)
    axes[-1, 1].set_xlabel(f"output angle [deg], first crank period ({period:.3g} deg)", fontsize=8)
    axes[-1, 2].set_xlabel(f"order [periods per output revolution]; grey: multiples of {crank_order}", fontsize=8)
    axes[0, 2].set_title("order spectrum, amplitude [arcsec]", fontsize=8, loc="left")
    axes[0, 1].set_title("zoom", fontsize=8, loc="left")
    if suptitle:
        fig.suptitle(suptitle, fontsize=10)
    return fig
