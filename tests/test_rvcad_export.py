"""Export and command line: a full export read back (STEP B-rep and STL within tolerance), the
build123d parts against it, cache, atomic writes, JSON output and bad input. Timings are in
benchmarks/bench_export.py, not here."""
from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from rvcad.cli import main
from rvcad.errors import Case
from rvcad.export import atomic_write, export_case
from rvcad.parts import Assembly, CycloidDisc, GearPart
from rvcad.step import edge_samples, read_step
from rvcad.stl import read_stl
from test_rvcad_helpers import stl_chords, stl_vertices

# on one worker with test_rvcad_build: both import build123d (about 6.5 CPU-s per process)
pytestmark = pytest.mark.xdist_group("build123d")

TOL = 1e-4  # 0.1 um
PARTS = (["sun", "planet0", "planet1", "crank0", "crank1", "flange", "disc0", "disc1", "carrier", "housing"]
         + [f"pin{i:02d}" for i in range(40)])


@pytest.fixture(scope="module")
def full_export(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict, None]:
    """One full export of the nominal case through the CLI (STEP + STL, 0.1 um)."""
    out = tmp_path_factory.mktemp("export") / "nominal"
    import contextlib
    import io

    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        code = main(["export", "--out", str(out), "--json", "--theta-in-deg", "12.5"])
    assert code == 0
    return out, json.loads(buf.getvalue()), None


@pytest.fixture(scope="module")
def nominal() -> Assembly:
    return Assembly(theta_in_deg=12.5)


@pytest.mark.slow
def test_full_export_writes_every_file(full_export: tuple[Path, dict, None]) -> None:
    out, rep, _ = full_export
    names = {f["file"] for f in rep["files"]}
    expect = {f"{p}.{x}" for p in PARTS for x in ("step", "stl")} | {"assembly.step", "assembly.stl", "case.json"}
    assert names == expect
    for f in rep["files"]:
        assert (out / f["file"]).stat().st_size == f["bytes"] > 0
        assert not f["skipped"]
    assert not [p.name for p in out.iterdir() if p.name.endswith(".tmp")]
    assert rep["design_check"]["ok"] is True and rep["design_check"]["undercut"] is False
    assert rep["tolerance_um"] == 0.1 and rep["theta_in_deg"] == 12.5
    assert json.loads((out / "case.json").read_text())["errors"] == {}
    manifest = json.loads((out / "manifest.json").read_text())
    assert set(manifest["files"]) == expect
    assert rep["overlaps"]["pin_disc"]["pairs"] == 0 and rep["overlaps"]["crank_disc"]["pairs"] == 0
    assert rep["design_check"]["geometry"]["pin_penetration_mm"] < 1e-9


@pytest.mark.slow
def test_step_cycloid_and_involute_within_tolerance(full_export: tuple[Path, dict, None],
                                                    nominal: Assembly) -> None:
    """Sample the B-rep edges of the STEP files back: cycloid within 0.1 um, involutes within 0.5 um."""
    out, _, _ = full_export
    for name, budget in (("disc0", 1e-4), ("planet1", 5e-4)):
        part = nominal[name]
        shape = read_step(out / f"{name}.step")
        edges = edge_samples(shape, per_edge=48, kinds=("BSplineCurve", "Circle"))
        splines = np.concatenate([p for kind, p in edges if kind == "BSplineCurve"])
        assert len(splines) > 10000
        if isinstance(part, CycloidDisc):
            d = part.boundary_distance(splines[:, :2])
        else:
            assert isinstance(part, GearPart)
            d = part.flank_distance(splines[:, :2])
        assert np.abs(d).max() < min(budget, TOL), name
        # circles are exact circles in the B-rep
        assert any(kind == "Circle" for kind, _ in edges)


@pytest.mark.slow
def test_stl_cycloid_vertices_and_chords_within_tolerance(full_export: tuple[Path, dict, None],
                                                          nominal: Assembly) -> None:
    out, _, _ = full_export
    for name in ("disc0", "disc1"):
        part = nominal[name]
        assert isinstance(part, CycloidDisc)
        v = stl_vertices(out / f"{name}.stl")
        outer = v[np.linalg.norm(v[:, :2], axis=1) > 50.0]
        assert len(outer) > 5000
        assert np.abs(part.boundary_distance(outer[:, :2])).max() < TOL
        ch = stl_chords(out / f"{name}.stl")
        mid = 0.5 * (ch[:, 0] + ch[:, 1])
        mid = mid[np.linalg.norm(mid[:, :2], axis=1) > 50.0]
        assert len(mid) > 2 * 5000  # top and bottom outline chords
        assert np.abs(part.boundary_distance(mid[:, :2])).max() < TOL


