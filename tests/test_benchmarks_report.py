"""benchmarks/results_log.py appends measured figures to the results table; benchmarks/report.py prints the
newest value of each (benchmark, figure)."""
from __future__ import annotations

import csv
import importlib
import sys
from pathlib import Path

import pytest

BENCH = Path(__file__).resolve().parents[1] / "benchmarks"


@pytest.fixture(scope="module")
def bench():
    sys.path.insert(0, str(BENCH))
    try:
        yield importlib.import_module("results_log"), importlib.import_module("report")
    finally:
        sys.path.remove(str(BENCH))


def _row(bench_name, figure, value, date):
    return {"benchmark": bench_name, "figure": figure, "value": repr(value), "unit": "s", "commit": "abc1234",
            "date": date, "machine": "cpu, 2 cores"}


def test_record_appends_rows_with_header_commit_date_and_machine(bench, tmp_path):
    log, _ = bench
    path = tmp_path / "results.csv"
    log.record("bench_x", [("a", 1.5, "s")], path=path)
    log.record("bench_x", [("a", 1.25, "s"), ("b", 3, "MB")], path=path)
    with open(path, newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert [(r["figure"], float(r["value"]), r["unit"]) for r in rows] == [("a", 1.5, "s"), ("a", 1.25, "s"), ("b", 3.0, "MB")]
    assert path.read_text().count("benchmark,figure,value") == 1  # one header
    assert all(r["date"].endswith("+00:00") and "cores" in r["machine"] and r["commit"] for r in rows)
    with pytest.raises(ValueError, match="every figure name must be non-empty"):
        log.record("bench_x", [("", 1.0, "s")], path=path)


def test_slug_makes_figure_names(bench):
    log, _ = bench
    assert log.slug("analytic physical pin_pitch 0.01 deg 720 steps CPU") == "analytic_physical_pin_pitch_0.01_deg_720_steps_cpu"
    with pytest.raises(ValueError, match="no letter or digit"):
        log.slug(" : ")


def test_newest_value_of_each_figure_by_date(bench):
    _, rep = bench
    rows = [_row("b1", "t", 3.0, "2030-01-02T00:00:00+00:00"), _row("b1", "t", 2.0, "2030-01-01T00:00:00+00:00"),
            _row("b0", "t", 9.0, "2030-01-01T00:00:00+00:00"), _row("b0", "t", 8.0, "2030-01-01T00:00:00+00:00")]
    got = rep.newest(rows)
    assert [(r["benchmark"], float(r["value"])) for r in got] == [("b0", 8.0), ("b1", 3.0)]  # a tie: later in the file


def test_report_prints_the_table_and_refuses_a_bad_file(bench, tmp_path, capsys):
    log, rep = bench
    path = tmp_path / "results.csv"
    log.record("bench_te", [("analytic_cpu", 0.41, "s")], path=path)
    log.record("bench_te", [("analytic_cpu", 0.39, "s")], path=path)
    log.record("bench_rsm", [("fit", 2.5, "ms")], path=path)
    assert rep.main(["--csv", str(path)]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0].split()[:4] == ["benchmark", "figure", "value", "unit"] and len(out) == 3
    assert out[1].split()[:4] == ["bench_rsm", "fit", "2.5", "ms"] and out[2].split()[:3] == ["bench_te", "analytic_cpu", "0.39"]
    assert rep.main(["--csv", str(path), "--all", "--benchmark", "bench_te"]) == 0
    assert len(capsys.readouterr().out.splitlines()) == 3
    bad = tmp_path / "bad.csv"
    bad.write_text("name,value\nx,1\n")
    assert rep.main(["--csv", str(bad)]) == 2
    assert "header ['name', 'value'] is not" in capsys.readouterr().err
    assert rep.main(["--csv", str(tmp_path / "none.csv")]) == 2
