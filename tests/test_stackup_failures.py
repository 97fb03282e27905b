"""rv-stackup when solves fail (issue 14 item 8): a report that says what failed, exit 1 only if nothing useful."""
from __future__ import annotations

import pandas as pd
import pytest

import rsm
from rvstudy import cli

SMALL = ["--solver", "analytic", "--steps", "24", "--workers", "1", "--stages", "doe", "--no-progress",
         "--no-figures"]


def _levels(tmp_path, ea_deg: float):
    p = tmp_path / "levels.csv"
    pd.DataFrame({"factor": ["EA", "EB", "EC", "ED"], "low": [-ea_deg, -14, -7, -14], "center": [0, 0, 0, 0],
                  "high": [ea_deg, 14, 7, 14], "unit": ["deg", "um", "um", "um"],
                  "error": ["pin_pitch", "pin_circle_diameter", "pin_radius", "disc_hole_eccentricity"]}).to_csv(p, index=False)
    return p


def test_every_design_run_failing_gives_a_report_and_exit_1(tmp_path, capsys):
    """EA = +-1 deg moves pin 0 by 1.1 mm into the disc: every run with EA != 0 fails, EA is constant in the
    rest, so no surface can be fitted: the report names the failures and the command exits 1 (not a traceback)."""
    out = tmp_path / "run"
    rc = cli.main(["--out", str(out), "--levels", str(_levels(tmp_path, 1.0)), *SMALL])
    err = capsys.readouterr().err
    assert rc == 1 and "no stage gave a result" in err and "Traceback" not in err
    rep = (out / "report.md").read_text()
    assert "InterferenceError" in rep and "no fit" in rep


def test_reduction_failure_keeps_the_fit_and_reports(tmp_path, capsys, monkeypatch):
    """When the reduced models cannot be formed (simulated: rsm.compare_reductions raises ValueError, as it
    does for a run set that leaves no significant term to refit), the full fit, its ANOVA and the rest of the
    report stand, section 6 says why Eq. 9 is missing, and the run succeeds."""
    def boom(*a, **k):
        raise ValueError("no term is significant")

    monkeypatch.setattr(rsm, "compare_reductions", boom)
    out = tmp_path / "run"
    argv = [a if a != "doe" else "doe,validation" for a in SMALL]
    assert cli.main(["--out", str(out), *argv, "--validation-cases", "2"]) == 0
    rep = (out / "report.md").read_text()
    assert "No reduced models: reduced models (Eq. 9) could not be formed" in rep
    assert "no term is significant" in rep and "Table 7" in rep
    assert (out / "tables" / "validation_metrics.csv").is_file()
