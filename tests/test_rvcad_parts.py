"""Parts: closed forms, exact outlines, valid meshes and solids, undercut, interference (python-fcl)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from rvdyn import collision
from rvcad.errors import Case
from rvcad.parts import (AXIAL_CLEARANCE_MM, Assembly, CycloidDisc, PinHousing, PlanetGear, SunGear, GearPart)
from rvcad.curves import involute_deviation
from rvcad.mesh import stacked_circles, triangulate
from rvcad.outline import Loop
from rvcad.plane import arc_steps

S = 1e-4  # 0.1 um sagitta / tolerance


@pytest.fixture(scope="module")
def nominal() -> Assembly:
    return Assembly()


def _perimeter(part) -> float:
    outer, holes = part.outline()
    return sum(float(np.linalg.norm(np.diff(np.vstack([r, r[:1]]), axis=0), axis=1).sum())
               for r in [outer.ring(1e-2)] + [h.ring(1e-2) for h in holes])


def test_mesh_volumes_match_closed_forms(nominal: Assembly) -> None:
    """Every vertex is on the exact outline and every chord within the sagitta, so the polyhedron's
    volume differs from the closed form by at most sagitta x perimeter x width."""
    for name in ["sun", "planet0", "crank0", "flange", "disc0", "disc1", "carrier", "housing", "pin00", "pin39"]:
        part = nominal[name]
        m = part.mesh(S).check()
        exact = part.exact_volume()
        assert exact is not None
        if name.startswith("crank"):
            bound = 2 * S * part.width * 2 * math.pi * 9.0 * 3
        else:
            bound = S * _perimeter(part) * part.width
        assert abs(m.volume - exact) <= bound, name
    pin = nominal["pin00"]
    assert pin.exact_volume() == pytest.approx(math.pi * 3.0 ** 2 * (2 * 10.0 + 0.5), rel=1e-15)


def test_disc_area_closed_form(nominal: Assembly) -> None:
    disc = nominal["disc0"]
    assert isinstance(disc, CycloidDisc)
    e, rp, Rp, zp = 1.3, 3.0, 64.0, 40
    t = np.linspace(0, 2 * np.pi, 100001)[:-1]
    L = np.linalg.norm(disc.profile.dq(t), axis=1).mean() * 2 * np.pi
    expect = math.pi * (Rp ** 2 + zp * e ** 2) - rp * L + math.pi * rp ** 2 - math.pi * (14.0 ** 2 + 2 * 9.0 ** 2)
    assert disc.exact_area() == pytest.approx(expect, rel=1e-12)
    area = disc.mesh(S).volume / disc.width
    assert area == pytest.approx(expect, abs=S * _perimeter(disc))


def test_gear_area_closed_form_against_fine_polygon(nominal: Assembly) -> None:
    from shapely.geometry import Polygon

    for name in ("sun", "planet0"):
        g = nominal[name]
        assert isinstance(g, GearPart)
        outer, holes = g.outline()
        poly = Polygon(outer.ring(1e-6), [h.ring(1e-6) for h in holes])
        # the inscribed polygon loses at most sagitta x perimeter
        assert 0.0 <= g.exact_area() - poly.area <= 1e-6 * _perimeter(g)


def test_housing_area_closed_form_against_fine_polygon(nominal: Assembly) -> None:
    from shapely.geometry import Polygon

    h = nominal["housing"]
    assert isinstance(h, PinHousing)
    outer, holes = h.outline()
    poly = Polygon(outer.ring(1e-6), [r.ring(1e-6) for r in holes])
    assert poly.is_valid
    assert h.exact_area() == pytest.approx(poly.area, abs=1e-3)


def test_outline_vertices_and_chords_within_tolerance(nominal: Assembly) -> None:
    """Cycloid envelope 0.1 um, involute flanks 0.5 um (here 0.1 um), vertices and chord midpoints,
    after float32 rounding."""
    for name in ("disc0", "disc1"):
        assert nominal[name].outline_deviation(S) < 1e-4
    for name in ("sun", "planet0", "planet1"):
        assert nominal[name].outline_deviation(S) < 1e-4
    # and a coarse tessellation is coarse: the check can fail
    assert nominal["disc0"].outline_deviation(1e-2) > 1e-3


def test_step_bsplines_within_tolerance(nominal: Assembly) -> None:
    for name in ("disc0", "sun", "planet0"):
        assert nominal[name].spline_deviation(S) < 0.6 * S


def test_gear_outline_matches_core_outline(nominal: Assembly) -> None:
    """Our outline has exact arcs; its vertices on the flanks are the core's exact involute points."""
    g = nominal["sun"]
    core = g.gear.outline(sagitta=S)
    ours = g.outline()[0].ring(S)
    r_core, r_ours = np.linalg.norm(core, axis=1), np.linalg.norm(ours, axis=1)
    assert r_core.min() == pytest.approx(r_ours.min(), abs=1e-12)
    assert r_core.max() == pytest.approx(r_ours.max(), abs=1e-12)
    fl = (r_ours > g.gear.base_radius + 1e-9) & (r_ours < g.gear.tip_radius - 1e-9)
    assert np.abs(g.flank_distance(ours[fl])).max() < 1e-12


