"""The candidate library (rvcalib.library) and the reading columns (rvcalib.readings): instances, prior scales
and weights, case construction, and the analytic columns against their closed forms."""
from __future__ import annotations

import math
import re
from types import SimpleNamespace

import numpy as np
import pytest

from rvcad.errors import Case, ERROR_TYPES
from rvcad.params import Design
from rvcalib.library import CaseDelta, build_library
from rvcalib.readings import nuisance_columns, ramp_shown, reading_columns


def _run(run, load, direction, out_deg, te_arcsec, design=Design(), test=None):
    ratio = float(design.ratio)
    inp = ratio * (np.asarray(out_deg) - np.asarray(te_arcsec) / 3600.0)
    return SimpleNamespace(run=run, load_Nm=load, direction=direction, input_deg=inp, output_deg=np.asarray(out_deg),
                           output_rad=np.radians(out_deg), te_arcsec=np.asarray(te_arcsec, dtype=float),
                           n=len(out_deg), noise_arcsec=0.2, speed_rpm=None, temperature_C=None, design=design,
                           revolutions=1.0)


def _dataset(runs, design=Design(), tests=None):
    of_run = tests or {r.run: f"{r.load_Nm:g}Nm" for r in runs}
    return SimpleNamespace(runs=runs, design=design, declared_keys=[], temperatures_vary=False,
                           ratio=float(design.ratio), tests=SimpleNamespace(of_run=of_run))


def _four_runs(design=Design(), n=100):
    out = np.linspace(0.0, 360.0, n, endpoint=False) + 0.3
    return _dataset([_run(f"r{i}", L, d, out if d > 0 else out[::-1], np.zeros(n), design)
                     for i, (L, d) in enumerate([(10, 1), (10, -1), (30, 1), (30, -1)])], design)


@pytest.mark.parametrize("design,cranks,pins", [(Design(), 2, 40), (Design(z_pins=30, z_disc=29, z_planet=27), 2, 30)])
def test_library_holds_every_instance(design, cranks, pins):
    lib = build_library(_four_runs(design), max_order=20)
    names = [c.name for c in lib]
    # a single pin's error: its positive and its negative values, each a candidate; pin pitch has single pins only
    assert {f"pin_pitch[pin={pins - 1}] (+)", f"pin_pitch[pin={pins - 1}] (-)"} <= set(names)
    assert "pin_pitch" not in names
    assert lib.by_name(f"pin_pitch[pin={pins - 1}] (-)").effect_name == f"pin_pitch[pin={pins - 1}]"
    assert lib.by_name(f"pin_pitch[pin={pins - 1}] (-)").upper == 0.0
    # all the pins' radius and circle diameter and the compliance: always estimated
    assert {c.name for c in lib if c.dense} == {"pin_radius", "pin_circle_diameter", "torsional_compliance_arcsec_per_Nm"}
    assert f"cam_phase[crank={cranks - 1},disc=1]" in names
    assert f"disc_hole_eccentricity[disc=1,hole={cranks - 1}]" in names
    assert f"pin_form_radial[k={pins // 2}]" in names and "pin_form_radial[k=1]" not in names
    n_t4 = sum(1 for c in lib if c.family == "table4")
    # sun 1, planet cranks, cam phase and ecc 2 cranks each, carrier cranks, disc hole 2 cranks, offset 1,
    # diameter 1 + 2 Zp, radius 1 + 2 Zp, disc phase 2, pitch 2 Zp
    assert n_t4 == 1 + cranks + 2 * 2 * cranks + cranks + 2 * cranks + 1 + 2 + 6 * pins + 2
    assert "order 20 (direction)" in names and "order 21 (common)" not in names


def test_prior_scales_and_weights():
    lib = build_library(_four_runs(), max_order=10)
    c = lib.by_name("cam_phase[crank=1,disc=0]")
    assert c.prior_scale == pytest.approx(ERROR_TYPES["cam_phase"].paper_value / 3.0)
    w = lib.prior_weights(1.0)
    by = {c.name: wi for c, wi in zip(lib, w)}
    # every type has weight one shared by its instances; pin-wise radius: half to all pins, half to the singles
    assert sum(v for k, v in by.items() if k.startswith("cam_phase")) == pytest.approx(1.0)
    assert by["pin_radius[pin=3] (+)"] == by["pin_radius[pin=3] (-)"] == pytest.approx(0.5 / 40 / 2)
    assert sum(v for k, v in by.items() if lib.by_name(k).family == "empirical") == pytest.approx(1.0)
    # the form modes' scale: a pin-wise class sigma spread over Zp / 2 modes of two components
    f = lib.by_name("pin_form_radial[k=3]")
    assert f.prior_scale == pytest.approx(10.0 / 3.0 / 2.0 * math.sqrt(2.0 / 40.0))


