"""rvcad.reducer: the case forms it accepts, bad input, lazy parts and their placement (cheap parts
only; the volumes of every part against the exported STEP are in test_rvcad_export)."""
from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

import rvcad
from rvcad.errors import Case
from rvcad.validation import CaseError, OptionError

# on the worker of test_rvcad_export: both import build123d (about 6.5 CPU-s per process)
pytestmark = pytest.mark.xdist_group("build123d")


def test_case_forms_and_attributes(tmp_path: Path) -> None:
    d = {"name": "j", "errors": {"pin_radius": 5}}
    path = tmp_path / "j.json"
    path.write_text(json.dumps(d))
    a, b, c = rvcad.reducer(d, check=False), rvcad.reducer(path, check=False), rvcad.reducer(Case.from_dict(d))
    assert a.case.key() == b.case.key() == c.case.key() != rvcad.reducer({}, check=False).case.key()
    assert c.ratio == pytest.approx(121.0) and c.design.z_pins == 40 and c.check["pin_penetration_mm"] > 0
    assert c.layout.disc1[0] - c.layout.disc0[1] == pytest.approx(c.design.disc_gap_mm)
    assert len(c.parts) == 50 and list(c.parts)[:3] == ["sun", "planet0", "planet1"]
    assert "0 built" in repr(c.parts)


def test_bad_input_names_the_field() -> None:
    with pytest.raises(CaseError, match="case 5 is of type int"):
        rvcad.reducer(5)
    with pytest.raises(OptionError, match="tolerance_mm 1.0 is out of range"):
        rvcad.reducer({}, tolerance_mm=1.0, check=False)
    r = rvcad.reducer({}, check=False)
    with pytest.raises(KeyError, match="no part 'gearbox'"):
        r.parts["gearbox"]


def test_parts_are_placed_labelled_build123d_solids() -> None:
    """A pin sits at its centre (world frame). A crankshaft's two cams are equal and 180 deg apart,
    so its centroid lies on its axis: placed at 40 deg input, on the placed axis to 1e-9 mm."""
    import build123d as bd

    r = rvcad.reducer({}, theta_in_deg=40.0, check=False)
    pin = r.parts["pin07"]
    assert isinstance(pin, bd.Solid) and pin.label == "pin07"
    c = r.geometry.pin_centers[7]
    assert abs(pin.center().X - c[0]) < 1e-9 and abs(pin.center().Y - c[1]) < 1e-9
    assert pin.volume == pytest.approx(math.pi * 3.0 ** 2 * r.assembly["pin07"].width, rel=1e-12)
    crank = r.parts["crank1"]
    x, y, _ = r.placements["crank1"]
    assert abs(crank.center().X - x) < 1e-9 and abs(crank.center().Y - y) < 1e-9
    assert r.parts["crank1"] is crank  # cached
    own = r.solid("crank1", placed=False)
    assert abs(own.center().X) < 1e-9 and own.volume == pytest.approx(crank.volume, rel=1e-12)
    assert (pin + crank).volume == pytest.approx(pin.volume + crank.volume, rel=1e-9)  # apart: no overlap
