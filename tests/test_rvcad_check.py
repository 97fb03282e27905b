"""Bad CAD input never gives an invalid file: the geometric design check (named fields, nothing
written), BRepCheck of every STEP solid, overlaps of the placed parts, export folders that never
mix two cases, output permissions and the temporary files of a killed export."""
from __future__ import annotations

import json
import math
import os
import stat
from pathlib import Path

import numpy as np
import pytest

import rvcad
from rvcad.atomic import atomic_path, remove_stale_temps
from rvcad.check import check_case, crank_period_input, pin_interference
from rvcad.cli import main
from rvcad.errors import Case
from rvcad.export import ExportFolderError, content_key, export_case
from rvcad.geometry import ReducerGeometry
from rvcad.occ import InvalidSolidError
from rvcad.overlap import overlaps
from rvcad.params import Design
from rvcad.parts import Assembly
from rvcad.validation import DesignError

#: The four examples of issue 14 (items 3 and 4): the crank angles are refused by the design layer
#: (Design.validate: the planets overlap), the others by the geometric check (rvcad.check).
BAD = [
    ({"design": {"stage1_backlash_mm": 1.0}}, r"design\.stage1_backlash_mm 1\.0 mm thins the planet teeth to a "
                                              r"point .* allowed: below 0\.99"),
    ({"design": {"crank_angles_deg": [0, 0]}}, r"design\.crank_angles_deg \[0, 0\] puts the two planets"),
    ({"errors": {"pin_radius": 1000}}, r"errors\.pin_radius 1000 makes the parts overlap \(pins in the discs, "
                                       r"loaded stage I flanks\) by at least 1000\.0 um .* at most 100 um"),
    ({"errors": {"pin_circle_diameter": -1000}}, r"errors\.pin_circle_diameter -1000 makes the parts overlap .* by "
                                                 r"at least 500\.0 um .* at most 100 um"),
]


@pytest.mark.parametrize("case, message", BAD)
def test_design_check_names_the_field(case: dict, message: str) -> None:
    with pytest.raises(DesignError, match=message) as err:
        check_case(Case.from_dict(case))
    assert err.value.field == message.split(" ")[0].replace("\\", "")
    with pytest.raises(DesignError, match=message.split(" ")[0]):
        rvcad.reducer(case)


@pytest.mark.parametrize("case, message", BAD)
def test_cli_refuses_before_writing(tmp_path: Path, capsys: pytest.CaptureFixture, case: dict, message: str) -> None:
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(case))
    for fmt in ("step,stl", "stl"):
        code = main(["export", str(path), "--out", str(tmp_path / "o"), "--parts", "planet0,disc0", "--format", fmt])
        cap = capsys.readouterr()
        assert code == 2 and cap.out == ""
        lines = cap.err.strip().splitlines()
        assert len(lines) == 1 and "Traceback" not in cap.err
        assert lines[0].startswith("rvcad export: error: ") and __import__("re").search(message, lines[0])
        assert not (tmp_path / "o").exists()


def test_tooth_land_closed_form() -> None:
    """The planet's tip land vanishes at b_max = 2 r_pitch * (tip half angle) of the geometry's own
    involute (thinning by b turns each flank by b / (2 r_pitch)); the check keeps a 1 um land, so it
    refuses from b_max - 1 um * r_pitch / r_tip on."""
    g = ReducerGeometry(Case.from_dict({}))
    b_max = 2.0 * g.planet.pitch_radius * g.planet.tip_half_angle()
    assert 0.99 < b_max < 1.0
    check_case(Case.from_dict({"design": {"stage1_backlash_mm": round(b_max - 2e-3, 4)}}))
    with pytest.raises(DesignError, match="stage1_backlash_mm"):
        check_case(Case.from_dict({"design": {"stage1_backlash_mm": round(b_max + 1e-4, 4)}}))


def test_pin_interference_closed_forms() -> None:
    """Nominal: the pins touch (0). All pins larger by d: d in every pose (the disc is surrounded by
    pins on every normal). Pin circle smaller by 2 d: each pin moves d radially, d cos(a) along its
    contact normal (a: angle between normal and radius, 0 at the roots and tips), so the largest
    penetration lies in (d cos(a_max), d] and reaches d where a pin sits at a root or tip. The
    bound never exceeds what rvdyn's equilibrium keeps (checked against rvdyn below)."""
    assert np.abs(pin_interference(ReducerGeometry(Case.from_dict({})), states=4)).max() < 1e-9
    pen = pin_interference(ReducerGeometry(Case.from_dict({"errors": {"pin_radius": 50}})), states=4)
    assert pen.min() == pytest.approx(0.05, abs=1e-6)
    pen = pin_interference(ReducerGeometry(Case.from_dict({"errors": {"pin_circle_diameter": -100}})), states=4)
    assert 0.0495 < pen.min() and pen.max() <= 0.05 + 1e-9


