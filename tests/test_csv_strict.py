"""One strict CSV reader (rsm.csvio.read_csv_strict) behind every table the tools read.

pandas reads a row with more fields than the header by taking the first column as the index and shifting
the rest; a trailing comma on every row (a spreadsheet export) then moved every value one column without
a word. Each reader now reads the trailing empty field as nothing and refuses a real extra field, naming
the file, the line and the counts.
"""
from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest

import rsm
from rsm.cli import main as rsm_main
from rsm.csvio import read_csv_strict
from rvcad.validation import DatasetError, TableError
from rvrig.dataset import read_dataset
from rvpaper import DATA_DIR as PAPER_DATA
from rvstudy.factors import load_factors


def test_reader_trailing_comma_extra_field_and_bad_files(tmp_path: Path):
    p = tmp_path / "t.csv"
    p.write_text("a,b\n1,2,\n3,4,\n")  # trailing comma on every row: plain pandas gave a = 2, 4 and b = NaN
    assert pd.read_csv(p)["a"].tolist() == [2, 4]  # the pitfall itself, so this test cannot pass by accident
    df = read_csv_strict(p, "data file")
    assert df["a"].tolist() == [1, 3] and df["b"].tolist() == [2, 4]
    p.write_text(" a , b\n1,2\n5,6,7\n")
    with pytest.raises(ValueError, match=r"data file '.*t\.csv': line 3 has 3 fields but the header has 2 columns"):
        read_csv_strict(p, "data file")
    p.write_text("a,b\n1,2\n")
    assert list(read_csv_strict(p, "data file").columns) == ["a", "b"]
    p.write_text("")
    with pytest.raises(ValueError, match=r"data file '.*' is empty; allowed: a CSV file with a header row"):
        read_csv_strict(p, "data file")
    p.write_bytes(b"a,b\n\xff\xfe,1\n")
    with pytest.raises(ValueError, match=r"cannot be read as CSV: not UTF-8 text"):
        read_csv_strict(p, "data file")
    with pytest.raises(ValueError, match=r"data file '.*nope\.csv' does not exist"):
        read_csv_strict(tmp_path / "nope.csv", "data file")
    with pytest.raises(ValueError, match=r"is a folder, not a CSV file"):
        read_csv_strict(tmp_path, "data file")
    with pytest.raises(TableError, match=r"line 3"):
        p.write_text("a,b\n1,2\n5,6,7\n")
        read_csv_strict(p, "x", TableError)


def _table6_with(tmp_path: Path, extra: str) -> Path:
    src = (PAPER_DATA / "paper_table6_bbd_runs.csv").read_text().splitlines()
    out = tmp_path / "t6.csv"
    out.write_text("\n".join(line + extra for line in src) + "\n")
    return out


def test_rsm_fit_reads_a_spreadsheet_export_and_refuses_extra_fields(tmp_path: Path, capsys):
    ref = rsm.ResponseSurfaceModel.from_csv(PAPER_DATA / "paper_table6_bbd_runs.csv", ["EA", "EB", "EC", "ED"],
                                            "te_arcmin").fit(warn=False)
    exported = _table6_with(tmp_path, ",")
    res = rsm.ResponseSurfaceModel.from_csv(exported, ["EA", "EB", "EC", "ED"], "te_arcmin").fit(warn=False)
    assert res.ssr == pytest.approx(ref.ssr, rel=1e-12) and res.params.equals(ref.params)
    lines = (PAPER_DATA / "paper_table6_bbd_runs.csv").read_text().splitlines()
    bad = tmp_path / "bad.csv"
    bad.write_text("\n".join(lines[:5] + [lines[5] + ",9"] + lines[6:]) + "\n")
    assert rsm_main(["fit", str(bad), "--factors", "EA", "EB", "EC", "ED", "--response", "te_arcmin"]) == 2
    err = capsys.readouterr().err
    assert "bad.csv': line 6 has" in err and "allowed: one field per column of the header" in err
    with pytest.raises(ValueError, match=r"levels file '.*bad\.csv': line 6 has"):
        rsm.Levels.from_csv(bad)


def test_levels_and_dataset_readers_refuse_extra_fields(tmp_path: Path):
    lev = tmp_path / "levels.csv"
    src = (PAPER_DATA / "paper_table5_levels.csv").read_text().splitlines()
    lev.write_text("\n".join(src[:2] + [src[2] + ",1"] + src[3:]) + "\n")
    with pytest.raises(TableError, match=r"--levels file '.*levels\.csv': line 3 has") as info:
        load_factors(str(lev), None)
    assert info.value.field == "--levels"
    ds = tmp_path / "ds"
    ds.mkdir()
    (ds / "runs.csv").write_text("run,load_Nm,direction\na,10,1,7\n")
    (ds / "samples.csv").write_text("run,input_deg,output_deg\na,0,0\n")
    with pytest.raises(DatasetError, match=r"runs file '.*runs\.csv': line 2 has 4 fields but the header has 3"):
        read_dataset(ds)
