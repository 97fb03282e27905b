"""The reducer's kinematic orders and periods for the loop, from its design (never from constants).

For a design with Z1 sun teeth, Z2 planet teeth, Zp pins and Zc = Zp - 1 disc lobes, the total
ratio is ``N = 1 + Z2 Zp / (Z1 (Zp - Zc))`` (paper Eq. A.5; 121 by default). Per output (carrier)
revolution the input (sun) turns N times, the sun relative to the carrier N - 1 times, and the
cranks relative to the carrier ``Zp`` times in the paper's convention (40 by default); the disc
lobes pass the pins ``Zc`` times. TE is periodic in one output revolution when N is an integer (it
is then an integer number of input turns), which the loop needs: its records, grids and empirical
terms are all per output revolution.

The orders that matter (cycles per output revolution) are 1 (anything on the carrier or the output
encoder), Zc and Zp and their doubles (disc and pin errors, crank order), and the input orders N - 1,
N, N + 1 (sun, input encoder, stage I mesh). :func:`screen_grid` chooses a screening grid that
resolves all of them and their neighbours without aliasing.
"""
from __future__ import annotations

import math

from rvcad.params import Design
from rvcad.validation import MAX_GRID_STEPS

#: Largest screening grid chosen from a ``--steps`` request (points per output revolution); larger
#: requests (1000, 1e6) screen on the smallest grid that resolves the orders instead.
SCREEN_MAX = 720
#: Largest ``--steps`` / ``--screen-points`` accepted (the time budget of the grid solves, as every
#: command's grid option; :data:`rvcad.validation.MAX_GRID_STEPS`).
STEPS_MAX = MAX_GRID_STEPS


def ratio(design: Design) -> float:
    """Total ratio N of a design (input turns per output turn)."""
    return float(design.ratio)


def check_periodic(design: Design) -> None:
    """Raise ``ValueError`` if the TE of the design is not periodic in one output revolution
    (a non-integer ratio), which the loop needs."""
    n = ratio(design)
    if abs(n - round(n)) > 1e-9:
        raise ValueError(
            f"design: ratio {n:.10g} (z_sun {design.z_sun}, z_planet {design.z_planet}, z_pins {design.z_pins}) "
            "is not an integer: the TE does not repeat every output revolution, which rv-calibrate needs "
            "(choose tooth counts with Z2 Zp / Z1 an integer)")


def period_deg(design: Design) -> float:
    """Input angle of one output revolution, deg (``N * 360``)."""
    return ratio(design) * 360.0


def base_orders(design: Design) -> dict[str, int]:
    """The reducer's base orders (cycles per output revolution), by what turns or meshes: ``output`` 1 (the
    carrier), ``lobe`` Zc (the discs' lobes passing the pins, the cranks' absolute turns), ``pin`` Zp (the
    cranks relative to the carrier), ``sun`` N - 1 (the sun relative to the carrier), ``input`` N and
    ``stage I mesh`` Z1 (N - 1) (sun teeth passing the planets)."""
    n = int(round(ratio(design)))
    return {"output": 1, "lobe": int(design.z_disc), "pin": int(design.z_pins), "sun": n - 1, "input": n,
            "stage I mesh": int(design.z_sun) * (n - 1)}


def orders_that_matter(design: Design) -> list[int]:
    """1, Zc, Zp, 2 Zc, 2 Zp and the input orders N - 1, N, N + 1 (sorted, unique)."""
    n = int(round(ratio(design)))
    zc, zp = int(design.z_disc), int(design.z_pins)
    return sorted({1, zc, zp, 2 * zc, 2 * zp, n - 1, n, n + 1})


def key_orders(design: Design) -> tuple[int, ...]:
    """Orders reported in the diagnostics: 0-3 and the orders that matter with their neighbours."""
    out = {0, 1, 2, 3}
    for k in orders_that_matter(design):
        out.update({k - 1, k, k + 1})
    return tuple(sorted(k for k in out if k >= 0))


def highest_order(design: Design) -> int:
    """Highest order a screening grid must resolve: the orders that matter and their neighbours."""
    return max(orders_that_matter(design)) + 1


def min_screen_grid(design: Design) -> int:
    """Smallest screening grid (points per output revolution) that resolves every order that matters
    and its neighbours without aliasing (Nyquist above :func:`highest_order`) and is a multiple of
    the pin count (pin-wise signatures are shifted by whole pin pitches). 280 for the default."""
    zp = int(design.z_pins)
    need = 2 * highest_order(design) + 1
    return zp * math.ceil(need / zp)


def resolves(design: Design, points: int) -> bool:
    """True if a grid of ``points`` per output revolution is a multiple of the pin count and resolves
    every order that matters (see :func:`min_screen_grid`)."""
    return points % int(design.z_pins) == 0 and points >= min_screen_grid(design)


def screen_grid(design: Design, steps: int | None = None, screen_points: int | None = None) -> tuple[int, str]:
    """The screening grid for a design and the user's requests, with a note saying how it was chosen.

    Parameters
    ----------
    design : Design
    steps : int or None
        ``--steps``: used as the screening grid when it resolves the orders and is at most
        :data:`SCREEN_MAX`; otherwise the smallest resolving grid is used (the readings are always
        solved exactly, so a coarser screening grid loses nothing but resolution it does not need).
    screen_points : int or None
        ``--screen-points``: an explicit screening grid; refused (ValueError naming it) unless it
        resolves the orders and is at most :data:`STEPS_MAX`.

    Returns
    -------
    (int, str)
        Points per output revolution and a one-sentence note (empty when the request was used).
    """
    lo = min_screen_grid(design)
    zp = int(design.z_pins)
    for name, v in (("steps", steps), ("screen_points", screen_points)):
        if v is None:
            continue
        if isinstance(v, bool) or not isinstance(v, int) or v < 1 or v > STEPS_MAX:
            raise ValueError(f"{name} {v!r} must be an integer in [1, {STEPS_MAX}]")
    if screen_points is not None:
        if not resolves(design, screen_points):
            raise ValueError(
                f"screen_points {screen_points} cannot resolve the orders that matter for this reducer "
                f"({', '.join(map(str, orders_that_matter(design)))} and neighbours, up to {highest_order(design)}): "
                f"a screening grid must be a multiple of the pin count {zp} and at least {lo} points")
        return int(screen_points), ""
    if steps is None:
        return lo, ""
    if resolves(design, steps) and steps <= SCREEN_MAX:
        return int(steps), ""
    why = (f"would alias the orders that matter (a multiple of {zp} of at least {lo} points is needed)"
           if not resolves(design, steps) else f"is more than the screening needs (at most {SCREEN_MAX})")
    return lo, (f"the screening grid is {lo} points per output revolution: the {steps} requested {why}; "
                "the model is solved exactly at every reading whatever the grid")