def test_involute_deviation_is_a_distance() -> None:
    g = SunGear(Assembly().geometry).gear
    lam = np.linspace(0.2, 0.7, 7)
    p = g.involute(lam)
    n = np.stack([np.cos(g.flank_origin - lam), np.sin(g.flank_origin - lam)], axis=1)  # toward the base circle
    # moving along the involute normal (tangent of the base circle) by d changes the distance by d
    t = np.stack([-np.sin(g.flank_origin - lam), np.cos(g.flank_origin - lam)], axis=1)
    for d in (1e-3, -2e-3):
        assert involute_deviation(g, p + d * t) == pytest.approx(np.full(7, d), abs=1e-12)
    assert np.abs(involute_deviation(g, p)).max() < 1e-12
    del n


def test_solids_valid_and_volumes(nominal: Assembly) -> None:
    from OCP.BRepCheck import BRepCheck_Analyzer
    from OCP.BRepGProp import BRepGProp
    from OCP.GProp import GProp_GProps

    for name in ["sun", "planet1", "crank1", "flange", "disc1", "carrier", "housing", "pin07"]:
        part = nominal[name]
        s = part.shape(S)
        assert BRepCheck_Analyzer(s).IsValid(), name
        props = GProp_GProps()
        BRepGProp.VolumeProperties_s(s, props)
        # lines and circles are exact; B-splines within 0.05 um (OpenCASCADE integrates to ~1e-6)
        assert props.Mass() == pytest.approx(part.exact_volume(), rel=2e-6), name


def test_derived_values_are_attributes(nominal: Assembly) -> None:
    d = nominal["disc0"]
    assert isinstance(d, CycloidDisc)
    assert d.root_radius == pytest.approx(64 - 1.3 - 3)
    assert d.tip_radius == pytest.approx(64 + 1.3 - 3)
    assert d.undercut is False
    assert d.design_check["message"] == "no undercut"
    assert d.min_convex_radius == pytest.approx(4.61, abs=0.01)
    p = nominal["planet1"]
    assert isinstance(p, PlanetGear)
    assert p.bore_radius == 7.0 and np.allclose(p.bore_center, 0.0)
    c = nominal["crank0"]
    assert c.cam_centers == pytest.approx(np.array([[1.3, 0.0], [-1.3, 0.0]]), abs=1e-12)
    assert nominal.layout.disc1[0] - nominal.layout.disc0[1] == pytest.approx(0.5)
    info = d.info()
    assert info["undercut"] is False and "root_radius_mm" in info


def test_undercut_disc_is_trimmed_valid_and_reported(tmp_path) -> None:
    asm = Assembly(Case.from_dict({"name": "undercut", "design": {"pin_radius_mm": 4.8}}))
    disc = asm["disc0"]
    assert isinstance(disc, CycloidDisc)
    assert disc.undercut
    assert "undercut" in disc.design_check["message"]
    check = asm.design_check()
    assert check["undercut"] is True
    assert any("undercut" in m for m in check["messages"])
    from shapely.geometry import Polygon

    outer, holes = disc.outline()
    ring = outer.ring(S)
    assert Polygon(ring).is_valid  # never a self-intersecting wire
    m = disc.mesh(S).check()
    assert m.volume > 0
    assert disc.outline_deviation(S) < 1e-4
    assert disc.spline_deviation(S) < 0.6 * S
    from OCP.BRepCheck import BRepCheck_Analyzer

    assert BRepCheck_Analyzer(disc.shape(S)).IsValid()
    # every pin still touches the trimmed disc (contacts are on the untrimmed flanks)
    gap = asm.geometry.pin_gaps(*asm.geometry.ideal_state(np.array([0.3])))[0]
    assert np.abs(gap).max() < 1e-9