def test_case_delta_adds_instances_and_pinwise_lists():
    lib = build_library(_four_runs(), max_order=5)
    acc = CaseDelta()
    lib.by_name("pin_pitch[pin=3] (+)").add_to(acc, np.array([0.01]))
    lib.by_name("pin_form_pitch[k=2]").add_to(acc, np.array([0.002, 0.0]))
    lib.by_name("planet_eccentricity[crank=1]").add_to(acc, np.array([3.0, 4.0]))
    lib.by_name("torsional_compliance_arcsec_per_Nm").add_to(acc, np.array([0.2]))
    d = acc.to_dict({"errors": {"pin_pitch": 0.001, "cam_phase": 2.0}, "load_Nm": 10, "direction": 1})
    pitch = np.array(d["errors"]["pin_pitch"])
    phi = 2 * np.pi * np.arange(40) / 40
    expect = 0.001 * (np.arange(40) == 0) + 0.002 * np.cos(2 * phi)      # declared number: the default instance, pin 0
    expect[3] += 0.01
    # a declared pin_pitch number applies to pin 0 (its default instance)
    case = Case.from_dict(d)
    got = {(e.key, e.pin): e.value for e in case.errors if e.key == "pin_pitch"}
    assert got[("pin_pitch", 3)] == pytest.approx(expect[3])
    assert d["model"] == {"torsional_compliance_arcsec_per_Nm": 0.2}
    planet = [e for e in case.errors if e.key == "planet_eccentricity"]
    assert {(e.crank, e.angle_deg, e.value) for e in planet} == {(1, 0.0, 3.0), (1, 90.0, 4.0)}


def test_reading_columns_closed_forms():
    ds = _four_runs()
    lib = build_library(ds, max_order=3)
    oe = reading_columns(lib.by_name("output_encoder_eccentricity"), ds)
    th = np.concatenate([r.output_rad for r in ds.runs])
    k = 1e-3 / 100.0 * 180 / math.pi * 3600           # arcsec per um at a 100 mm radius
    assert oe == pytest.approx(k * np.column_stack([np.sin(th), np.cos(th)]))
    h = reading_columns(lib.by_name("order 3 (load)"), ds)
    loads = np.concatenate([np.full(r.n, r.load_Nm / 30.0) for r in ds.runs])
    assert h == pytest.approx(loads[:, None] * np.column_stack([np.cos(3 * th), np.sin(3 * th)]))
    c = reading_columns(lib.by_name("constant (load x direction)"), ds)
    assert c[:, 0] == pytest.approx(np.concatenate([np.full(r.n, r.direction * r.load_Nm / 30.0) for r in ds.runs]))


def test_nuisance_columns_one_constant_per_load_by_default_or_per_test():
    ds = _four_runs()
    N, tests = nuisance_columns(ds)
    assert N.shape == (400, 2) and len(tests) == 2
    assert np.all(N[:100, 0] == 1) and np.all(N[100:200, 0] == 1) and np.all(N[200:, 1] == 1)
    ds.tests = SimpleNamespace(of_run={"r0": "a", "r1": "b", "r2": "a", "r3": "b"})
    N, tests = nuisance_columns(ds)
    assert tests == ["a", "b"] and np.all(N[200:300, 0] == 1)


def test_ramp_shown_only_where_the_record_does_not_meet_itself():
    out = np.linspace(0.0, 360.0, 333, endpoint=False) + 0.4
    th = np.radians(out)
    rng = np.random.default_rng(3)
    periodic = 20.0 + 15.0 * np.sin(th) + 8.0 * np.cos(3 * th) + 2.0 * np.sin(40 * th) + 0.2 * rng.normal(size=333)
    ds = _dataset([_run("a", 10, 1, out, periodic)])
    shown, lines = ramp_shown(ds)
    assert not shown, lines
    ramp = periodic + 4.0 * (out - out[0]) / 360.0          # 4 arcsec over the record: 20 times the noise
    shown, lines = ramp_shown(_dataset([_run("a", 10, 1, out, ramp)]))
    assert shown, lines
    size, se = (float(x) for x in re.search(r"ramp ([-+0-9.e]+) arcsec .*standard error ([0-9.e]+)", lines[0]).groups())
    assert abs(size - 4.0) < 3.0 * se
