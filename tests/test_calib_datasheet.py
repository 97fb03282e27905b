"""rvcalib.datasheet: the reducer's datasheet as declared and as calibrated (rvdyn stiffness), the rated torque
from the user, and the rigidity's interval by the series law."""
from __future__ import annotations

from types import SimpleNamespace

import pytest

from rig_records import R81, cos_orders, write_dataset
from rvrig.dataset import read_dataset
from rvcalib.datasheet import reducer_datasheet
from rvcalib.result import NamedEffect

C = 0.2                      # arcsec/(N m): the compliance the calibration found
CI = (0.18, 0.22)


@pytest.fixture(scope="module")
def ds81(tmp_path_factory):
    runs = [{"run": f"{d:+d}", "load_Nm": 100.0, "direction": d, "te": cos_orders({1: (2.0, 0.0)})} for d in (1, -1)]
    return read_dataset(write_dataset(tmp_path_factory.mktemp("d") / "ds", runs, per_rev=60))


def _result(rated=None):
    comp = NamedEffect("torsional_compliance_arcsec_per_Nm", "torsional_compliance_arcsec_per_Nm", "model", {},
                       "arcsec/(N m)", C, None, [C], [[1e-4]], list(CI), 1.0, "")
    case = {"design": dict(R81), "model": {"torsional_compliance_arcsec_per_Nm": C, "friction_torque_Nm": 40.0}}
    return SimpleNamespace(effects=[comp], calibrated_case=case, settings={"rated_Nm": rated, "contact": None})


@pytest.mark.slow
def test_the_calibrated_reducer_is_softer_by_the_compliance_found(ds81):
    """b/a of the calibrated reducer against the declared: the series law 1/k = 1/k0 + C/60 (arcmin/(N m)), to
    the friction's share of the sweep (0.35 % here; about 1 %, rvcalib.datasheet); the friction torque is not
    swept (else the sweep would not be the maker's); the interval is the series law at the compliance's ends."""
    sheet = reducer_datasheet(_result(), ds81, rated_Nm=1568.0)
    assert sheet["computed"] and sheet["rated_torque_Nm"] == 1568.0 and sheet["rated_source"] == "given (--rated-Nm)"
    k0 = sheet["model"]["torsional_rigidity_Nm_per_arcmin"]
    k1 = sheet["calibrated"]["torsional_rigidity_Nm_per_arcmin"]
    assert 1.0 / k1 == pytest.approx(1.0 / k0 + C / 60.0, rel=0.01)
    lo, hi = sheet["rigidity_ci"]
    assert 1.0 / lo == pytest.approx(1.0 / k1 + (CI[1] - C) / 60.0, rel=1e-12)
    assert 1.0 / hi == pytest.approx(1.0 / k1 + (CI[0] - C) / 60.0, rel=1e-12)
    assert sheet["calibrated"]["rated_torque_Nm"] == 1568.0


def test_the_settings_rated_torque_is_used_when_the_call_gives_none(ds81, monkeypatch):
    import rvcalib.datasheet as mod

    seen = []
    monkeypatch.setattr(mod, "calibrated_datasheet", lambda *a: seen.append(a[-1]) or {"note": ""})
    assert reducer_datasheet(_result(1568.0), ds81)["rated_source"] == "given (--rated-Nm)"
    assert seen == [1568.0]


def test_no_datasheet_without_the_rated_torque_of_a_design_not_the_default(ds81):
    sheet = reducer_datasheet(_result(), ds81)
    assert sheet == {"computed": False, "rated_torque_Nm": None, "rated_source": sheet["rated_source"]}
    assert sheet["rated_source"].startswith("the rated torque is needed: this reducer (ratio 81, 40 pins)")