def test_stacked_circles_with_crossing_cams() -> None:
    """disc_gap_mm = 0: the two cams meet face to face; the step faces are the two crescents."""
    asm = Assembly(Case.from_dict({"design": {"disc_gap_mm": 0.0}}))
    crank = asm["crank0"]
    m = crank.mesh(S).check()
    assert m.volume == pytest.approx(crank.exact_volume(), rel=1e-4)
    r = 9.0
    d = 2.6
    lens = 2 * r * r * math.acos(d / (2 * r)) - 0.5 * d * math.sqrt(4 * r * r - d * d)
    assert lens > 0
    # the union solid exists too
    from OCP.BRepCheck import BRepCheck_Analyzer

    assert BRepCheck_Analyzer(crank.shape(S)).IsValid()


def test_triangulate_rejects_self_intersection() -> None:
    bow = np.array([[0.0, 0.0], [1.0, 1.0], [1.0, 0.0], [0.0, 1.0]])
    with pytest.raises(ValueError, match="invalid"):
        triangulate([bow])
    with pytest.raises(ValueError, match="sagitta"):
        arc_steps(1.0, 1.0, 0.0)
    with pytest.raises(ValueError, match="do not join"):
        from rvcad.outline import LineSeg

        Loop((LineSeg((0, 0), (1, 0)), LineSeg((1, 0), (0, 1)), LineSeg((0, 1), (0, 0.5))))
    with pytest.raises(ValueError, match="overlap"):
        stacked_circles([(0, 1, (0, 0), 1.0), (1, 2, (5, 0), 1.0)], 1e-3)


# ---------------------------------------------------------------------------- interference (fcl)
MARGIN = 1e-3  # probes shrunk by 1 um so that FCL measures a positive distance


_BVH: dict[str, object] = {}


def _mesh_obj(asm: Assembly, name: str):
    """FCL object of a part's own-frame mesh (BVH built once) at the part's placement."""
    if name not in _BVH:
        m = asm[name].mesh(S)
        _BVH[name] = collision.bvh(m.vertices, m.faces)
    x, y, r = asm.placements[name]
    return collision.obj(_BVH[name], collision.transform(r, (x, y), 0.0))


def _probe(center, radius: float, z: tuple[float, float]):
    """Exact FCL cylinder shrunk by MARGIN, world frame."""
    return collision.obj(collision.cylinder(radius - MARGIN, z[1] - z[0]),
                         collision.transform(0.0, (float(center[0]), float(center[1])), 0.5 * (z[0] + z[1])))


def _world(asm: Assembly, name: str, p: np.ndarray) -> np.ndarray:
    x, y, r = asm.placements[name]
    a = math.radians(r)
    return np.array([x, y]) + np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]]) @ p


