"""CAD of a reducer with three crankshafts: every part for each crank, valid solids, the perturbed holes of the
third crank measured back from the exported STL (0.1 um), no overlaps at the ideal pose, the ``--state`` pose."""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from rvcad.cli import main
from rvcad.errors import Case
from rvcad.export import export_case
from rvcad.overlap import overlaps
from rvcad.parts import Assembly
from rvdyn import collision
from test_rvcad_helpers import fit_circle, stl_vertices

# on one worker with the other build123d users (one import of the CAD kernel per process)
pytestmark = pytest.mark.xdist_group("build123d")

UM = 1e-3
TOL = 1e-4  # 0.1 um
THREE = {"crank_angles_deg": [0, 120, 240]}
ERRORS = {"carrier_hole_eccentricity": {"value": 10, "crank": 2},
          "disc_hole_eccentricity": {"value": 10, "disc": 1, "hole": 2},
          "cam_eccentricity": {"value": 10, "crank": 2, "disc": 0}}


def _u(deg: float) -> np.ndarray:
    return np.array([math.cos(math.radians(deg)), math.sin(math.radians(deg))])


def _hole(v: np.ndarray, near: np.ndarray, radius: float) -> tuple[np.ndarray, float]:
    sel = np.linalg.norm(v[:, :2] - near, axis=1) < radius + 0.3
    return fit_circle(v[sel])


@pytest.mark.slow
def test_three_crank_parts_exported_and_measured_back(tmp_path: Path) -> None:
    case = Case.from_dict({"name": "three", "design": THREE, "errors": ERRORS})
    out = tmp_path / "out"
    rep = export_case(case, out, formats=["stl"], tolerance_um=0.1,
                      parts=["planet2", "crank2", "flange", "carrier", "disc1"])
    names = {Path(f.file).stem for f in rep.files}
    assert {"planet2", "crank2", "flange", "carrier", "disc1"} <= names
    # the plates: three journal holes on the 30 mm crank circle, crank 2's moved outward by 10 um
    for plate in ("flange", "carrier"):
        v = stl_vertices(out / f"{plate}.stl")
        for j, beta in enumerate((0.0, 120.0, 240.0)):
            c, r = _hole(v, 30.0 * _u(beta), 7.0)
            assert r == pytest.approx(7.0, abs=TOL)
            assert np.abs(c - (30.0 + (10 * UM if j == 2 else 0.0)) * _u(beta)).max() < TOL
    # disc 1: three crank holes of radius 9 mm, hole 2 moved outward by 10 um
    v = stl_vertices(out / "disc1.stl")
    for h, beta in enumerate((0.0, 120.0, 240.0)):
        c, r = _hole(v, 30.0 * _u(beta), 9.0)
        assert r == pytest.approx(9.0, abs=TOL)
        assert np.abs(c - (30.0 + (10 * UM if h == 2 else 0.0)) * _u(beta)).max() < TOL
    # crank 2: the cam of disc 0 at eccentricity 1.3 mm + 10 um (own frame, at phase 0), disc 1's at 1.3 mm
    v = stl_vertices(out / "crank2.stl")
    lay = Assembly(case).layout
    for k, e in ((0, 1.3 + 10 * UM), (1, 1.3)):
        z0, z1 = lay.disc(k)
        sel = (np.isclose(v[:, 2], z0) | np.isclose(v[:, 2], z1)) & (np.linalg.norm(v[:, :2], axis=1) > 7.0 + 1e-3)
        c, r = fit_circle(v[sel])
        assert r == pytest.approx(9.0, abs=TOL)
        assert np.abs(c - e * _u(180.0 * k)).max() < TOL


@pytest.mark.slow
def test_three_crank_solids_valid_and_no_overlap_at_the_ideal_pose() -> None:
    from OCP.BRepCheck import BRepCheck_Analyzer
    from OCP.BRepGProp import BRepGProp
    from OCP.GProp import GProp_GProps

    asm = Assembly(Case.from_dict({"name": "three", "design": THREE}), theta_in_deg=17.0)
    assert [n for n in asm.parts if n.startswith(("planet", "crank"))] == \
        ["planet0", "planet1", "planet2", "crank0", "crank1", "crank2"]
    for name in ("planet2", "crank2", "flange", "disc0", "carrier"):
        s = asm[name].shape(TOL)
        assert BRepCheck_Analyzer(s).IsValid(), name
        props = GProp_GProps()
        BRepGProp.VolumeProperties_s(s, props)
        assert props.Mass() == pytest.approx(asm[name].exact_volume(), rel=2e-6), name
    for theta in (0.0, 17.0, 1000.0):
        ov = overlaps(asm.at(theta))
        assert ov["pin_disc"]["pairs"] == 0 and ov["pin_disc"]["max_depth_mm"] < TOL
        assert ov["crank_disc"]["pairs"] == 0 and not ov["stage1"]["overlap"]
        assert len(ov["stage1"]["min_gap_mm"]) == 3
    # the planets (tip circles 46.5 mm across on the 30 mm circle, 51.96 mm apart) and the cranks stay apart
    meshes = {}
    for n in ("planet0", "planet1", "planet2", "crank0", "crank1", "crank2"):
        m = asm.placed_mesh(n, 1e-2)
        meshes[n] = collision.obj(collision.bvh(m.vertices, m.faces))
    for a, b in (("planet0", "planet1"), ("planet1", "planet2"), ("planet2", "planet0"), ("crank0", "crank2")):
        assert not collision.collide(meshes[a], meshes[b]), (a, b)
        assert collision.distance(meshes[a], meshes[b]).distance > 5.0, (a, b)


@pytest.mark.slow
def test_state_pose_takes_one_angle_per_crank(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    path = tmp_path / "three.json"
    path.write_text(json.dumps({"name": "three", "design": THREE}))
    argv = ["export", str(path), "--out", str(tmp_path / "o"), "--parts", "crank2", "--format", "stl", "--json",
            "--theta-in-deg", "30", "--state"]
    ideal_out = 30.0 / 121.0
    ideal_psi = -(30.0 - ideal_out) / 3.0 + ideal_out
    assert main(argv + [f"{ideal_out},{ideal_psi},{ideal_psi},{ideal_psi}"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["pose"] == "state" and rep["overlaps"]["pin_disc"]["max_depth_mm"] < TOL
    code = main(argv + [f"{ideal_out},{ideal_psi},{ideal_psi}"])
    assert code == 2 and "must give the output angle and 3 crank angles" in capsys.readouterr().err
