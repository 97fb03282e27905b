"""The reducer's kinematic orders and periods for the loop, from its design (never from constants).

For a design with Z1 sun teeth, Z2 planet teeth, Zp pins and Zc = Zp - 1 disc lobes, the total
ratio is ``N = 1 + Z2 Zp / (Z1 (Zp - Zc))`` (paper Eq. A.5; 121 by default). Per output (carrier)
revolution the input (sun) turns N times, the sun relative to the carrier N - 1 times, and the
cranks relative to the carrier ``Zp`` times in the paper's convention (40 by default); the disc
lobes pass the pins ``Zc`` times. TE is periodic in one output revolution when N is an integer (it
is then an integer number of input turns), which the loop needs: its records and empirical terms are all
per output revolution. :func:`base_orders` names the reducer's base orders (:mod:`rvrig.spectrum` builds their
harmonics and crank-count sidebands).
"""
from __future__ import annotations

from rvcad.params import Design


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
