"""A preloaded case in the maker's sweep (docs/physics.md, section 9): errors that the parts can only take as
an interference leave no play, and the preload's normal forces keep the Coulomb friction band open at zero
torque, so the hysteresis loss is the friction's alone."""
from __future__ import annotations

import pytest

from rvcad.errors import Case
from rvdyn.stiffness import hysteresis

PRELOAD = {"disc_hole_eccentricity": 10.0}      # um: hole 0 of disc 0 outward, fought by the two cams


@pytest.fixture(scope="module")
def sweeps():
    out = {}
    for name, mu in (("friction", None), ("frictionless", 0.0)):
        model = {} if mu is None else {"pin_friction_coefficient": mu, "bearing_friction_coefficient": mu}
        out[name] = hysteresis(Case.from_dict({"errors": PRELOAD, "model": model}), points=9)
    return out


def test_preload_keeps_the_friction_band_open_at_zero_torque(sweeps) -> None:
    f = sweeps["friction"].figures
    assert f["preloaded"] is True
    assert f["backlash_arcmin"] == 0.0
    el = sweeps["friction"].elastic
    zero = el[el["torque_Nm"].abs() <= 1e-3]
    assert len(zero) == 2 and (zero["friction_torque_Nm"] > 0.0).all()      # normal forces at zero torque
    assert f["hysteresis_loss_arcmin"] > 0.01
    # the band is the friction's: without friction it closes (the elastic curve through zero torque)
    g = sweeps["frictionless"].figures
    assert g["preloaded"] is True
    assert g["hysteresis_loss_arcmin"] == pytest.approx(0.0, abs=1e-9)
