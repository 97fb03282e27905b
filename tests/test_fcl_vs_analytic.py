"""The fcl solver against the exact analytic solver on the same cases (issue 3 acceptance).

TE curves must agree within 0.5 arcsec RMS and 1 arcsec at any step, for the nominal case and for
each single Table 4 error at its paper value (default load 20 N m, elastic law).
"""
from __future__ import annotations

import numpy as np
import pytest

from rvcad.errors import ERROR_TYPES, Case
from rvcad.geometry import ReducerGeometry
from rvdyn.te import run_te

STEPS = 96
CASES = {"nominal": {}} | {k: {k: et.paper_value} for k, et in ERROR_TYPES.items()}


@pytest.mark.slow
@pytest.mark.parametrize("name", list(CASES))
def test_fcl_matches_analytic(name: str) -> None:
    case = Case.from_dict({"name": name, "errors": CASES[name]})
    g = ReducerGeometry(case)
    a = run_te(case, "analytic", STEPS, geom=g)
    f = run_te(case, "fcl", STEPS, geom=g)
    d = f.table["te_arcsec"].to_numpy() - a.table["te_arcsec"].to_numpy()
    assert np.sqrt(np.mean(d ** 2)) < 0.5
    assert np.abs(d).max() < 1.0
    assert f.stats["ratio"] == pytest.approx(a.stats["ratio"], rel=1e-6)


def test_fcl_ideal_rigid_zero_te() -> None:
    r = run_te(Case.from_dict({}), "fcl", 48, load_Nm=0.0)
    assert np.abs(r.table["te_arcsec"]).max() < 0.01
    assert r.stats["ratio"] == pytest.approx(121.0, rel=1e-6)
