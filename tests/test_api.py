"""The five-line Python API (``rvdyn.solve``) and the one forward runner (``rvdyn.run_cases``)."""
from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import rvdyn
from rvcad.errors import Case
from rvdyn.te import run_te, te_stats

ROOT = Path(__file__).resolve().parents[1]
STEPS = 24
CASE = {"name": "ea", "errors": {"pin_pitch": 0.02}}


def readme_snippet() -> str:
    """The README's Python block that starts with ``import rvdyn``."""
    blocks = re.findall(r"```python\n(.*?)```", (ROOT / "README.md").read_text(encoding="utf-8"), re.S)
    found = [b for b in blocks if b.startswith("import rvdyn\n")]
    assert len(found) == 1, "the README holds one Python snippet starting with 'import rvdyn'"
    return found[0]


@pytest.mark.slow
def test_readme_snippet_is_five_lines_and_runs(tmp_path):
    code = readme_snippet()
    assert len(code.strip().splitlines()) == 5
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]),
           "MPLBACKEND": "Agg"}
    done = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env=env, capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    pp, mean_abs = (float(x) for x in lines[0].split())
    ref = run_te(Case.from_dict({"errors": {"pin_pitch": 0.02}}), "analytic", 360)
    assert pp == pytest.approx(ref.stats["pp"], rel=1e-12) and mean_abs == pytest.approx(ref.stats["mean_abs"], rel=1e-12)
    assert lines[1].split() == ["input_deg", "output_deg", "te_arcsec"]
    assert not list(tmp_path.iterdir())  # the snippet writes nothing


@pytest.fixture(scope="module")
def solved() -> rvdyn.Result:
    return rvdyn.solve(CASE, steps=STEPS)


def test_solve_table_and_stats_are_run_te_and_te_stats(solved):
    ref = run_te(Case.from_dict(CASE), "analytic", STEPS)
    pd.testing.assert_frame_equal(solved.table, ref.table)
    assert {"input_deg", "output_deg", "te_arcsec"} <= set(solved.table)
    st = te_stats(solved.table["te_arcsec"].to_numpy())
    assert {k: solved.stats[k] for k in st} == st  # pp, mean, mean_abs, rms in arcsec
    assert solved.stats["pp"] > 1.0  # a pin-pitch error of 0.02 deg makes a TE ripple of arcsec


@pytest.mark.parametrize("form", ["case", "json"])
def test_solve_takes_a_case_or_a_json_path(solved, tmp_path, form):
    if form == "case":
        arg = Case.from_dict(CASE)
    else:
        arg = tmp_path / "case.json"
        arg.write_text(json.dumps(CASE))
    r = rvdyn.solve(arg, steps=STEPS)
    np.testing.assert_array_equal(r.table["te_arcsec"], solved.table["te_arcsec"])
    assert r.case.key() == solved.case.key()


@pytest.mark.parametrize("case, kw, match", [
    (3, {}, "case int is not allowed"),
    ({"errors": {"no_such_error": 1.0}}, {}, "no_such_error"),
    ("missing-case.json", {}, "missing-case.json"),
    (None, {"solver": "magic"}, "solver 'magic'"),
    (None, {"steps": 1}, "steps 1"),
])
def test_solve_bad_input_names_the_field(case, kw, match):
    with pytest.raises(ValueError, match=match):
        rvdyn.solve(case, **kw)


def test_plot_draws_te_against_output_angle(solved, tmp_path):
    from matplotlib.figure import Figure

    ax = Figure().add_subplot(1, 1, 1)
    assert solved.plot(ax=ax, path=tmp_path / "te.png") is ax
    x, y = ax.lines[0].get_data()
    np.testing.assert_array_equal(y, solved.table["te_arcsec"])
    np.testing.assert_array_equal(x, solved.table["output_deg"])
    assert (tmp_path / "te.png").stat().st_size > 0 and [p.name for p in tmp_path.iterdir()] == ["te.png"]


# ---------------------------------------------------------------------------------------------- runner
def test_run_cases_per_case_steps_angles_and_cache(solved, tmp_path):
    cases = [Case.from_dict(CASE), Case.from_dict({})]
    th = np.linspace(0.0, 40.0, 9)
    first = rvdyn.run_cases(cases, steps=[STEPS, 12], cache=tmp_path / "c")
    np.testing.assert_array_equal(first[0]["te_arcsec"], solved.table["te_arcsec"])
    assert first[1]["te_arcsec"].shape == (12,) and not any(r["cached"] for r in first)
    assert first[0]["stats"]["pp"] == solved.stats["pp"] and first[0]["status"] == "ok"
    again = rvdyn.run_cases(cases, steps=[STEPS, 12], cache=tmp_path / "c")
    assert all(r["cached"] for r in again)
    np.testing.assert_array_equal(again[0]["te_arcsec"], first[0]["te_arcsec"])
    # at given input angles (e.g. readings): the same values as run_te at those angles; another key
    at = rvdyn.run_cases(cases[:1], theta_in_deg=[th], cache=tmp_path / "c")
    np.testing.assert_array_equal(at[0]["te_arcsec"], run_te(cases[0], theta_in_deg=th).table["te_arcsec"])
    assert not at[0]["cached"] and at[0]["key"] != first[0]["key"]


@pytest.mark.parametrize("kw, match", [
    ({"steps": [24]}, "steps has 1 entries for 2 cases"),
    ({"steps": [24, 1]}, r"steps\[1\] 1"),
    ({"theta_in_deg": [None]}, "theta_in_deg has 1 entries"),
    ({"theta_in_deg": [[0.0], None]}, r"theta_in_deg\[0\]"),
    ({"solver": "magic"}, "solver 'magic'"),
    ({"executor": 0}, "workers 0"),
    ({"executor": " "}, "scheduler address ' '"),
])
def test_run_cases_bad_input_names_the_field(kw, match):
    with pytest.raises(ValueError, match=match):
        rvdyn.run_cases([Case.from_dict({}), Case.from_dict({})], **kw)


