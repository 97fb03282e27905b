"""The validation layer (issue 14 items 1, 2, 5, 7; issue 15 item 3): every bad input named.

Each example of the issues is here: a ``pytest.raises(..., match=<field>)`` on the loader, or a CLI
run that exits 2 with one line on stderr, no traceback and no file written.
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from rvcad.memo import LRUMemo
from rvcad.errors import Case, load_case
from rvcad.params import FIELD_RANGES, Design, load_design
from rvcad.profile import CycloidProfile
from rvcad.validation import (CaseError, DatasetError, DesignError, InputError, JSONInputError, OptionError,
                              TableError, as_int, as_real, loads_json)


def _case_file(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "case.json"
    p.write_text(text)
    return p


# ------------------------------------------------------------------------- case JSON (issue 14 items 1, 2)
@pytest.mark.parametrize("design, match", [
    (5, r"design 5 is of type int, not an object"),
    ("abc", r"design 'abc' is of type str, not an object"),
    ({"crank_angles_deg": 0}, r"design.crank_angles_deg 0 is of type int, not a list"),
    (None, r"design None is null, not an object"),
    ([None], r"design \[None\] is of type list, not an object"),
    (True, r"design True is of type bool, not an object"),
    ([], r"design \[\] is of type list, not an object"),
    ({"z_planet": 10000000}, r"design.z_planet 10000000 is out of range; allowed: an integer in \[6, 300\]"),
    ({"disc_gap_mm": 1e12}, r"design.disc_gap_mm 1000000000000.0 is out of range; allowed: a number in \[0, 1000\] mm"),
    ({"z_sun": "12"}, r"design.z_sun '12' is of type str, not an integer"),
    ({"z_sun": 12.5}, r"design.z_sun 12.5 is not an integer"),
    ({"crank_angles_deg": [0, "x"]}, r"design.crank_angles_deg\[1\] 'x' is of type str"),
    ({"crank_angles_deg": [0]}, r"design.crank_angles_deg \[0.0\] lists 1; allowed: 2 to 12 crank angles"),
    ({"crank_angles_deg": [30.0 * j for j in range(13)]}, r"design.crank_angles_deg \[0.0, 30.0, .* lists 13; "
                                                          r"allowed: 2 to 12 crank angles"),
    ({"pin_radius_mm": []}, r"design.pin_radius_mm \[\] is of type list, not a number"),
    ({"eccentricity_mm": float("nan")}, r"design.eccentricity_mm nan is not finite"),
])
def test_bad_design_values_name_the_field(tmp_path: Path, design, match: str) -> None:
    with pytest.raises(DesignError, match=match):
        Case.from_dict({"design": design})
    text = json.dumps({"design": design})
    if "NaN" in text:  # the strict JSON reader refuses the literal before the design sees it
        with pytest.raises(CaseError, match=r"NaN is not a JSON number"):
            load_case(_case_file(tmp_path, text))
        return
    with pytest.raises(DesignError, match=match):
        load_case(_case_file(tmp_path, text))


@pytest.mark.parametrize("text", ["null", "[null]", "true", "5", '"case"', "[]"])
def test_case_file_top_level_must_be_an_object(tmp_path: Path, text: str) -> None:
    with pytest.raises(CaseError, match=r"case file '.*case.json': the top level .* is not an object; allowed: a JSON "
                                        r"object with keys from \['name', 'design'"):
        load_case(_case_file(tmp_path, text))


@pytest.mark.parametrize("key, value, match", [
    ("errors", False, r"errors False is of type bool, not an object"),
    ("errors", 0, r"errors 0 is of type int, not an object"),
    ("errors", "", r"errors '' is of type str, not an object"),
    ("errors", None, r"errors None is null, not an object"),
    ("errors", [], r"errors \[\] is of type list, not an object"),
    ("model", 0, r"model 0 is of type int, not an object"),
    ("model", {"temperature_C": "hot"}, r"model.temperature_C 'hot' is of type str, not a number"),
    ("model", {"temperature_C": 1e9}, r"model.temperature_C 1000000000.0 degC is out of range"),
    ("load_Nm", 1e12, r"load_Nm 1000000000000.0 is out of range; allowed: a number in \[0, 20000\] N m"),
    ("load_Nm", True, r"load_Nm True is of type bool, not a number"),
    ("direction", 2, r"direction 2 is not a drive direction; allowed: \+1 or -1"),
    ("direction", True, r"direction True is not a drive direction"),
    ("name", 5, r"name 5 is of type int, not a string"),
    ("name", "a\nb", r"name 'a\\nb' holds control characters"),
])
def test_bad_case_values_name_the_field(key: str, value, match: str) -> None:
    with pytest.raises(CaseError, match=match):
        Case.from_dict({key: value})


@pytest.mark.parametrize("errors, match", [
    ({"pin_radius": []}, r"errors.pin_radius \[\] is an empty list; allowed: a number, an object"),
    ({"cam_phase": [1, 2]}, r"errors.cam_phase\[0\] 1 is not an object; allowed: objects"),
    ({"pin_radius": 10 ** 400}, r"errors.pin_radius 1000.* is too large for a float64"),
    ({"pin_radius": 1001}, r"errors.pin_radius 1001 is out of range; allowed: a number in \[-1000, 1000\] um"),
    ({"disc_phase": 6}, r"errors.disc_phase 6 is out of range; allowed: a number in \[-5, 5\] deg"),
    ({"sun_eccentricity": {"value": 1, "angle_deg": 1e9}}, r"errors.sun_eccentricity.angle_deg 1000000000.0 is out of range"),
    ({"pin_pitch": {"value": 0.01, "pin": 1.5}}, r"errors.pin_pitch.pin 1.5 is not an integer"),
    ({"pin_pitch": {"value": 0.01, "pin": True}}, r"errors.pin_pitch.pin True is of type bool"),
    ({"pin_pitch": {"pin": 3}}, r"errors.pin_pitch {'pin': 3} has no 'value'"),
    ({"pin_pitch": None}, r"errors.pin_pitch None is of type NoneType, not a number"),
])
def test_bad_error_values_name_the_field(errors: dict, match: str) -> None:
    with pytest.raises(CaseError, match=match):
        Case.from_dict({"errors": errors})


@pytest.mark.parametrize("text, field", [
    ('{"design": {}, "design": {"z_sun": 18}}', "design"),
    ('{"errors": {"pin_radius": 1, "pin_radius": 2}}', "pin_radius"),
    ('{"design": {"z_sun": 12, "z_sun": 18}}', "z_sun"),
])
def test_duplicate_json_keys_are_an_error(tmp_path: Path, text: str, field: str) -> None:
    with pytest.raises(CaseError, match=rf"case file '.*': key '{field}' appears twice in one object"):
        load_case(_case_file(tmp_path, text))


def test_strict_json_helpers() -> None:
    with pytest.raises(JSONInputError, match=r"x: NaN is not a JSON number"):
        loads_json('{"a": NaN}', "x")
    with pytest.raises(JSONInputError, match=r"x: key 'b' appears twice"):
        loads_json('[{"a": {"b": 1, "b": 2}}]', "x")
    with pytest.raises(JSONInputError, match=r"x nests too deeply"):
        loads_json("[" * 100000, "x")
    with pytest.raises(JSONInputError, match=r"x is not readable JSON"):
        loads_json("1" * 5000, "x")
    assert loads_json('{"a": [1, 2.5, null]}', "x") == {"a": [1, 2.5, None]}
    assert as_int(12.0, "n", lo=0, hi=20) == 12 and as_real(3, "x", lo=0.0) == 3.0
    for cls in (CaseError, DesignError, TableError, DatasetError, OptionError, JSONInputError):
        assert issubclass(cls, InputError) and issubclass(cls, ValueError)


def test_valid_cases_still_load(tmp_path: Path) -> None:
    case = load_case(_case_file(tmp_path, json.dumps({
        "design": {"z_sun": 18, "z_planet": 36, "z_pins": 40, "z_disc": 39.0},
        "errors": {"pin_radius": [0.5] * 40, "pin_pitch": [{"value": 0.01, "pin": 3}], "cam_phase": {"value": 2}},
        "load_Nm": 0, "direction": -1.0, "model": {"temperature_C": 30}})))
    assert case.design.ratio == pytest.approx(81.0, abs=1e-12)
    assert case.direction == -1 and case.load_Nm == 0.0 and case.name == "case"
    assert Case.from_dict(case.to_dict()) == case


# ------------------------------------------------------------------------- design relations (issue 15 item 3)
def test_every_numeric_design_field_has_a_physical_range() -> None:
    from dataclasses import fields

    numeric = [f.name for f in fields(Design) if isinstance(f.default, (int, float)) and not isinstance(f.default, bool)]
    missing = [n for n in numeric + ["crank_angles_deg"] if n not in FIELD_RANGES]
    assert missing == [], f"add these Design fields to rvcad.params.FIELD_RANGES: {missing}"
    for n, (lo, hi, _, _) in FIELD_RANGES.items():
        default = getattr(Design(), n)
        for x in (default if isinstance(default, tuple) else (default,)):
            assert lo <= x <= hi, n


@pytest.mark.parametrize("name", sorted(FIELD_RANGES))
def test_every_design_field_has_a_range_naming_it(name: str) -> None:
    lo, hi, _, _ = FIELD_RANGES[name]
    big = [0.0, 2 * hi] if name == "crank_angles_deg" else (int(hi) + 1 if name.startswith("z_") else 2 * hi)
    with pytest.raises(DesignError, match=rf"design.{name}"):
        Design.from_dict({name: big})
    with pytest.raises(DesignError, match=rf"design.{name}.* is of type str"):
        Design.from_dict({name: "abc"})


@pytest.mark.parametrize("design, match", [
    ({"z_disc": 38}, r"design.z_disc 38 .*allowed: z_pins - 1 = 39"),
    ({"z_pins": 30}, r"design.z_disc 39 .*allowed: z_pins - 1 = 29"),
    ({"pin_radius_mm": 5.1}, r"design.pin_radius_mm 5.1 mm makes the 40 pins overlap.*< half the pin chord pitch, 5.0214 mm"),
    ({"eccentricity_mm": 1.6}, r"design.eccentricity_mm 1.6 mm gives a shortening coefficient e\*Zp/Rp = 1.0000 >= 1"),
    ({"crank_angles_deg": [0, 0]}, r"design.crank_angles_deg \[0, 0\] puts the two planets 0.000 mm apart"),
    ({"crank_angles_deg": [0, 90]}, r"design.crank_angles_deg \[0, 90\] puts the two planets 42.426 mm apart .*"
                                    r"tip circles \(46.500 mm across\) overlap; allowed: cranks at least 101.61 deg"),
    ({"crank_angles_deg": [0, 90, 180]}, r"design.crank_angles_deg \[0, 90, 180\] puts planets 0 and 1 42.426 mm apart"
                                         r".*allowed: cranks at least 101.61 deg apart \(at most 3 cranks\)"),
    # a pillar midway between cranks 120 deg apart on the 30 mm crank circle stands 2 a sin(30 deg) = 30 mm from
    # each: its hole (17 + 1.3 mm) and the 12 mm crank hole overlap
    ({"crank_angles_deg": [0, 120, 240], "cam_radius_mm": 12.0, "disc_center_hole_radius_mm": 11.0,
      "carrier_pillar_radius_mm": 17.0},
     r"design.carrier_pillar_radius_mm 17.0 mm: the pillar holes of the discs .* cut into the crank holes \(cam "
     r"radius 12 mm\); allowed: < 16.7000 mm \(a pillar midway between the closest cranks, 120 deg apart, stands "
     r"30.0000 mm from each\)"),
    ({"cam_radius_mm": 29.0}, r"design.cam_radius_mm 29.0 mm plus the eccentricity reaches the disc centre"),
    ({"crank_journal_radius_mm": 8.0}, r"design.crank_journal_radius_mm 8.0 mm does not pass through the cam"),
    ({"housing_outer_radius_mm": 66.0}, r"design.housing_outer_radius_mm 66.0 mm does not hold the pins"),
])
def test_design_relations_name_the_field(design: dict, match: str) -> None:
    with pytest.raises(DesignError, match=match):
        Design.from_dict(design)


def test_designs_of_issue_15_are_valid() -> None:
    assert Design.from_dict({"z_sun": 18, "z_planet": 36}).ratio == pytest.approx(81.0, abs=1e-9)
    d30 = Design.from_dict({"z_pins": 30, "z_disc": 29})
    assert d30.ratio == pytest.approx(1 + 36 * 30 / 12, abs=1e-9)


def test_a_design_read_once_is_taken_from_the_memo_and_a_refused_one_is_refused_every_time(monkeypatch) -> None:
    """Design.from_dict keeps the designs it validated by the JSON text of their object: an equal object (keys in
    any order) gives the same frozen Design, another value another Design, a refused object its DesignError naming
    the field on every call, and the memo holds at most DESIGN_MEMO_SIZE designs. to_dict gives a new dict each
    time (the asdict is made once per design), and Case.key is the content hash either way."""
    from rvcad import params

    monkeypatch.setattr(params, "design_memo", LRUMemo(2))
    a = Design.from_dict({"z_sun": 12, "eccentricity_mm": 1.3})
    assert Design.from_dict({"eccentricity_mm": 1.3, "z_sun": 12}) is a
    b = Design.from_dict({"z_sun": 12, "eccentricity_mm": 1.2})
    assert b is not a and b.eccentricity_mm == 1.2 and a.eccentricity_mm == 1.3
    for _ in range(2):
        with pytest.raises(DesignError, match="design.eccentricity_mm"):
            Design.from_dict({"eccentricity_mm": -1.0})
    Design.from_dict({"z_sun": 12, "eccentricity_mm": 1.1})
    assert len(params.design_memo) == 2
    assert Design.from_dict({"z_sun": 12, "eccentricity_mm": 1.3}) is not a       # pushed out, validated again
    d1, d2 = a.to_dict(), a.to_dict()
    assert d1 == d2 and d1 is not d2 and d1["crank_angles_deg"] is not d2["crank_angles_deg"]
    d1["z_sun"] = 99
    d1["crank_angles_deg"].append(1.0)
    assert a.to_dict() == d2 and Design.from_dict(d2) == a
    c1 = Case.from_dict({"design": {"eccentricity_mm": 1.3}, "errors": {"cam_phase": 1.0}})
    c2 = Case.from_dict({"design": {"eccentricity_mm": 1.2}, "errors": {"cam_phase": 1.0}})
    assert c1.key() == c1.key() != c2.key()
    assert c1.key() == Case.from_dict(c1.to_dict()).key()


def test_the_memo_is_shared_by_threads_without_error(monkeypatch) -> None:
    """rvcad.memo.LRUMemo holds a lock: 8 threads reading 7 designs through a memo of 3 (evicting all the time) get
    each its own design and no error."""
    import threading

    from rvcad import params

    monkeypatch.setattr(params, "design_memo", LRUMemo(3))
    errors: list[str] = []

    def work(k: int) -> None:
        try:
            for i in range(200):
                e = 1.0 + 0.01 * ((i + k) % 7)
                assert Design.from_dict({"eccentricity_mm": e}).eccentricity_mm == e
        except Exception as exc:  # noqa: BLE001 - collected and asserted below
            errors.append(repr(exc))

    threads = [threading.Thread(target=work, args=(k,)) for k in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert errors == [] and len(params.design_memo) == 3


def test_undercut_radius_matches_the_profile_maths() -> None:
    d = Design()
    prof = CycloidProfile(d.pin_circle_radius_mm, d.eccentricity_mm, d.z_pins, d.pin_radius_mm)
    assert d.min_convex_radius_mm == pytest.approx(prof.min_convex_radius, rel=1e-4)
    assert 4.5 < d.min_convex_radius_mm < 4.7  # conventions: "about 4.6 mm"
    # undercut is allowed (the CAD trims the loops and reports it), overlapping pins are not
    assert Design.from_dict({"pin_radius_mm": 4.8}).pin_radius_mm > d.min_convex_radius_mm


def test_design_file(tmp_path: Path) -> None:
    p = tmp_path / "design.json"
    p.write_text('{"z_sun": 18, "z_planet": 36}')
    assert load_design(p).ratio == pytest.approx(81.0)
    p.write_text('{"z_sun": 18, "z_sun": 36}')
    with pytest.raises(DesignError, match=r"design file '.*design.json': key 'z_sun' appears twice"):
        load_design(p)
    p.write_text("[1]")
    with pytest.raises(DesignError, match=r"design file '.*' \[1\] is not an object"):
        load_design(p)
    with pytest.raises(DesignError, match=r"design file '.*missing.json' does not exist"):
        load_design(tmp_path / "missing.json")
    from rvstudy.study import load_reducer

    p.write_text('{"design": {"z_sun": 18, "z_sun": 36}}')
    with pytest.raises(DesignError, match=r"--reducer file '.*design.json': key 'z_sun' appears twice"):
        load_reducer(str(p))
    p.write_text('{"design": 5}')
    with pytest.raises(DesignError, match=r"--reducer design.json: design 5 is of type int, not an object"):
        load_reducer(str(p))
    p.write_text('{"design": {"z_sun": 18, "z_planet": 36}}')
    assert load_reducer(str(p)).ratio == pytest.approx(81.0)


# ------------------------------------------------------------------------- tables and datasets
def test_tolerance_tables(tmp_path: Path) -> None:
    from rvstudy.montecarlo import load_tolerances, parse_tolerance

    j = tmp_path / "t.json"
    j.write_text('{"pin_radius": "normal:1", "pin_radius": "normal:2"}')
    with pytest.raises(TableError, match=r"key 'pin_radius' appears twice"):
        load_tolerances(j)
    c = tmp_path / "t.csv"
    c.write_text("error,dist,p1\npin_radius,normal,1\npin_radius,normal,2\n")
    with pytest.raises(TableError, match=r"row 2: error 'pin_radius' is given twice"):
        load_tolerances(c)
    c.write_text("error,dist,p1,p5\npin_radius,normal,1,2\n")  # p4 is truncnormal's MEAN
    with pytest.raises(TableError, match=r"column 'p5' is unknown"):
        load_tolerances(c)
    c.write_bytes(b"error,dist\n\xff\xfe,normal\n")
    with pytest.raises(TableError, match=r"cannot be read as CSV"):
        load_tolerances(c)
    # a row with more fields than the header: pandas took the first column as the index and shifted the fields
    # ("pin_radius,normal,1" read as error "normal"); an extra empty field (the fuzz test's example, which gave a
    # TypeError on the row number) carries nothing and is read as the row without it
    c.write_text("error,dist\npin_radius,normal,1\n")
    with pytest.raises(TableError, match=r"t\.csv': line 2 has 3 fields but the header has 2 columns; allowed: one field per "
                       r"column of the header"):
        load_tolerances(c)
    c.write_text("error,dist\n0,,\n,")
    with pytest.raises(TableError, match=r"row 1: tolerance 0: error key '0' is unknown"):
        load_tolerances(c)
    c.write_text("error,dist,p1\npin_radius,normal,1\n")
    assert load_tolerances(c)["pin_radius"].params == (1.0,)
    with pytest.raises(TableError, match=r"pin_radius=normal:200.*reaches 1200 um; allowed: draws within \|value\| <= 1000"):
        parse_tolerance("pin_radius=normal:200")
    with pytest.raises(TableError, match=r"disc_phase=uniform:-9:1.*reaches 9 deg"):
        parse_tolerance("disc_phase=uniform:-9:1")
    assert parse_tolerance("pin_radius=normal:100").params == (100.0,)


def test_levels_table_values_within_the_case_bounds(tmp_path: Path) -> None:
    from rvstudy.study import load_factors

    p = tmp_path / "levels.csv"
    p.write_text("factor,low,center,high,unit,error\nEA,-0.02,0,0.02,deg,pin_pitch\nEB,-2000,0,2000,um,"
                 "pin_circle_diameter\nEC,-5,0,5,um,pin_radius\n")
    with pytest.raises(TableError, match=r"--levels: factor 'EB' \(pin_circle_diameter\) low -2000.0 um is out of range; allowed: "
                                         r"a finite value with \|value\| <= 1000 um"):
        load_factors(str(p), None)


def test_dataset_errors_are_dataset_errors(tmp_path: Path) -> None:
    from rvrig.dataset import read_dataset

    (tmp_path / "runs.csv").write_text("run,load_Nm,direction\na,20,2\n")
    (tmp_path / "samples.csv").write_text("run,input_deg,output_deg\na,0,0\n")
    with pytest.raises(DatasetError, match=r"runs.csv: column 'direction' run a is 2"):
        read_dataset(tmp_path)
    # found by the fuzz: an empty run cell in samples.csv (pandas 3 keeps it NaN) crashed the run lookup
    (tmp_path / "runs.csv").write_text("run,load_Nm,direction\n1,20,1\n")
    (tmp_path / "samples.csv").write_text("run,input_deg,output_deg\n,-1,-1\n1,0.0,0.0\na,10890.0,90.0\n")
    with pytest.raises(DatasetError, match=r"samples.csv: column 'run' row 2 is empty"):
        read_dataset(tmp_path)


# ------------------------------------------------------------------------- command lines (items 2, 5, 7)
def _one_line_exit_2(capsys: pytest.CaptureFixture, rc: int, needle: str) -> None:
    err = capsys.readouterr().err
    assert rc == 2, err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert needle in err, err


def test_rvdyn_te_refusals(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    from rvdyn.cli import main

    outdir = tmp_path / "existing"
    outdir.mkdir()
    _one_line_exit_2(capsys, main(["te", "--steps", "8", "--out", str(outdir)]), f"--out '{outdir}' is an existing folder")
    assert list(outdir.iterdir()) == []
    out = tmp_path / "te.csv"
    _one_line_exit_2(capsys, main(["te", "--steps", "1000000000", "--out", str(out)]),
                     "--steps 1000000000 is out of range; allowed: an integer in [2, 100000]")
    _one_line_exit_2(capsys, main(["te", "--revolutions", "1e9", "--out", str(out)]), "--revolutions 1000000000.0")
    _one_line_exit_2(capsys, main(["te", str(_case_file(tmp_path, '{"design": 5}')), "--out", str(out)]),
                     "design 5 is of type int, not an object")
    try:
        rc = main(["te", "--steps", "abc"])
    except SystemExit as exc:
        rc = exc.code
    _one_line_exit_2(capsys, rc, "argument --steps: invalid int value: 'abc'")
    assert not out.exists() and list(tmp_path.glob(".te.csv*")) == []


def test_rv_stackup_refusals(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    from rvstudy.cli import main

    afile = tmp_path / "afile"
    afile.write_text("x")
    _one_line_exit_2(capsys, main(["--out", str(afile), "--solver", "analytic", "--no-progress"]),
                     f"--out '{afile}' is an existing file, not a folder")
    assert afile.read_text() == "x"
    out = tmp_path / "o"
    _one_line_exit_2(capsys, main(["--out", str(out), "--steps", "1000000000", "--stages", "screen", "--solver",
                                   "analytic", "--no-progress"]),
                     "--steps 1000000000 is out of range; allowed: an integer in [2, 100000]")
    for argv, needle in ((["--workers", "1000"], "--workers 1000 is out of range"),
                         (["--mc-check", "100000"], "--mc-check 100000 is out of range"),
                         (["--mc-draws", "1000000000"], "--mc-draws 1000000000 is out of range"),
                         (["--sweep-points", "100000"], "--sweep-points 100000 is out of range")):
        _one_line_exit_2(capsys, main(["--out", str(out), "--solver", "analytic", "--no-progress", *argv]), needle)
    assert not out.exists()


def test_rv_calibrate_refusals(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    from rvcalib.cli import main

    out = tmp_path / "o"
    for argv, needle in ((["--max-terms", "0"], "--max-effects 0 is out of range; allowed: an integer in [1, 1000]"),
                         (["--max-order", "-3"], "--max-order -3 is out of range; allowed: an integer in [1, 5000]"),
                         (["--workers", "64"], "--workers 64 is out of range; allowed: an integer in [1, 32]"),
                         (["--rated-Nm", "inf"], "--rated-Nm inf is not finite"),
                         (["--empirical-weight", "nan"], "--empirical-weight nan is not finite")):
        _one_line_exit_2(capsys, main([str(tmp_path / "dataset"), "--out", str(out), *argv]), needle)
    assert not out.exists()


def test_rvcad_export_refuses_before_writing(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    from rvcad.cli import main

    out = tmp_path / "o"
    for text, needle in (('{"design": {"crank_angles_deg": 0}}', "design.crank_angles_deg 0"),
                         ('{"design": {"stage1_backlash_mm": 1.0}}', "design.stage1_backlash_mm 1.0 mm"),
                         ('{"design": {"crank_angles_deg": [0, 0]}}', "design.crank_angles_deg [0, 0]"),
                         ('{"errors": {}, "errors": {}}', "key 'errors' appears twice")):
        _one_line_exit_2(capsys, main(["export", str(_case_file(tmp_path, text)), "--out", str(out)]), needle)
    assert not out.exists()


def test_rsm_design_refusals(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    from rsm.cli import main

    _one_line_exit_2(capsys, main(["design", "ccd", "--factors", "3", "--center", "100000000"]),
                     "--center 100000000 is out of range")
    _one_line_exit_2(capsys, main(["design", "bbd", "--factors", "3", "--out", str(tmp_path)]), "is an existing folder")