@pytest.mark.slow
def test_stl_involute_flanks_within_tolerance(full_export: tuple[Path, dict, None], nominal: Assembly) -> None:
    out, _, _ = full_export
    for name in ("sun", "planet0"):
        part = nominal[name]
        assert isinstance(part, GearPart)
        g = part.gear
        v = stl_vertices(out / f"{name}.stl")[:, :2]
        r = np.linalg.norm(v, axis=1)
        flank = (r > g.base_radius + 1e-6) & (r < g.tip_radius - 2e-6)
        assert flank.sum() > 500
        assert part.flank_distance(v[flank]).max() < TOL
        ch = stl_chords(out / f"{name}.stl")[:, :, :2]
        ra, rb = np.linalg.norm(ch[:, 0], axis=1), np.linalg.norm(ch[:, 1], axis=1)
        both = ((ra > g.base_radius + 1e-6) & (ra < g.tip_radius - 2e-6)
                & (rb > g.base_radius + 1e-6) & (rb < g.tip_radius - 2e-6))
        mid = 0.5 * (ch[both, 0] + ch[both, 1])
        assert part.flank_distance(mid).max() < TOL


@pytest.mark.slow
def test_stl_volumes_and_assembly(full_export: tuple[Path, dict, None], nominal: Assembly) -> None:
    """STL volumes (float32 data) against the closed forms; the assembly STL is the placed parts."""
    import trimesh

    out, _, _ = full_export
    for name in ("pin00", "disc0", "housing", "carrier", "crank1"):
        tri, _ = read_stl(out / f"{name}.stl")
        m = trimesh.Trimesh(*trimesh.triangles.to_kwargs(tri).values())
        m.merge_vertices()
        assert m.is_watertight and m.is_winding_consistent
        assert m.volume == pytest.approx(nominal[name].exact_volume(), rel=5e-5)
    tri, _ = read_stl(out / "assembly.stl")
    assert len(tri) == sum(len(nominal[p].mesh(TOL).faces) for p in PARTS)
    # the placed disc in the assembly touches every pin: its outline is the placed own-frame outline
    x, y, r = nominal.placements["disc0"]
    own = nominal.placed_mesh("disc0", TOL).vertices
    a = math.radians(-r)
    back = (own[:, :2] - [x, y]) @ np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]]).T
    assert np.abs(back - nominal["disc0"].mesh(TOL).vertices[:, :2]).max() < 1e-12


@pytest.mark.slow
def test_assembly_step_has_named_placed_parts(full_export: tuple[Path, dict, None], nominal: Assembly) -> None:
    out, _, _ = full_export
    text = (out / "assembly.step").read_text(errors="replace")
    for name in ("disc0", "planet1", "crank0", "pin39", "housing", "carrier", "flange", "sun"):
        assert f"PRODUCT('{name}'" in text
    shape = read_step(out / "assembly.step")
    from OCP.Bnd import Bnd_Box
    from OCP.BRepBndLib import BRepBndLib

    box = Bnd_Box()
    BRepBndLib.Add_s(shape, box)
    lo, hi = box.CornerMin(), box.CornerMax()
    zmin, zmax, xmax = lo.Z(), hi.Z(), hi.X()
    assert zmin == pytest.approx(0.0, abs=1e-6)
    assert zmax == pytest.approx(nominal.layout.carrier[1], abs=1e-6)
    assert xmax == pytest.approx(80.0, abs=1e-3)  # the housing rim


@pytest.mark.slow
def test_rerun_skips_unchanged_files(full_export: tuple[Path, dict, None], capsys: pytest.CaptureFixture) -> None:
    out, rep, _ = full_export
    mtimes = {p.name: p.stat().st_mtime_ns for p in out.iterdir()}
    assert main(["export", "--out", str(out), "--json", "--theta-in-deg", "12.5"]) == 0
    again = json.loads(capsys.readouterr().out)
    assert all(f["skipped"] for f in again["files"])
    assert {p.name: p.stat().st_mtime_ns for p in out.iterdir() if p.name != "manifest.json"} == \
        {k: v for k, v in mtimes.items() if k != "manifest.json"}
    # another input angle changes only the assembly files
    assert main(["export", "--out", str(out), "--json", "--theta-in-deg", "20", "--format", "stl"]) == 0
    third = json.loads(capsys.readouterr().out)
    written = sorted(f["file"] for f in third["files"] if not f["skipped"])
    assert written == ["assembly.stl"]


