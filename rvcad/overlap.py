"""Overlaps of the placed parts of an assembly: pins in the discs, cams in the disc holes, stage I teeth.

An assembly placed by the ideal kinematics (or a solved pose) of a case with errors can overlap:
the errors close clearances the rigid parts do not have. This module measures it:

* pin i / disc k: depth from the exact signed envelope distance
  (:meth:`ReducerGeometry.pin_gaps`, positive = clearance); volume from the intersection of the
  placed outlines (vertex-exact polygons inscribed in the exact curves, so the area is a lower
  bound within one sagitta band of the exact one) times the disc width;
* crank j / disc k: the cam circle (radius r_c) against its hole (radius r_h) at centre distance
  d: depth ``d + r_c - r_h``, area ``pi r_c^2 - lens(r_h, r_c, d)`` (closed form) times the disc
  width (the cam bearings that would take this up are not modelled);
* sun / planet j: the stage I flank gap along the line of action for both flanks
  (:meth:`ReducerGeometry.stage1_gaps`); a negative gap is a tooth overlap (depth only).

Lengths in mm, volumes in mm^3.
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np
from shapely.geometry import Polygon

from rvcad.assembly import Assembly
from rvcad.housing import lens_area
from rvcad.plane import rotate2d

#: Overlap depth below which two parts are said to touch, not overlap, mm (0.1 um, the tolerance
#: of the export; the solver's interference tolerance ``TOL.interference_mm`` is the same).
TOUCH_MM = 1e-4


def _state(asm: Assembly) -> tuple[np.ndarray, np.ndarray]:
    g = asm.geometry
    th = math.radians(asm.theta_in_deg)
    if asm.state is not None:
        return np.array([asm.state[0]]), np.array([asm.state[1]], dtype=float)
    return g.ideal_state(np.array([th]))


def _placed_ring(asm: Assembly, name: str, sagitta: float) -> np.ndarray:
    outer, _ = asm[name].outline()
    x, y, r = asm.placements[name]
    return rotate2d(outer.ring(sagitta), math.radians(r)) + np.array([x, y])


def overlaps(asm: Assembly, sagitta_mm: float = 1e-4) -> dict[str, Any]:
    """Overlaps of the placed parts (pin-disc, crank-disc, stage I) of an assembly.

    Parameters
    ----------
    asm : Assembly
        Placed at the ideal kinematics or at an explicit state.
    sagitta_mm : float
        Sagitta of the disc outline used for the pin-disc volumes, mm.

    Returns
    -------
    dict
        ``pose`` (``ideal`` or ``state``), ``theta_in_deg``, and for ``pin_disc``, ``crank_disc``:
        ``pairs`` (count overlapping more than :data:`TOUCH_MM`), ``max_depth_mm``, ``volume_mm3``,
        ``worst`` (pair name); ``stage1``: ``min_gap_mm`` per planet and ``overlap`` (bool).
    """
    g, d = asm.geometry, asm.design
    to, ps = _state(asm)
    th = np.array([math.radians(asm.theta_in_deg)])
    width = d.disc_width_mm
    # pins against discs
    gap = g.pin_gaps(to, ps)[0][0]  # (n_discs, Zp)
    pd: dict[str, Any] = {"pairs": 0, "max_depth_mm": float(max(-gap.min(), 0.0)), "volume_mm3": 0.0, "worst": None}
    if pd["max_depth_mm"] > TOUCH_MM:
        k, i = np.unravel_index(int(np.argmin(gap)), gap.shape)
        pd["worst"] = f"pin{i:02d}-disc{k}"
    for k in range(d.n_discs):
        hits = np.nonzero(-gap[k] > TOUCH_MM)[0]
        if hits.size == 0:
            continue
        disc = Polygon(_placed_ring(asm, f"disc{k}", sagitta_mm))
        for i in hits:
            pin = Polygon(asm[f"pin{i:02d}"].outline()[0].ring(sagitta_mm))
            pd["volume_mm3"] += float(disc.intersection(pin).area) * width
            pd["pairs"] += 1
    # cams against disc holes
    cams = g.cam_centers(to, ps)[0]  # (n_cranks, n_discs, 2)
    cen, ang = g.disc_poses(to, ps)
    rc, rh = d.cam_radius_mm, d.cam_radius_mm
    cd: dict[str, Any] = {"pairs": 0, "max_depth_mm": 0.0, "volume_mm3": 0.0, "worst": None}
    for k in range(d.n_discs):
        holes = rotate2d(g.disc_holes[k], float(ang[0, k])) + cen[0, k]
        for j in range(d.n_cranks):
            dist = float(np.linalg.norm(cams[j, k] - holes[j]))
            depth = dist + rc - rh
            if depth > cd["max_depth_mm"]:
                cd["max_depth_mm"], cd["worst"] = depth, f"crank{j}-disc{k}"
            if depth > TOUCH_MM:
                cd["pairs"] += 1
                cd["volume_mm3"] += (math.pi * rc * rc - lens_area(rh, rc, dist)) * width
    if cd["max_depth_mm"] <= TOUCH_MM:
        cd["worst"] = None
    # stage I flanks
    s1 = np.minimum(g.stage1_gaps(th, to, ps, 1)[0], g.stage1_gaps(th, to, ps, -1)[0])
    st = {"min_gap_mm": [float(v) for v in s1], "overlap": bool(np.any(s1 < -TOUCH_MM))}
    return {"pose": "ideal" if asm.state is None else "state", "theta_in_deg": asm.theta_in_deg,
            "pin_disc": pd, "crank_disc": cd, "stage1": st}


def overlap_summary(ov: dict[str, Any]) -> str:
    """One line: the overlaps (or none) of :func:`overlaps`."""
    parts = []
    for key, label in (("pin_disc", "pin-disc"), ("crank_disc", "crank-disc")):
        o = ov[key]
        if o["pairs"]:
            parts.append(f"{label} {o['volume_mm3']:.3g} mm^3 in {o['pairs']} pair(s), deepest "
                         f"{o['max_depth_mm'] * 1e3:.2f} um ({o['worst']})")
    if ov["stage1"]["overlap"]:
        parts.append(f"stage I teeth {-min(ov['stage1']['min_gap_mm']) * 1e3:.2f} um")
    return "overlaps: " + ("; ".join(parts) if parts else "none") + f" (at the {ov['pose']} pose)"


__all__ = ["TOUCH_MM", "overlap_summary", "overlaps"]
