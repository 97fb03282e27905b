"""Each Table 4 error (B..L) applied alone, measured back from the exported STL files.

Every exported vertex lies on the exact (perturbed) outline, so circle fits to the vertices
recover the perturbed centres and radii to float32 precision (~0.005 um); the checks ask for
0.1 um or better. Lengths in mm.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from rvcad.errors import Case
from rvcad.export import export_case
from rvcad.geometry import ReducerGeometry
from rvcad.parts import AxialLayout, CycloidDisc
from test_rvcad_helpers import fit_circle, stl_vertices

UM = 1e-3
TOL = 1e-4  # 0.1 um
NOMINAL = ReducerGeometry()
LAYOUT = AxialLayout.from_design(NOMINAL.design)


def _export(tmp_path: Path, errors: dict, parts: list[str]) -> Path:
    case = Case.from_dict({"name": "t", "errors": errors})
    out = tmp_path / "out"
    export_case(case, out, formats=["stl"], tolerance_um=0.1, parts=parts)
    return out


def _hole(v: np.ndarray, near: np.ndarray, radius: float) -> tuple[np.ndarray, float]:
    sel = np.linalg.norm(v[:, :2] - near, axis=1) < radius + 0.3
    return fit_circle(v[sel])


def test_B_sun_eccentricity(tmp_path: Path) -> None:
    out = _export(tmp_path, {"sun_eccentricity": {"value": 10, "angle_deg": 30}}, ["sun"])
    v = stl_vertices(out / "sun.stl")
    c, r = _hole(v, np.zeros(2), 3.3)  # the input-shaft bore, centred on the input axis
    offset = -c  # gear centre relative to the input axis, sun frame
    expect = 10 * UM * np.array([math.cos(math.radians(30)), math.sin(math.radians(30))])
    assert np.abs(offset - expect).max() < TOL
    # the teeth stay centred on the part origin: tip vertices at the tip radius
    rr = np.linalg.norm(v[:, :2], axis=1)
    assert rr.max() == pytest.approx(NOMINAL.sun.tip_radius, abs=TOL)


def test_C_planet_eccentricity(tmp_path: Path) -> None:
    out = _export(tmp_path, {"planet_eccentricity": {"value": 10, "crank": 1, "angle_deg": 45}},
                  ["planet0", "planet1"])
    g = ReducerGeometry(Case.from_dict({"errors": {"planet_eccentricity": {"value": 10, "crank": 1,
                                                                           "angle_deg": 45}}}))
    for j, value in ((0, 0.0), (1, 10.0)):
        v = stl_vertices(out / f"planet{j}.stl")
        c, r = _hole(v, np.zeros(2), 7.0)
        assert r == pytest.approx(7.0, abs=TOL)
        ph = g.planet_tooth_phase[j]
        R = np.array([[math.cos(ph), -math.sin(ph)], [math.sin(ph), math.cos(ph)]])
        o = -(R @ c)  # gear centre relative to the crank axis, crank frame
        expect = value * UM * np.array([math.cos(math.radians(45)), math.sin(math.radians(45))])
        assert np.abs(o - expect).max() < TOL


def _cam(v: np.ndarray, k: int) -> np.ndarray:
    z0, z1 = LAYOUT.disc(k)
    sel = (np.isclose(v[:, 2], z0) | np.isclose(v[:, 2], z1)) & (np.linalg.norm(v[:, :2], axis=1) > 7.0 + 1e-3)
    c, r = fit_circle(v[sel])
    assert r == pytest.approx(9.0, abs=TOL)
    return c


def test_D_cam_phase(tmp_path: Path) -> None:
    out = _export(tmp_path, {"cam_phase": {"value": 10, "crank": 0, "disc": 1}}, ["crank0"])
    v = stl_vertices(out / "crank0.stl")
    e = 1.3
    c1 = _cam(v, 1)
    arc = e * (math.atan2(c1[1], c1[0]) - math.pi) if c1[1] >= 0 else e * (math.atan2(c1[1], c1[0]) + math.pi)
    assert arc == pytest.approx(10 * UM, abs=TOL)
    assert np.linalg.norm(c1) == pytest.approx(e, abs=TOL)
    c0 = _cam(v, 0)  # the other cam is untouched
    assert np.abs(c0 - np.array([e, 0.0])).max() < TOL


def test_E_cam_eccentricity(tmp_path: Path) -> None:
    out = _export(tmp_path, {"cam_eccentricity": {"value": 10, "crank": 0, "disc": 0}}, ["crank0", "crank1"])
    c0 = _cam(stl_vertices(out / "crank0.stl"), 0)
    assert np.linalg.norm(c0) == pytest.approx(1.3 + 10 * UM, abs=TOL)
    assert abs(c0[1]) < TOL
    c1 = _cam(stl_vertices(out / "crank0.stl"), 1)
    assert np.linalg.norm(c1) == pytest.approx(1.3, abs=TOL)
    assert np.linalg.norm(_cam(stl_vertices(out / "crank1.stl"), 0)) == pytest.approx(1.3, abs=TOL)


def test_F_carrier_hole_eccentricity(tmp_path: Path) -> None:
    out = _export(tmp_path, {"carrier_hole_eccentricity": {"value": 10, "crank": 0}}, ["carrier", "flange"])
    for plate in ("carrier", "flange"):
        v = stl_vertices(out / f"{plate}.stl")
        c0, r0 = _hole(v, np.array([30.0, 0.0]), 7.0)
        c1, _ = _hole(v, np.array([-30.0, 0.0]), 7.0)
        assert r0 == pytest.approx(7.0, abs=TOL)
        assert np.abs(c0 - np.array([30.0 + 10 * UM, 0.0])).max() < TOL
        assert np.abs(c1 - np.array([-30.0, 0.0])).max() < TOL


def test_G_disc_hole_eccentricity(tmp_path: Path) -> None:
    out = _export(tmp_path, {"disc_hole_eccentricity": {"value": 10, "disc": 0, "hole": 1}}, ["disc0", "disc1"])
    v = stl_vertices(out / "disc0.stl")
    c0, r0 = _hole(v, np.array([30.0, 0.0]), 9.0)
    c1, r1 = _hole(v, np.array([-30.0, 0.0]), 9.0)
    assert r1 == pytest.approx(9.0, abs=TOL)
    assert np.abs(c0 - np.array([30.0, 0.0])).max() < TOL
    assert np.abs(c1 - np.array([-30.0 - 10 * UM, 0.0])).max() < TOL  # moved radially outward
    c1b, _ = _hole(stl_vertices(out / "disc1.stl"), np.array([-30.0, 0.0]), 9.0)
    assert np.abs(c1b - np.array([-30.0, 0.0])).max() < TOL


def _pin_centers(out: Path) -> tuple[np.ndarray, np.ndarray]:
    cs, rs = [], []
    for i in range(40):
        c, r = fit_circle(stl_vertices(out / f"pin{i:02d}.stl"))
        cs.append(c)
        rs.append(r)
    return np.array(cs), np.array(rs)


def test_H_pin_circle_offset(tmp_path: Path) -> None:
    out = _export(tmp_path, {"pin_circle_offset": {"value": 10, "angle_deg": 60}}, ["pin*", "housing"])
    expect = 10 * UM * np.array([math.cos(math.radians(60)), math.sin(math.radians(60))])
    cs, _ = _pin_centers(out)
    assert np.abs(cs - NOMINAL.pin_centers - expect).max() < TOL
    centre, radius = fit_circle(cs)
    assert np.abs(centre - expect).max() < TOL
    assert radius == pytest.approx(64.0, abs=TOL)
    # the housing bore (arcs between the grooves) is centred on the moved pin circle too
    v = stl_vertices(out / "housing.stl")
    d_pin = np.min(np.linalg.norm(v[:, None, :2] - cs[None], axis=2), axis=1)
    bore = v[(np.linalg.norm(v[:, :2], axis=1) < 65.0) & (d_pin > 3.0 + 1e-3)]
    cb, rb = fit_circle(bore)
    assert np.abs(cb - expect).max() < TOL
    assert rb == pytest.approx(64.0, abs=TOL)


def test_I_pin_circle_diameter(tmp_path: Path) -> None:
    out = _export(tmp_path, {"pin_circle_diameter": -14}, ["pin*"])
    cs, rs = _pin_centers(out)
    _, radius = fit_circle(cs)
    assert 2.0 * radius == pytest.approx(128.0 - 14 * UM, abs=TOL)
    assert np.abs(rs - 3.0).max() < TOL


def test_J_pin_radius(tmp_path: Path) -> None:
    out = _export(tmp_path, {"pin_radius": 7}, ["pin*"])
    cs, rs = _pin_centers(out)
    assert np.abs(rs - 3.007).max() < TOL
    assert np.abs(cs - NOMINAL.pin_centers).max() < TOL


def test_K_disc_phase(tmp_path: Path) -> None:
    out = _export(tmp_path, {"disc_phase": {"value": 0.1, "disc": 0}}, ["disc0", "disc1"])
    v = stl_vertices(out / "disc0.stl")
    outer = v[np.linalg.norm(v[:, :2], axis=1) > 50.0]
    nominal = CycloidDisc(NOMINAL, 0)
    turned = CycloidDisc(ReducerGeometry(Case.from_dict({"errors": {"disc_phase": 0.1}})), 0)
    assert np.abs(turned.boundary_distance(outer[::4, :2])).max() < TOL
    assert np.abs(nominal.boundary_distance(outer[::4, :2])).max() > 10 * TOL
    # the root vertex of lobe 0 sits at the profile rotation; the holes did not move
    near = outer[np.abs(np.arctan2(outer[:, 1], outer[:, 0])) < 0.05]
    root = near[np.argmin(np.linalg.norm(near[:, :2], axis=1))]
    assert math.degrees(math.atan2(root[1], root[0])) == pytest.approx(0.1, abs=1e-6)
    c0, _ = _hole(v, np.array([30.0, 0.0]), 9.0)
    assert np.abs(c0 - np.array([30.0, 0.0])).max() < TOL
    v1 = stl_vertices(out / "disc1.stl")
    outer1 = v1[np.linalg.norm(v1[:, :2], axis=1) > 50.0][::4]
    assert np.abs(CycloidDisc(NOMINAL, 1).boundary_distance(outer1[:, :2])).max() < TOL


def test_L_pin_pitch_only_at_pin_0(tmp_path: Path) -> None:
    out = _export(tmp_path, {"pin_pitch": 0.01}, ["pin*"])
    cs, rs = _pin_centers(out)
    assert math.degrees(math.atan2(cs[0, 1], cs[0, 0])) == pytest.approx(0.01, abs=1e-6)
    assert np.linalg.norm(cs[0]) == pytest.approx(64.0, abs=TOL)
    assert np.abs(cs[1:] - NOMINAL.pin_centers[1:]).max() < TOL
    moved = np.linalg.norm(cs - NOMINAL.pin_centers, axis=1) > TOL
    assert moved.tolist() == [True] + [False] * 39