def test_cache_key_includes_case_and_tolerance(tmp_path: Path) -> None:
    out = tmp_path / "o"
    r1 = export_case(None, out, formats=["stl"], parts=["pin00"])
    assert [f.skipped for f in r1.files] == [False, False]
    r2 = export_case(None, out, formats=["stl"], parts=["pin00"])
    assert [f.skipped for f in r2.files] == [True, True]
    r3 = export_case(None, out, formats=["stl"], parts=["pin00"], tolerance_um=0.2, force=True)
    assert [f.skipped for f in r3.files] == [False, False]
    c = Case.from_dict({"name": "j", "errors": {"pin_radius": 5}})
    r4 = export_case(c, out, formats=["stl"], parts=["pin00"], tolerance_um=0.2, force=True)
    assert [f.skipped for f in r4.files] == [False, False]
    # a file changed behind the manifest's back is rewritten
    (out / "pin00.stl").write_bytes(b"x")
    r5 = export_case(c, out, formats=["stl"], parts=["pin00"], tolerance_um=0.2)
    assert [f.skipped for f in r5.files] == [True, False]
    assert (out / "pin00.stl").stat().st_size == r4.files[1].bytes
    r6 = export_case(c, out, formats=["stl"], parts=["pin00"], tolerance_um=0.2, force=True)
    assert not any(f.skipped for f in r6.files)


def test_atomic_write_leaves_nothing_half_written(tmp_path: Path) -> None:
    target = tmp_path / "part.stl"
    target.write_bytes(b"old")

    def failing(p: Path) -> None:
        p.write_bytes(b"half")
        raise RuntimeError("disk full")

    with pytest.raises(RuntimeError, match="disk full"):
        atomic_write(target, failing)
    assert target.read_bytes() == b"old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["part.stl"]


