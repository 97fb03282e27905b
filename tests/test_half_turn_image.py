"""The half-turn image of a two-crank reducer's errors (every crank-, disc-, hole- and pin-indexed error moved to
the crank, disc, hole and pin half a turn away, its size kept; every direction turned by 180 deg): in the plane
(the impact law, or rigid supports) it is the same reducer turned half a turn, so its TE is the same; with the
physical law's elastic supports the two discs sit at different places along the bending cranks, and the image
differs. This is why the loop reports such effects as groups (rvcalib.twins) on planar models."""
from __future__ import annotations

import numpy as np
import pytest

import rvdyn
from rvcad.tolerances import TOL
from rvdyn.solver import ARCSEC_PER_RAD

#: Two solves, each converged to the solver's angle tolerance, agree within this, arcsec.
RESOLUTION = 2.0 * TOL.solver_angle_rad * ARCSEC_PER_RAD

ERRORS = {"pin_pitch": {"value": 0.008, "pin": 7}, "cam_eccentricity": {"value": 3.5, "crank": 1, "disc": 0},
          "planet_eccentricity": {"value": 2.0, "crank": 0, "angle_deg": 106.0},
          "disc_hole_eccentricity": {"value": 3.0, "disc": 0, "hole": 1},
          "pin_circle_offset": {"value": 5.5, "angle_deg": 11.0},
          "sun_eccentricity": {"value": 2.6, "angle_deg": 129.0}}
IMAGE = {"pin_pitch": {"value": 0.008, "pin": 27}, "cam_eccentricity": {"value": 3.5, "crank": 0, "disc": 1},
         "planet_eccentricity": {"value": 2.0, "crank": 1, "angle_deg": 286.0},
         "disc_hole_eccentricity": {"value": 3.0, "disc": 1, "hole": 0},
         "pin_circle_offset": {"value": 5.5, "angle_deg": 191.0},
         "sun_eccentricity": {"value": 2.6, "angle_deg": 309.0}}


def _te(errors: dict, model: dict) -> np.ndarray:
    return rvdyn.solve({"errors": errors, "model": model}, solver="analytic", steps=45).table["te_arcsec"].to_numpy()


@pytest.mark.parametrize("model", [{"contact": "impact"}, {"supports": "rigid"}], ids=["impact", "rigid_supports"])
def test_the_half_turn_image_has_the_same_te_in_the_plane(model):
    te, image, nominal = _te(ERRORS, model), _te(IMAGE, model), _te({}, model)
    assert np.sqrt(np.mean((te - nominal) ** 2)) > 1.0                   # the errors show (arcsec)
    assert np.abs(te - image).max() < RESOLUTION


def test_elastic_supports_tell_the_image_from_the_reducer():
    te, image = _te(ERRORS, {}), _te(IMAGE, {})
    assert np.abs(te - image).max() > 1.0