def test_interference_bound_below_the_solver() -> None:
    """One pin 80 um too large: the check's bound (smallest reachable penetration, 45-62 um over the
    states) lies below the penetration rvdyn's equilibrium keeps at the same states (81-82 um) and
    is of its size (the solver also holds the planets and the unloaded flanks)."""
    from rvdyn.contacts import AnalyticContacts
    from rvdyn.solver import QuasiStaticSolver

    case = Case.from_dict({"errors": {"pin_radius": [{"pin": 3, "value": 80}]}})
    g = ReducerGeometry(case)
    bound = pin_interference(g, states=6)
    th = np.linspace(0.0, crank_period_input(g), 6, endpoint=False)
    sol = QuasiStaticSolver(g, AnalyticContacts(g)).solve(th, direction=1, load_Nm=case.load_Nm)
    assert np.all(bound <= sol.max_penetration_mm + 1e-6)
    assert bound.max() > 0.5 * sol.max_penetration_mm.max()


def test_invalid_solid_is_an_error_not_a_file(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Past the design checks (bypassed here: the case is built without validation and the geometric
    check is switched off), BRepCheck stops the pointed planet: no planet0.step."""
    monkeypatch.setattr("rvcad.export.check_case", lambda case, geometry=None: {})
    case = Case(name="pointed", design=Design(stage1_backlash_mm=1.0))
    with pytest.raises(InvalidSolidError, match="part planet0: the built solid is not valid"):
        export_case(case, tmp_path / "o", formats=["step"], parts=["planet0"])
    assert not (tmp_path / "o" / "planet0.step").exists()
    assert not [p for p in (tmp_path / "o").iterdir() if p.name.endswith(".tmp")]


# ---------------------------------------------------------------------------- overlaps
def test_overlaps_closed_form_crank_disc() -> None:
    """A crank hole of disc 0 moved radially by 10 um: the rigid fit of the disc to its two cams
    splits the mismatch, so each cam sits 5 um off its hole: depth 5 um, volume of the two
    crescents pi r^2 - lens(r, r, d) times the disc width."""
    case = Case.from_dict({"errors": {"disc_hole_eccentricity": {"disc": 0, "hole": 0, "value": 10}}})
    ov = overlaps(Assembly(case, 7.0))
    cd = ov["crank_disc"]
    assert cd["pairs"] == 2 and cd["max_depth_mm"] == pytest.approx(0.005, abs=1e-9)
    r, d, w = 9.0, 0.005, 10.0
    lens = 2 * r * r * math.acos(d / (2 * r)) - 0.5 * d * math.sqrt(4 * r * r - d * d)
    assert cd["volume_mm3"] == pytest.approx(2 * (math.pi * r * r - lens) * w, rel=1e-9)
    # the disc itself moved by the 5 um fit residual, so it can reach the pins by at most that
    assert ov["pin_disc"]["max_depth_mm"] <= 0.005 + 1e-9 and not ov["stage1"]["overlap"]


def test_overlaps_pins_and_report(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """Pins 20 um larger: every pin overlaps both discs by 20 um at the ideal pose; the export's
    JSON and summary report it."""
    ov = overlaps(Assembly(Case.from_dict({"errors": {"pin_radius": 20}}), 3.0))
    pd = ov["pin_disc"]
    assert pd["pairs"] == 80 and pd["max_depth_mm"] == pytest.approx(0.02, abs=1e-9)
    assert 0 < pd["volume_mm3"] < 80 * 0.02 * 2 * 3.0 * 10.0  # below depth x pin diameter x width each
    path = tmp_path / "c.json"
    path.write_text(json.dumps({"errors": {"pin_radius": 20}}))
    assert main(["export", str(path), "--out", str(tmp_path / "o"), "--parts", "pin00", "--format", "stl",
                 "--json"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["pose"] == "ideal" and rep["overlaps"]["pin_disc"]["pairs"] == 80
    assert main(["export", str(path), "--out", str(tmp_path / "o"), "--parts", "pin00", "--format", "stl",
                 "--quiet"]) == 0
    assert "overlaps: pin-disc" in capsys.readouterr().out


def test_solved_pose_export(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """rvcad places the assembly at an explicit state; rvdyn.pose gives the solved one (rvcad sits
    below rvdyn and never imports it): output angle within the TE of the ideal one, the pose named
    in the report, the assembly's cache key changed."""
    from rvdyn.pose import main as pose_main
    from rvdyn.pose import solved_state

    case = Case.from_dict({"name": "c", "errors": {"pin_radius": 5}})
    to, psi = solved_state(case, 30.0)
    ideal = math.radians(30.0) / case.design.ratio
    assert abs(to - ideal) < math.radians(60 / 3600) and len(psi) == 2
    path = tmp_path / "c.json"
    path.write_text(json.dumps(case.to_dict()))
    assert pose_main([str(path), "--theta-in-deg", "30"]) == 0
    text = capsys.readouterr().out.strip()
    assert [float(v) for v in text.split(",")] == pytest.approx([math.degrees(v) for v in (to,) + psi], abs=1e-9)
    argv = ["export", str(path), "--out", str(tmp_path / "o"), "--parts", "pin00", "--format", "stl",
            "--theta-in-deg", "30", "--json", "--state", text]
    assert main(argv) == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["pose"] == "state" and rep["overlaps"]["pose"] == "state"
    assert rep["overlaps"]["pin_disc"]["max_depth_mm"] < 0.1  # elastic contact under the case's load
    # the assembly files of another state are cached under their own key
    assert content_key(case, 0.1, "stl", "assembly.stl", 30.0, (to, psi)) != \
        content_key(case, 0.1, "stl", "assembly.stl", 30.0)
    code = main(argv[:-1] + ["1,2"])
    cap = capsys.readouterr()
    assert code == 2 and "--state 1,2 must give the output angle and 2 crank angles" in cap.err


# ---------------------------------------------------------------------------- export folders
def test_folder_of_another_case_refused_or_cleaned(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    out = tmp_path / "o"
    assert main(["export", "--out", str(out), "--parts", "pin0?", "--format", "stl", "--quiet"]) == 0
    capsys.readouterr()
    before = sorted(p.name for p in out.iterdir())
    other = tmp_path / "other.json"
    other.write_text(json.dumps({"name": "other", "errors": {"pin_radius": 5}}))
    code = main(["export", str(other), "--out", str(out), "--parts", "disc0", "--format", "stl"])
    cap = capsys.readouterr()
    assert code == 2 and cap.out == "" and len(cap.err.strip().splitlines()) == 1
    assert "holds the export of case 'nominal'" in cap.err and "--force" in cap.err
    assert sorted(p.name for p in out.iterdir()) == before
    with pytest.raises(ExportFolderError, match="refusing to mix case 'other'"):
        export_case(Case.from_dict({"name": "other", "errors": {"pin_radius": 5}}), out, formats=["stl"],
                    parts=["disc0"])
    (out / "notes.txt").write_text("mine")
    assert main(["export", str(other), "--out", str(out), "--parts", "disc0", "--format", "stl", "--force"]) == 0
    text = capsys.readouterr().out
    assert "--force: removed 12 file(s) of another export" in text
    assert sorted(p.name for p in out.iterdir()) == ["case.json", "disc0.stl", "manifest.json", "notes.txt"]
    assert json.loads((out / "manifest.json").read_text())["case_name"] == "other"


# ---------------------------------------------------------------------------- permissions and temp files
@pytest.mark.parametrize("umask, mode", [(0o022, 0o644), (0o027, 0o640)])
def test_outputs_follow_the_umask(tmp_path: Path, umask: int, mode: int) -> None:
    old = os.umask(umask)
    try:
        with atomic_path(tmp_path / "f.txt") as tmp:
            tmp.write_text("x")
        rep = export_case(None, tmp_path / "o", formats=["stl"], parts=["pin00"])
    finally:
        os.umask(old)
    assert stat.S_IMODE((tmp_path / "f.txt").stat().st_mode) == mode
    for f in rep.files:
        assert stat.S_IMODE((tmp_path / "o" / f.file).stat().st_mode) == mode, f.file
    assert stat.S_IMODE((tmp_path / "o" / "manifest.json").stat().st_mode) == mode


def test_rerun_removes_temp_files_of_a_killed_export(tmp_path: Path) -> None:
    """A kill between write and rename leaves .<file>.XXXXXXXX.tmp; the rerun removes exactly those."""
    out = tmp_path / "o"
    out.mkdir()
    left = [".planet0.step.k1ll3d_x.tmp", ".manifest.json.abcdefgh.tmp", ".pin07.stl.a1b2c3d4.tmp"]
    keep = [".planet0.step.tmp", ".other.abcdefgh.tmp", "notes.tmp", ".planet0.step.abcdefgh.tmp.bak"]
    for n in left + keep:
        (out / n).write_text("x")
    rep = export_case(None, out, formats=["stl"], parts=["pin00"])
    assert sorted(rep.removed_temps) == sorted(left)
    assert sorted(p.name for p in out.iterdir()) == sorted(keep + ["case.json", "manifest.json", "pin00.stl"])
    assert remove_stale_temps(out, ["pin00.stl"]) == []


def test_check_case_takes_what_reducer_takes(tmp_path: Path) -> None:
    """A Case, the case JSON object as a dict, the path of a case JSON file, or None (nominal)."""
    d = {"errors": {"pin_radius": 5.0}}
    want = check_case(Case.from_dict(d), cache=False)
    path = tmp_path / "case.json"
    path.write_text(json.dumps(d))
    assert check_case(d, cache=False) == want
    assert check_case(path, cache=False) == want and check_case(str(path), cache=False) == want
    assert check_case(None, cache=False) == check_case(Case.from_dict({}), cache=False) != want
    with pytest.raises(DesignError, match=r"design\.stage1_backlash_mm 1\.0 mm thins"):
        check_case(BAD[0][0])
    with pytest.raises(ValueError, match=r"errors key 'pin_radus' is unknown"):
        check_case({"errors": {"pin_radus": 5.0}})
    with pytest.raises(ValueError, match="case 7 is of type int; allowed: a rvcad.Case, a dict"):
        check_case(7)
    with pytest.raises(ValueError, match="case file"):
        check_case(tmp_path / "missing.json")