def test_undercut_export_reports_it(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    case = tmp_path / "undercut.json"
    case.write_text(json.dumps({"name": "undercut", "design": {"pin_radius_mm": 4.8}}))
    assert main(["export", str(case), "--out", str(tmp_path / "o"), "--format", "stl", "--parts", "disc0",
                 "--quiet"]) == 0
    text = capsys.readouterr().out
    assert "undercut: yes" in text
    assert "swallowtail loops are trimmed" in text
    assert (tmp_path / "o" / "disc0.stl").stat().st_size > 0


def test_human_summary_by_default(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    assert main(["export", "--out", str(tmp_path / "o"), "--format", "stl", "--parts", "pin0?", "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "11 file(s) written" in out and "design check: ok" in out
    with pytest.raises(json.JSONDecodeError):
        json.loads(out)


# ---------------------------------------------------------------------------- bad input
def _run(argv: list[str], capsys: pytest.CaptureFixture) -> tuple[int, str, str]:
    code = main(argv)
    cap = capsys.readouterr()
    return code, cap.out, cap.err


def test_overlapping_pins_refused_by_the_cli(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    case = tmp_path / "overlap.json"
    case.write_text(json.dumps({"design": {"pin_radius_mm": 4.5}, "errors": {"pin_pitch": {"value": 4.0, "pin": 0}}}))
    code, out, err = _run(["export", str(case), "--out", str(tmp_path / "o")], capsys)
    assert code == 2
    assert "pins 0 and 1 overlap" in err and "Traceback" not in err
    assert out == ""
    assert not (tmp_path / "o").exists()
    code, _, err = _run(["export", "--out", str(tmp_path / "o")] + [str(tmp_path / "o.json")], capsys)
    assert code == 2 and "does not exist" in err


@pytest.mark.parametrize("argv, message", [
    (["export", "--out", "{d}", "--format", "iges"], "unknown format 'iges'"),
    (["export", "--out", "{d}", "--format", ""], "at least one format"),
    (["export", "--out", "{d}", "--tolerance-um", "0"], "outside"),
    (["export", "--out", "{d}", "--tolerance-um", "nan"], "outside"),
    (["export", "--out", "{d}", "--tolerance-um", "abc"], "not a number"),
    (["export", "--out", "{d}", "--theta-in-deg", "inf"], "finite"),
    (["export", "--out", "{d}", "--parts", "gearbox"], "matches no part"),
    (["export"], "--out"),
    (["frobnicate"], "invalid choice"),
])
def test_bad_arguments_exit_2(tmp_path: Path, capsys: pytest.CaptureFixture, argv: list[str], message: str) -> None:
    argv = [a.replace("{d}", str(tmp_path / "o")) for a in argv]
    code, out, err = _run(argv, capsys)
    assert code == 2
    assert message in err
    assert "Traceback" not in err


def test_bad_case_file_exit_2(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    code, _, err = _run(["export", str(bad), "--out", str(tmp_path / "o")], capsys)
    assert code == 2 and "not valid JSON" in err
    bad.write_text(json.dumps({"errors": {"pin_pich": 0.01}}))
    code, _, err = _run(["export", str(bad), "--out", str(tmp_path / "o")], capsys)
    assert code == 2 and "errors key 'pin_pich' is unknown" in err
    afile = tmp_path / "afile"
    afile.write_text("x")
    code, _, err = _run(["export", "--out", str(afile), "--parts", "pin00"], capsys)
    assert code == 2 and "not a folder" in err


def test_api_bad_input_raises() -> None:
    with pytest.raises(ValueError, match="format 'dxf' is unknown"):
        export_case(None, "/nonexistent-dir-never-created", formats=["dxf"])
    with pytest.raises(ValueError, match=r"tolerance 0.001 um must be a number in \[0.01, 100.0\] um"):
        export_case(None, "/nonexistent-dir-never-created", tolerance_um=0.001)
    with pytest.raises(ValueError, match="theta_in_deg nan must be a finite number"):
        export_case(None, "/nonexistent-dir-never-created", theta_in_deg=float("nan"))


def test_help_describes_every_option(capsys: pytest.CaptureFixture) -> None:
    assert main(["export", "--help"]) == 0
    text = capsys.readouterr().out
    for opt in ("--out", "--format", "--tolerance-um", "--theta-in-deg", "--parts", "--force", "--json", "CASE.json",
                "--state", "own frame", "world frame", "assembly.step", "exit codes", "BRepCheck"):
        assert opt in text
    assert main(["--help"]) == 0
    assert "export" in capsys.readouterr().out
    assert main([]) == 2


def test_python_dash_m_rvcad_help() -> None:
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1])}
    r = subprocess.run([sys.executable, "-m", "rvcad", "export", "--help"], capture_output=True, text=True,
                       env=env, timeout=120)
    assert r.returncode == 0 and "--tolerance-um" in r.stdout


@pytest.mark.slow
def test_build123d_parts_match_the_exported_step(full_export: tuple[Path, dict, None]) -> None:
    """rvcad.reducer gives a labelled, placed build123d Solid for every part; volumes and centres of
    mass equal those of the exported assembly.step read back with build123d (same OpenCASCADE
    solids: relative volume difference below 1e-9, centres within 1e-8 mm; measured ~1e-13 and
    ~1e-11 mm), own-frame solids equal the per-part STEP files (two cheap ones read back), and the
    closed-form volumes agree to the B-spline budget (OpenCASCADE's volume integration: 2e-6 relative)."""
    import build123d as bd

    import rvcad

    out, _, _ = full_export
    r = rvcad.reducer({}, theta_in_deg=12.5)
    assert set(r.parts) == set(PARTS) and r.ratio == pytest.approx(121.0) and r.design.z_pins == 40
    step = {c.label: c for c in bd.import_step(out / "assembly.step").children}
    assert set(step) == set(PARTS)
    for name in PARTS:
        s = r.parts[name]
        assert isinstance(s, bd.Solid) and s.label == name and s.is_valid
        assert s.volume == pytest.approx(step[name].volume, rel=1e-9), name
        assert (s.center() - step[name].center()).length < 1e-8, name
        exact = r.assembly[name].exact_volume()
        if exact is not None:
            assert s.volume == pytest.approx(exact, rel=2e-6), name
    for name in ("housing", "crank1"):  # own frame: the per-part file
        own = bd.import_step(out / f"{name}.step")
        assert r.solid(name, placed=False).volume == pytest.approx(own.volume, rel=1e-9)
    both = r.parts["disc0"] + r.parts["disc1"]  # plain build123d from here on
    assert both.volume == pytest.approx(r.parts["disc0"].volume + r.parts["disc1"].volume, rel=1e-9)
