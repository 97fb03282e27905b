"""The ``rsm`` command line: fit (human / JSON), design, errors, ``python -m rsm``."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from rsm.cli import main
from rvpaper import DATA_DIR as PAPER_DATA

REPO = Path(__file__).resolve().parents[1]
DATA = PAPER_DATA
RUNS = str(DATA / "paper_table6_bbd_runs.csv")
LEVELS = str(DATA / "paper_table5_levels.csv")
FIT = ["fit", RUNS, "--factors", "EA", "EB", "EC", "ED", "--response", "te_arcmin"]


def _json(capsys, argv: list[str]) -> dict:
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert out.count("\n") == 1  # exactly one JSON object on one line
    return json.loads(out)


def test_fit_json_contract(capsys):
    d = _json(capsys, FIT + ["--levels", LEVELS, "--json"])
    paper = pd.read_csv(DATA / "paper_table7_anova.csv", dtype=str)
    assert list(d["anova"]) == list(paper["source"])
    for row in d["anova"].values():
        assert set(row) == {"sum_sq", "df", "mean_sq", "F", "p"}
    assert d["anova"]["Residual"]["F"] is None and d["anova"]["Cor total"]["mean_sq"] is None
    assert d["anova"]["Residual"]["df"] == 12
    assert round(d["anova"]["EA^2"]["F"], 2) == 446.61
    assert round(d["anova"]["Lack of fit"]["p"], 4) == 0.0546
    assert round(d["r2"], 4) == 0.9779 and round(d["r2_adj"], 4) == 0.9521
    assert 0 < d["r2_pred"] < d["r2_adj"]
    assert d["coefficients"]["actual"]["EA^2"] == pytest.approx(404.36592, rel=1e-3)
    assert d["coefficients"]["coded"]["EA^2"] == pytest.approx(404.36592 * 0.06**2, rel=1e-3)
    assert "reduction" not in d


def test_fit_json_without_levels_has_null_actual(capsys):
    d = _json(capsys, FIT + ["--json", "--model", "linear"])
    assert d["coefficients"]["actual"] is None
    assert d["terms"] == ["Intercept", "EA", "EB", "EC", "ED"]
    assert d["anova"]["Residual"]["df"] == 22


def test_fit_reduce_modes_json(capsys):
    p = _json(capsys, FIT + ["--levels", LEVELS, "--reduce", "paper", "--json"])
    assert p["reduction"]["terms"] == ["Intercept", "EA", "EB:EC", "EA^2", "EB^2", "EC^2", "ED^2"]
    assert p["reduction"]["refitted"] is False
    assert p["reduction"]["coefficients"]["actual"]["EB:EC"] == pytest.approx(2.258e-3, rel=1e-3)
    b = _json(capsys, FIT + ["--levels", LEVELS, "--reduce", "backward", "--json"])
    assert b["reduction"]["method"] == "backward" and b["reduction"]["removed"]
    assert b["comparison"]["backward"]["sse"] <= b["comparison"]["paper"]["sse"]
    assert b["comparison"]["paper_refit"]["sse"] <= b["comparison"]["paper"]["sse"] + 1e-12
    assert b["comparison"]["paper"]["sse"] == pytest.approx(p["reduction"]["sse"])


def test_fit_human_summary(capsys):
    assert main(FIT + ["--levels", LEVELS, "--reduce", "paper"]) == 0
    out = capsys.readouterr().out
    for text in ["Lack of fit", "Pure error", "Cor total", "R2 = 0.9779", "R2adj = 0.9521",
                 "< 0.0001", "Paper-mode", "cost of not refitting", "EA [deg]"]:
        assert text in out, text


def test_fit_plots_option(capsys, tmp_path):
    two = str(tmp_path / "two.csv")
    assert main(["design", "ccd", "--factors", "2", "--names", "EA", "EB", "--out", two]) == 0
    d = pd.read_csv(tmp_path / "two.csv")
    noise = np.random.default_rng(1).normal(scale=0.05, size=len(d))
    d["te_arcmin"] = 0.2 + d["EA"] ** 2 + 0.1 * d["EB"] + noise
    d.to_csv(tmp_path / "two.csv", index=False)
    capsys.readouterr()
    figs = tmp_path / "figs"
    out = _json(capsys, ["fit", str(tmp_path / "two.csv"), "--factors", "EA", "EB", "--response",
                         "te_arcmin", "--plots", str(figs), "--json"])
    assert sorted(Path(p).name for p in out["plots"]) == [
        "predicted_vs_observed.png", "residuals.png", "surface_EA_EB.png"]
    assert all(Path(p).stat().st_size > 10_000 for p in out["plots"])


def test_fit_user_terms_and_validation(capsys, tmp_path):
    hold = pd.read_csv(RUNS).iloc[:6]
    hold.to_csv(tmp_path / "hold.csv", index=False)
    d = _json(capsys, FIT + ["--terms", "linear", "EA^2", "--validate", str(tmp_path / "hold.csv"), "--json"])
    assert d["terms"] == ["Intercept", "EA", "EB", "EC", "ED", "EA^2"]
    assert d["validation"]["n"] == 6 and 0 <= d["validation"]["pi_coverage"] <= 1


@pytest.mark.parametrize("kind,k,center,n", [("bbd", 4, 3, 27), ("bbd", 7, 2, 58), ("ccd", 3, 4, 18),
                                              ("ff3", 2, 1, 9)])
def test_design_command(capsys, tmp_path, kind, k, center, n):
    out = tmp_path / "d.csv"
    assert main(["design", kind, "--factors", str(k), "--center", str(center), "--out", str(out)]) == 0
    assert f"{n} runs" in capsys.readouterr().out
    d = pd.read_csv(out)
    assert len(d) == n and [f"x{i + 1}" for i in range(k)] == list(d.columns[3:])


def test_design_command_levels_seed_and_json(capsys):
    a = _json(capsys, ["design", "bbd", "--levels", LEVELS, "--randomize", "--seed", "5", "--json"])
    b = _json(capsys, ["design", "bbd", "--levels", LEVELS, "--randomize", "--seed", "5", "--json"])
    assert a == b and a["n_runs"] == 27 and a["factors"] == ["EA", "EB", "EC", "ED"]
    runs = pd.DataFrame(a["runs"])
    assert set(runs["EA_actual"].round(6)) == {-0.06, 0.0, 0.06}
    assert runs["std_order"].tolist() != list(range(1, 28))
    c = _json(capsys, ["design", "ccd", "--factors", "2", "--alpha", "face", "--json"])
    assert c["alpha"] == 1.0
    assert main(["design", "bbd", "--factors", "3"]) == 0
    printed = capsys.readouterr().out
    assert printed.startswith("run,std_order,point_type,x1,x2,x3") and printed.count("\n") == 16


def test_cli_errors_exit_2_with_message(capsys, tmp_path):
    assert main(FIT[:2] + ["--factors", "EA", "EB", "EZ", "--response", "te_arcmin"]) == 2
    assert "factor column 'EZ' not found" in capsys.readouterr().err
    df = pd.read_csv(RUNS)
    df["EB"] = 0.0
    df.to_csv(tmp_path / "const.csv", index=False)
    assert main(["fit", str(tmp_path / "const.csv"), "--factors", "EA", "EB", "--response", "te_arcmin"]) == 2
    assert "factor column 'EB' is constant (value 0.0)" in capsys.readouterr().err
    assert main(["fit", str(tmp_path / "nope.csv"), "--factors", "EA", "--response", "y"]) == 2
    assert "does not exist" in capsys.readouterr().err
    assert main(["design", "bbd", "--factors", "9"]) == 2
    assert "3 to 7 factors" in capsys.readouterr().err
    assert main(["fit"]) == 2  # argparse usage error
    assert main(["--help"]) == 0


def test_python_dash_m_rsm(tmp_path):
    r = subprocess.run([sys.executable, "-m", "rsm", *FIT, "--json"], cwd=REPO, capture_output=True,
                       text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    d = json.loads(r.stdout)
    assert np.isclose(d["r2"], 0.97790, atol=5e-5)