def test_cache_key_covers_every_solver_module():
    """Every module of rvcad and rvdyn enters the cache key (so a changed law never serves stale numbers),
    except the runner, the cache, the API and the CLIs; the fcl provider's modules for fcl jobs only."""
    from rvdyn.cache import FCL_MODULES, NOT_PHYSICS, code_fingerprint, physics_modules

    every = {p.parent.name if p.stem == "__init__" else f"{p.parent.name}.{p.stem}"
             for pkg in ("rvcad", "rvdyn") for p in (ROOT / pkg).glob("*.py")}
    assert set(physics_modules("fcl")) == every - NOT_PHYSICS
    assert set(physics_modules("analytic")) == every - NOT_PHYSICS - FCL_MODULES
    assert {"rvcad.geometry", "rvcad.params", "rvdyn.solver", "rvdyn.te", "rvdyn.contacts"} <= set(physics_modules())
    assert code_fingerprint("analytic") != code_fingerprint("fcl")


def test_runner_memory_cache_serves_repeats_and_keeps_its_budget(tmp_path):
    """The in-memory cache (no disk): a repeat is served from memory, equal to the solve; the caller gets
    its own writable copy; beyond the budget the least recently used entry goes first."""
    from rvdyn.runner import ENTRY_OVERHEAD_BYTES, Runner

    cases = [Case.from_dict(CASE), Case.from_dict({})]
    one = ENTRY_OVERHEAD_BYTES + 12 * 8  # one entry of 12 float64 TE values
    with Runner(steps=12, memory_bytes=one) as run:  # room for one entry
        a = run(cases[:1])
        b = run(cases[:1])
        assert not a[0]["cached"] and b[0]["cached"] and (run.computed, run.reused) == (1, 1)
        np.testing.assert_array_equal(a[0]["te_arcsec"], b[0]["te_arcsec"])
        b[0]["te_arcsec"][:] = 0.0  # the caller's copy; the kept entry is unchanged
        assert run(cases[:1])[0]["te_arcsec"].tolist() == a[0]["te_arcsec"].tolist()
        run(cases[1:])  # pushes the first case out
        assert len(run.memory) == 1 and run.memory.bytes == one
        assert not run(cases[:1])[0]["cached"] and run.computed == 3
    assert not list(tmp_path.iterdir())  # nothing on disk
    with Runner(steps=12, memory_bytes=2 * one) as run:
        assert [r["cached"] for r in run(cases + cases)] == [False, False, False, False]  # equal jobs solved once
        assert run.computed == 2 and run.memory.hits == 0 and run(cases)[0]["cached"]


@pytest.mark.parametrize("bad", [-1, 1.5, True])
def test_runner_memory_budget_must_be_a_nonnegative_integer(bad):
    from rvdyn.runner import Runner

    with pytest.raises(ValueError, match=f"memory_bytes {bad!r} must be an integer >= 0"):
        Runner(memory_bytes=bad)


def test_runner_without_a_law_solves_each_case_with_its_own():
    """``law=None``: every case with the contact law of its ``model`` options (as ``run_te`` does);
    a law given to the runner replaces it for every case."""
    from rvdyn.contacts import ContactLaw

    soft = Case.from_dict({**CASE, "model": {"contact": "impact", "contact_K_N_per_mm_n": 5.0e4}})
    paper_case = Case.from_dict({**CASE, "model": {"contact": "impact"}})
    own, paper, default = rvdyn.run_cases([soft, paper_case, Case.from_dict(CASE)], steps=STEPS)
    np.testing.assert_array_equal(own["te_arcsec"], run_te(soft, "analytic", STEPS).table["te_arcsec"])
    forced = rvdyn.run_cases([soft], steps=STEPS, law=ContactLaw())[0]
    np.testing.assert_array_equal(forced["te_arcsec"], paper["te_arcsec"])
    assert forced["key"] != own["key"]  # the law enters the key
    assert np.max(np.abs(own["te_arcsec"] - paper["te_arcsec"])) > 0.1  # a softer contact winds up more
    # a case that names no law is solved with the default, physical one (conventions.md)
    phys = run_te(Case.from_dict(CASE), "analytic", STEPS)
    assert phys.stats["contact"] == "physical"
    np.testing.assert_array_equal(default["te_arcsec"], phys.table["te_arcsec"])
    assert np.max(np.abs(default["te_arcsec"] - paper["te_arcsec"])) > 0.1


def test_cli_te_and_stiffness_default_to_the_physical_law(capsys):
    """conventions.md: the quasi-static analysis is physical by default; the impact law is a named option,
    and its --K/--n without --contact impact are refused naming the option."""
    import json

    from rvdyn.cli import main

    assert main(["te", "--steps", "4", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["contact"] == "physical"
    assert main(["te", "--steps", "4", "--json", "--contact", "impact", "--K", "2e5", "--n", "1.5"]) == 0
    assert json.loads(capsys.readouterr().out)["contact"] == "impact"
    assert main(["te", "--steps", "4", "--K", "2e5"]) == 2
    assert "--K and --n set the impact law; they need --contact impact" in capsys.readouterr().err
    assert main(["stiffness", "--points", "5", "--json"]) == 0
    f = json.loads(capsys.readouterr().out)
    assert f["contact"] == "physical" and {"carrier", "pin_seats"} <= set(f["budget"])
