"""Reducers other than the paper's (issue 15): a ratio-81 RV (Z1 18, Z2 36, 40 pins, 39 lobes) and a
30-pin / 29-lobe reducer (ratio 91). The same closed forms as for the paper's design
(docs/physics.md): ideal parts give zero TE and the exact ratio; a common pin-radius reduction dr is a
clearance whose TE is -dr over the largest pin lever, whose longest lever is e * i * Z1/Z2; the exported
disc lies on the exact profile within the tolerance. The study on these designs is in
tests/test_stackup_reducer.py, the loop in tests/test_calib_design.py."""
from __future__ import annotations

import numpy as np
import pytest

from rvcad.assembly import Assembly
from rvcad.errors import Case
from rvcad.export import export_case
from rvcad.geometry import ReducerGeometry
from rvdyn.contacts import ContactLaw
from rvdyn.solver import ARCSEC_PER_RAD
from rvdyn.te import run_te
from closed_forms import pin_levers
from test_rvcad_helpers import stl_chords, stl_vertices

DESIGNS = {"ratio81": ({"z_sun": 18, "z_planet": 36}, 81.0),
           "pins30": ({"z_pins": 30, "z_disc": 29}, 91.0)}
STEPS = 96


@pytest.mark.parametrize("name", DESIGNS)
def test_ideal_parts_zero_te_and_exact_ratio(name: str) -> None:
    design, ratio = DESIGNS[name]
    case = Case.from_dict({"design": design})
    assert case.design.ratio == pytest.approx(ratio, rel=1e-12)
    for law, load in ((ContactLaw(), 0.0), (ContactLaw(rigid=True), 20.0)):
        r = run_te(case, "analytic", STEPS, load_Nm=load, law=law)
        assert np.abs(r.table["te_arcsec"]).max() < 0.01
        assert r.stats["ratio"] == pytest.approx(ratio, rel=1e-6)


@pytest.mark.parametrize("name", DESIGNS)
def test_pin_radius_clearance_closed_form(name: str) -> None:
    design, _ = DESIGNS[name]
    dr_um = 5.0
    case = Case.from_dict({"design": design, "errors": {"pin_radius": -dr_um}})
    g = ReducerGeometry(case)
    r = run_te(case, "analytic", STEPS, load_Nm=0.0, geom=g)
    lam_max = pin_levers(g, np.radians(r.table["input_deg"].to_numpy())).max(axis=(1, 2))
    expect = -dr_um * 1e-3 / lam_max * ARCSEC_PER_RAD
    # The paper's design agrees to 0.2 % (tests/test_rvdyn_physics.py); the 30-pin design to 0.39 %,
    # the same at dr = 5, 2.5 and 1.25 um (so not a second-order term of dr): an open 0.4 % gap of the
    # closed form's lever (taken at the ideal pose) on that design, bounded here, not explained.
    assert r.table["te_arcsec"].to_numpy() == pytest.approx(expect, rel=5e-3)
    d = g.design
    bound = d.eccentricity_mm * d.ratio * d.z_sun / d.z_planet  # |n . u'| <= 1
    assert lam_max.max() <= bound * (1 + 1e-9)
    assert lam_max.max() == pytest.approx(bound, rel=5e-3)  # reached where a pin normal lines up with u'


@pytest.mark.parametrize("name", DESIGNS)
def test_exported_disc_within_tolerance(name: str, tmp_path) -> None:
    design, _ = DESIGNS[name]
    case = Case.from_dict({"design": design})
    tol_mm = 1e-4
    export_case(case, tmp_path, formats=["stl"], tolerance_um=0.1, parts=["disc0"])
    part = Assembly(case)["disc0"]
    d = case.design
    outer_r = d.pin_circle_radius_mm - d.pin_radius_mm - 2.0 * d.eccentricity_mm  # inside every root: the profile only
    v = stl_vertices(tmp_path / "disc0.stl")
    outer = v[np.linalg.norm(v[:, :2], axis=1) > outer_r]
    assert len(outer) > 1000
    assert np.abs(part.boundary_distance(outer[:, :2])).max() < tol_mm
    ch = stl_chords(tmp_path / "disc0.stl")
    mid = 0.5 * (ch[:, 0] + ch[:, 1])
    mid = mid[np.linalg.norm(mid[:, :2], axis=1) > outer_r]
    assert np.abs(part.boundary_distance(mid[:, :2])).max() < tol_mm