@pytest.mark.slow
@pytest.mark.parametrize("theta_in_deg", [0.0, 37.0, 1000.0])
def test_nominal_assembly_contacts_and_clearances(nominal: Assembly, theta_in_deg: float) -> None:
    asm = nominal.at(theta_in_deg)
    lay = asm.layout
    contact = []  # distances of exact probes shrunk by MARGIN: MARGIN within the tessellation tolerance
    discs = {k: _mesh_obj(asm, f"disc{k}") for k in range(2)}
    for i in range(40):
        pin = asm[f"pin{i:02d}"]
        probe = _probe(pin.center, pin.radius, lay.pins)
        for k in range(2):
            contact.append(("pin-disc", collision.distance(probe, discs[k]).distance))
    housing = _mesh_obj(asm, "housing")
    for i in (0, 13, 27):
        pin = asm[f"pin{i:02d}"]
        contact.append(("pin-housing", collision.distance(_probe(pin.center, pin.radius, lay.pins), housing).distance))
    plates = {n: _mesh_obj(asm, n) for n in ("flange", "carrier")}
    planets = {j: _mesh_obj(asm, f"planet{j}") for j in range(2)}
    for j in range(2):
        crank = asm[f"crank{j}"]
        axis = _world(asm, f"crank{j}", np.zeros(2))
        for k in range(2):
            cam = _world(asm, f"crank{j}", crank.cam_centers[k])
            probe = _probe(cam, crank.cam_radius, lay.disc(k))
            contact.append(("cam-disc", collision.distance(probe, discs[k]).distance))
        for n in ("flange", "carrier"):
            contact.append(("journal-plate", collision.distance(
                _probe(axis, crank.journal_radius, getattr(lay, n)), plates[n]).distance))
        contact.append(("journal-planet", collision.distance(
            _probe(axis, crank.journal_radius, lay.gears), planets[j]).distance))
    for kind, d in contact:
        assert abs(d - MARGIN) <= S + 1e-6, (kind, d)

    # gears mesh: the meshes touch (distance within the tolerance) ...
    sun = _mesh_obj(asm, "sun")
    for j in range(2):
        d = collision.distance(sun, planets[j]).distance
        assert d <= S, d
    # ... and no planet vertex is inside a sun tooth beyond the tolerance (exact involute distance)
    sun_part = asm["sun"]
    assert isinstance(sun_part, SunGear)
    xs, ys, rs = asm.placements["sun"]
    for j in range(2):
        v = asm.placed_mesh(f"planet{j}", S).vertices[:, :2]
        a = math.radians(-rs)
        q = (v - np.array([xs, ys])) @ np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]]).T
        r = np.linalg.norm(q, axis=1)
        q = q[(r > sun_part.gear.base_radius) & (r < sun_part.gear.tip_radius)]
        pitch = 2 * math.pi / sun_part.gear.z
        k = np.round(np.arctan2(q[:, 1], q[:, 0]) / pitch)
        c, s = np.cos(-k * pitch), np.sin(-k * pitch)
        q0 = np.stack([c * q[:, 0] - s * q[:, 1], s * q[:, 0] + c * q[:, 1]], axis=1)
        up = involute_deviation(sun_part.gear, q0)
        low = involute_deviation(sun_part.gear, q0 * np.array([1.0, -1.0]))
        assert np.maximum(up, low).min() >= -S

    # parts that should be apart are apart
    apart = [("disc0", "disc1", 0.5), ("flange", "disc0", AXIAL_CLEARANCE_MM), ("disc1", "carrier", AXIAL_CLEARANCE_MM),
             ("sun", "flange", AXIAL_CLEARANCE_MM), ("planet0", "flange", AXIAL_CLEARANCE_MM),
             ("sun", "disc0", 1.0), ("disc0", "housing", 0.3), ("disc1", "housing", 0.3),
             ("crank0", "crank1", 10.0), ("sun", "crank0", 5.0), ("pin00", "carrier", AXIAL_CLEARANCE_MM)]
    objs: dict[str, object] = {"disc0": discs[0], "disc1": discs[1], "housing": housing, **plates,
                               "planet0": planets[0], "sun": sun}
    for a, b, at_least in apart:
        oa = objs.get(a) or _mesh_obj(asm, a)
        ob = objs.get(b) or _mesh_obj(asm, b)
        assert not collision.collide(oa, ob), (a, b)
        assert collision.distance(oa, ob).distance >= at_least - 1e-6, (a, b)


def test_disc_outline_is_the_core_boundary_sampling(nominal: Assembly) -> None:
    """The exported disc outline has the vertices of ``CycloidProfile.boundary_points`` (what rvdyn
    assumes), turned by the disc phase."""
    for k in range(2):
        disc = nominal[f"disc{k}"]
        ours = disc.outline()[0].ring(S)
        core = disc.profile.boundary_points(S)
        assert len(ours) == len(core)
        key = lambda p: np.lexsort((np.round(p[:, 1], 9), np.round(p[:, 0], 9)))  # noqa: E731
        a, b = ours[key(ours)], core[key(core)]
        assert np.abs(a - b).max() < 1e-11


@pytest.mark.slow
def test_placed_discs_are_the_analysed_geometry() -> None:
    """With errors, FCL distances from the exact pins to the placed disc meshes equal the analytic
    pin gaps of ReducerGeometry (the exported geometry is the analysed geometry)."""
    errors = {"pin_radius": -10, "disc_phase": {"value": 0.002, "disc": 1}, "pin_pitch": {"value": 0.003, "pin": 5},
              "cam_eccentricity": {"value": 3, "crank": 1, "disc": 0}, "disc_hole_eccentricity": 2,
              "pin_circle_offset": {"value": 2, "angle_deg": 30}}
    asm = Assembly(Case.from_dict({"errors": errors}), theta_in_deg=23.0)
    g = asm.geometry
    to, ps = g.ideal_state(np.array([math.radians(23.0)]))
    gap = g.pin_gaps(to, ps)[0][0]  # (n_discs, Zp) mm
    assert gap.min() > 2e-3
    for k in range(2):
        m = asm.placed_mesh(f"disc{k}", S)
        disc = collision.obj(collision.bvh(m.vertices, m.faces))
        for i in range(0, 40, 3):
            pin = asm[f"pin{i:02d}"]
            probe = collision.obj(collision.cylinder(pin.radius, asm.layout.pins[1] - asm.layout.pins[0]),
                                  collision.transform(0.0, tuple(pin.center), 0.5 * sum(asm.layout.pins)))
            d = collision.distance(probe, disc).distance
            assert d == pytest.approx(gap[k, i], abs=S + 1e-6), (k, i)
