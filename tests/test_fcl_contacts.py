"""The fcl contact provider against the exact (analytic) geometry and the exported polygons."""
from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest
import shapely
from shapely.geometry import Polygon

from rvcad.errors import Case
from rvcad.geometry import ReducerGeometry
from rvdyn.fcl_contacts import FclContacts

UM = 1e-3  # mm
DIST_TOL = 0.05 * UM  # disc distance vs exact envelope (default sagitta 0.05 um)
NORMAL_TOL = 1e-4  # rad (brief: 1e-3; the solver's Jacobian wants ~1e-4, measured ~1.2e-5)
STAGE1_TOL = 0.1 * UM


def _angle(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Unsigned angle between unit vectors (rad)."""
    return np.abs(np.arctan2(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0], np.einsum("ij,ij->i", a, b)))


@pytest.fixture(scope="module")
def nominal() -> tuple[ReducerGeometry, FclContacts]:
    g = ReducerGeometry()
    return g, FclContacts(g)


def _points_near_boundary(prof, rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Points b(t) + d n(t): roots, flanks and tips; d from -50 um (inside) to 3.05 mm (pin centres).

    Outside the material d stays below 3.05 mm: the boundary's smallest concave radius of
    curvature is 3.071 mm (at the roots), and beyond it a point has several local feet, where
    the analytic foot point (Newton from t0) need not be the nearest.
    """
    zc = prof.z_lobes
    pitch = 2 * math.pi / zc
    lobe = rng.integers(0, zc, n)
    rel = np.concatenate([
        rng.normal(0.0, 0.004, n // 4),  # roots (the pins sit here)
        rng.uniform(-0.5, 0.5, n // 4) * pitch,  # anywhere
        0.5 * pitch + rng.normal(0.0, 0.01, n // 4),  # tips
        rng.uniform(0.05, 0.45, n - 3 * (n // 4)) * pitch * rng.choice([-1, 1], n - 3 * (n // 4)),  # flanks
    ])
    t = prof.root_t() + lobe * pitch + rel
    d = np.concatenate([
        rng.uniform(-0.05, 0.05, n // 3),  # at the boundary, down to 50 um penetration
        rng.uniform(2.95, 3.05, n // 3),  # pin centres (rp = 3 mm) +-50 um
        rng.uniform(-0.05, 3.05, n - 2 * (n // 3)),
    ])
    rng.shuffle(d)
    p = prof.boundary(t) + d[:, None] * prof.normal(t)
    t0 = t + rng.uniform(-0.2, 0.2, n) * pitch  # t0 is only a hint of the tooth space
    return p, t0, d


@pytest.mark.parametrize("k", [0, 1])
def test_disc_distance_matches_exact_envelope(nominal, k: int) -> None:
    g, fc = nominal
    prof = g.profiles[k]
    rng = np.random.default_rng(10 + k)
    p, t0, d = _points_near_boundary(prof, rng, 6000)
    sd, n = fc.disc_distance(k, p, t0)
    ref, _, nref = prof.boundary_distance(p, t0)
    assert sd.shape == (len(p),) and n.shape == (len(p), 2)
    assert np.abs(sd - ref).max() < DIST_TOL
    assert np.all(np.sign(sd[np.abs(ref) > 1e-4]) == np.sign(ref[np.abs(ref) > 1e-4]))
    assert (sd < -0.045).any()  # penetration to ~ -50 um really tested
    assert np.abs(np.linalg.norm(n, axis=1) - 1.0).max() < 1e-12
    assert _angle(n, nref).max() < NORMAL_TOL


def test_disc_distance_is_the_distance_to_the_exported_polygon(nominal) -> None:
    """Independent check: shapely's distance to the closed outline ``boundary_points(sagitta)``."""
    g, fc = nominal
    prof = g.profiles[1]
    rng = np.random.default_rng(5)
    p, t0, _ = _points_near_boundary(prof, rng, 3000)
    poly = Polygon(prof.boundary_points(fc.sagitta_mm))
    inside = shapely.contains_xy(poly, p[:, 0], p[:, 1])
    ref = shapely.distance(shapely.points(p), poly.exterior) * np.where(inside, -1.0, 1.0)
    sd, _ = fc.disc_distance(1, p, t0)
    assert np.abs(sd - ref).max() < 1e-9


def test_window_is_built_from_the_exported_samples(nominal) -> None:
    """Every window vertex, turned by whole lobe pitches, is a vertex of the exported outline."""
    g, fc = nominal
    for k, prof in enumerate(g.profiles):
        w = fc.windows[k]
        exported = prof.boundary_points(fc.sagitta_mm)
        n_per = len(exported) // prof.z_lobes
        for m in (0, 7, 38):
            a = m * w.pitch
            R = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
            turned = w.b[n_per:2 * n_per] @ R.T  # lobe 0 of the window -> lobe m
            assert np.abs(turned - exported[m * n_per:(m + 1) * n_per]).max() < 1e-11
        assert w.n_triangles == 2 * n_per  # one triangle per chord, two lobe pitches


def test_disc_distance_rejects_a_wrong_tooth_space(nominal) -> None:
    g, fc = nominal
    prof = g.profiles[0]
    t = np.array([prof.root_t(3)])
    p = prof.boundary(t) + 3.0 * prof.normal(t)
    with pytest.raises(ValueError, match="tooth space"):
        fc.disc_distance(0, p, t + 2 * math.pi / prof.z_lobes)
    with pytest.raises(ValueError, match="points but t0"):
        fc.disc_distance(0, p, np.array([0.0, 1.0]))
    d, n = fc.disc_distance(0, np.empty((0, 2)), np.empty(0))
    assert d.shape == (0,) and n.shape == (0, 2)


PIN_CASES = [
    {},
    {"pin_pitch": 0.06, "pin_circle_diameter": -14, "pin_radius": 7,
     "disc_hole_eccentricity": {"value": 14, "disc": 0, "hole": 0}},
    {"cam_phase": 10, "cam_eccentricity": 10, "carrier_hole_eccentricity": 10, "disc_phase": 0.1,
     "pin_circle_offset": {"value": 10, "angle_deg": 30}},
    {"disc_phase": {"value": -0.1, "disc": 1}, "pin_pitch": [0.01 * ((i * 7) % 5 - 2) for i in range(40)],
     "sun_eccentricity": 10, "planet_eccentricity": 10},
]


@pytest.mark.parametrize("errors", PIN_CASES)
def test_pin_gaps_of_perturbed_cases(errors: dict) -> None:
    g = ReducerGeometry(Case.from_dict({"errors": errors}))
    fc = FclContacts(g)
    th = np.linspace(0.0, 2 * math.pi * g.ratio, 121)[:-1] + 0.0123
    to, ps = g.ideal_state(th)
    p, t0 = g.pins_in_profile_frames(to, ps)
    gap, nrm, _, _ = g.pin_gaps(to, ps)
    for k in range(g.design.n_discs):
        d, n = fc.disc_distance(k, p[:, k].reshape(-1, 2), t0[:, k].ravel())
        gf = d.reshape(len(th), -1) - g.pin_radii[None]
        ga = gap[:, k]
        # where a pin can touch (|gap| < 60 um) the analytic foot is the nearest one: agree
        near = np.abs(ga) < 0.06
        assert near.sum() > 0.25 * near.size
        assert np.abs(gf - ga)[near].max() < DIST_TOL
        assert _angle(n.reshape(-1, 2)[near.ravel()], nrm[:, k].reshape(-1, 2)[near.ravel()]).max() < NORMAL_TOL
        # far from contact the analytic Newton may stop at a local foot: fcl's is the global one
        assert np.all(gf <= ga + DIST_TOL)


def test_pin_gaps_of_displaced_discs() -> None:
    """States off the ideal motion, as the solver's iterations produce them."""
    g = ReducerGeometry(Case.from_dict({"errors": {"pin_circle_diameter": 10}}))
    fc = FclContacts(g)
    rng = np.random.default_rng(2)
    th = rng.uniform(0, 2 * math.pi * g.ratio, 40)
    to, ps = g.ideal_state(th)
    shift = rng.normal(0.0, 0.01, (len(th), 2, 2))
    turn = rng.normal(0.0, 2e-4, (len(th), 2))
    p, t0 = g.pins_in_profile_frames(to + rng.normal(0, 2e-4, len(th)), ps, disc_shift=shift, disc_turn=turn)
    for k, prof in enumerate(g.profiles):
        pk, tk = p[:, k].reshape(-1, 2), t0[:, k].ravel()
        d, n = fc.disc_distance(k, pk, tk)
        ref, _, nref = prof.boundary_distance(pk, tk)
        near = np.abs(ref - prof.pin_radius) < 0.06
        assert np.abs(d - ref)[near].max() < DIST_TOL
        assert _angle(n[near], nref[near]).max() < NORMAL_TOL


@pytest.mark.slow
def test_undercut_profile_distance_is_exact_to_the_trimmed_polygon() -> None:
    """Pin radius above the smallest convex radius of curvature: trimmed corners in the mesh."""
    g = ReducerGeometry(Case.from_dict({"design": {"pin_radius_mm": 4.8}}))
    prof = g.profiles[0]
    trim = prof.trim_t  # (about 2 s each: computed once here)
    assert trim is not None
    fc = FclContacts(g)
    rng = np.random.default_rng(3)
    t = rng.uniform(0, 2 * math.pi, 4000)
    d = rng.uniform(-0.05, 0.5, len(t))
    p = prof.boundary(t) + d[:, None] * prof.normal(t)
    poly = Polygon(prof.boundary_points(fc.sagitta_mm))
    inside = shapely.contains_xy(poly, p[:, 0], p[:, 1])
    ref = shapely.distance(shapely.points(p), poly.exterior) * np.where(inside, -1.0, 1.0)
    sd, n = fc.disc_distance(0, p, t)
    assert np.abs(sd - ref).max() < 1e-9
    # away from the trim corners the exact envelope applies
    exact, tf, nref = prof.boundary_distance(p, t)
    pitch = 2 * math.pi / prof.z_lobes
    rel = np.mod(tf - prof.root_t(), pitch)
    r1, r2 = (x - prof.root_t() for x in trim)
    far = ~(((rel > r1 - 0.01) & (rel < r2 + 0.01)) | ((rel > pitch - r2 - 0.01) & (rel < pitch - r1 + 0.01)))
    assert far.sum() > 1000
    assert np.abs(sd - exact)[far].max() < DIST_TOL
    assert _angle(n[far], nref[far]).max() < NORMAL_TOL


STAGE1_CASES = [
    {},
    {"errors": {"sun_eccentricity": 10}},
    {"errors": {"planet_eccentricity": 10}},
    {"errors": {"planet_eccentricity": {"value": 10, "crank": 1, "angle_deg": 135}}},
    {"errors": {"sun_eccentricity": {"value": 20, "angle_deg": 70},
                "planet_eccentricity": [{"value": 15, "crank": 0}, {"value": 8, "crank": 1, "angle_deg": 200}]}},
    {"errors": {"sun_eccentricity": 150}},  # interference deeper than the first margin
    {"design": {"stage1_backlash_mm": 0.03}, "errors": {"carrier_hole_eccentricity": 10}},
]


@pytest.mark.parametrize("case", STAGE1_CASES)
@pytest.mark.parametrize("direction", [1, -1])
def test_stage1_gaps_match_involute_reference(case: dict, direction: int) -> None:
    g = ReducerGeometry(Case.from_dict(case))
    fc = FclContacts(g)
    th = np.linspace(0.0, 2 * 2 * math.pi, 241) + 0.003  # two sun turns, many mesh positions
    to, ps = g.ideal_state(th)
    got = fc.stage1_gaps(th, to, ps, direction)
    ref = g.stage1_gaps(th, to, ps, direction)
    assert got.shape == ref.shape == (len(th), g.design.n_cranks)
    assert np.abs(got - ref).max() < STAGE1_TOL
    # off the ideal motion (solver iterations): output and crank angles perturbed
    rng = np.random.default_rng(7)
    to2 = to + rng.normal(0.0, 2e-5, len(th))
    ps2 = ps + rng.normal(0.0, 2e-4, ps.shape)
    got2 = fc.stage1_gaps(th, to2, ps2, direction)
    ref2 = g.stage1_gaps(th, to2, ps2, direction)
    assert np.abs(got2 - ref2).max() < STAGE1_TOL
    assert np.ptp(ref2) > 1e-3  # the perturbation really moved the gaps (um scale)


def test_stage1_rejects_bad_direction(nominal) -> None:
    g, fc = nominal
    to, ps = g.ideal_state(np.array([0.1]))
    with pytest.raises(ValueError, match="direction"):
        fc.stage1_gaps(np.array([0.1]), to, ps, 0)


def test_no_fcl_import_outside_collision() -> None:
    """python-fcl is wrapped in one module, rvdyn.collision."""
    root = Path(__file__).resolve().parents[1]
    importers = sorted(str(p.relative_to(root)) for pkg in ("rvcad", "rvdyn", "rvstudy", "rvcalib", "rsm", "rvpaper")
                       for p in (root / pkg).rglob("*.py")
                       if re.search(r"^\s*(import fcl|from fcl\b)", p.read_text(), re.M))
    assert importers == ["rvdyn/collision.py"]


def test_constructor_validates_sagitta() -> None:
    g = ReducerGeometry()
    with pytest.raises(ValueError, match="sagitta_mm"):
        FclContacts(g, sagitta_mm=0.0)
    with pytest.raises(ValueError, match="flank_sagitta_mm"):
        FclContacts(g, flank_sagitta_mm=float("nan"))
