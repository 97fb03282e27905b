"""Property-based fuzz of every input loader: nothing but the InputError family may escape.

Each loader gets structured-but-wrong input (right keys with values of every JSON type, huge and
non-finite numbers, repeated keys, broken CSV) and plain random text. A loader either returns or
raises :class:`rvcad.validation.InputError`; any other exception (TypeError, KeyError, IndexError,
OverflowError, a bare ValueError from numpy/pandas, ...) fails the test with the input that caused it.

The example counts are sized for about 15 s in CI; ``FUZZ_EXAMPLES`` (environment) multiplies them
for a longer local run, e.g. ``FUZZ_EXAMPLES=40 pytest tests/test_fuzz_loaders.py``.
"""
from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from rvcad.errors import ERROR_TYPES, Case, load_case, parse_errors
from rvcad.params import Design
from rvcad.validation import InputError

SCALE = float(os.environ.get("FUZZ_EXAMPLES", "1"))


def fuzz(n: int):
    """Hypothesis settings: ``n`` examples (times FUZZ_EXAMPLES), no deadline, no shrinking database."""
    return settings(max_examples=max(1, int(n * SCALE)), deadline=None, database=None,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture,
                                           HealthCheck.filter_too_much, HealthCheck.data_too_large])


DESIGN_KEYS = [f for f in Design().to_dict()]
NUMBERS = st.one_of(
    st.integers(-10 ** 6, 10 ** 6), st.integers(), st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([0, 1, -1, 2, 3, 12, 36, 39, 40, 1e12, -1e12, 1e308, 5e-324, 10 ** 400, 0.5, 1.3, 3.0, 128.0]))
SCALARS = st.one_of(st.none(), st.booleans(), NUMBERS, st.text(max_size=8))
JSON = st.recursive(SCALARS, lambda c: st.one_of(st.lists(c, max_size=5),
                                                 st.dictionaries(st.text(max_size=6), c, max_size=5)),
                    max_leaves=12)
VALUE = st.one_of(NUMBERS, JSON)


@st.composite
def design_dicts(draw) -> dict:
    keys = draw(st.lists(st.one_of(st.sampled_from(DESIGN_KEYS), st.text(max_size=6)), max_size=6))
    d = {}
    for k in keys:
        if k == "crank_angles_deg":
            d[k] = draw(st.one_of(st.lists(NUMBERS, max_size=4), VALUE))
        elif k.startswith("z_"):
            d[k] = draw(st.one_of(st.integers(-5, 400), VALUE))
        else:
            d[k] = draw(st.one_of(st.floats(-10, 200), VALUE))
    return d


INSTANCE_KEYS = ["value", "crank", "disc", "hole", "pin", "angle_deg"]


@st.composite
def error_dicts(draw) -> dict:
    keys = draw(st.lists(st.one_of(st.sampled_from(sorted(ERROR_TYPES)), st.text(max_size=6)), max_size=4))
    item = st.one_of(NUMBERS, st.dictionaries(st.one_of(st.sampled_from(INSTANCE_KEYS), st.text(max_size=4)),
                                              st.one_of(st.integers(-2, 45), NUMBERS, SCALARS), max_size=4))
    spec = st.one_of(item, st.lists(item, max_size=4), st.lists(st.floats(-20, 20), min_size=40, max_size=40), VALUE)
    return {k: draw(spec) for k in keys}


@st.composite
def case_dicts(draw) -> dict:
    d = {}
    for k, strat in (("name", st.one_of(st.text(max_size=10), VALUE)), ("design", st.one_of(design_dicts(), VALUE)),
                     ("errors", st.one_of(error_dicts(), VALUE)), ("load_Nm", st.one_of(st.floats(-5, 3e4), VALUE)),
                     ("direction", st.one_of(st.sampled_from([1, -1, 0, 1.0, True]), VALUE)),
                     ("model", st.one_of(st.dictionaries(st.text(max_size=12), NUMBERS, max_size=3), VALUE)),
                     (draw(st.text(max_size=5)), VALUE)):
        if draw(st.booleans()):
            d[k] = draw(strat)
    return d


def _dump(obj) -> str:
    try:
        return json.dumps(obj, allow_nan=True)
    except (ValueError, OverflowError):  # an integer too long for json.dumps' str(): another literal
        return "1" * 5000


@st.composite
def case_texts(draw) -> str:
    kind = draw(st.integers(0, 3))
    if kind == 0:
        return _dump(draw(case_dicts()))
    if kind == 1:
        text = _dump(draw(case_dicts()))
        cut = draw(st.integers(0, len(text)))
        return text[:cut] + draw(st.text(max_size=5)) + text[cut:]
    if kind == 2:  # a repeated key at the top level or inside design
        key = draw(st.sampled_from(["design", "errors", "name"]))
        return '{"%s": {}, "%s": {}}' % (key, key) if key != "name" else '{"name": "a", "name": "b"}'
    return draw(st.text(max_size=40))


@pytest.fixture(scope="module")
def scratch():
    with tempfile.TemporaryDirectory() as d:
        yield Path(d)


def _only_input_errors(fn, *args):
    try:
        fn(*args)
    except InputError:
        pass


@fuzz(100)
@given(d=design_dicts())
def test_fuzz_design_from_dict(d: dict) -> None:
    _only_input_errors(Design.from_dict, d)


@fuzz(100)
@given(e=error_dicts())
def test_fuzz_parse_errors(e: dict) -> None:
    _only_input_errors(parse_errors, e, Design())


@fuzz(100)
@given(d=case_dicts())
def test_fuzz_case_from_dict(d: dict) -> None:
    _only_input_errors(Case.from_dict, d)


@fuzz(80)
@given(text=case_texts())
def test_fuzz_load_case_text(scratch: Path, text: str) -> None:
    p = scratch / "case.json"
    p.write_bytes(text.encode("utf-8", errors="surrogatepass"))
    _only_input_errors(load_case, p)


# ------------------------------------------------------------------------- tables (study layer)
CELL = st.one_of(st.sampled_from(["", "nan", "inf", "-1", "0", "1", "5", "1e9", "x", "normal", "uniform",
                                  "triangular", "fixed", "none", "pin_pitch", "pin_radius", "EA", "um", "deg",
                                  '"', "a,b", "pin_radius[all]", "pin_pitch[odd]"]),
                 st.text(alphabet=st.characters(blacklist_categories=("Cs",)), max_size=6),
                 st.floats(-2000, 2000).map(str))


@st.composite
def csv_texts(draw, columns: list[str]) -> str:
    cols = draw(st.lists(st.one_of(st.sampled_from(columns), st.text(max_size=4)), min_size=0, max_size=7))
    rows = draw(st.lists(st.lists(CELL, min_size=len(cols), max_size=len(cols) + 1), max_size=6))
    lines = [",".join(cols)] + [",".join(r) for r in rows]
    text = "\n".join(lines)
    if draw(st.integers(0, 9)) == 0:
        text = draw(st.text(max_size=30))
    return text


@fuzz(60)
@given(text=csv_texts(["error", "dist", "p1", "p2", "p3"]), as_json=st.booleans())
def test_fuzz_tolerance_tables(scratch: Path, text: str, as_json: bool) -> None:
    from rvstudy.montecarlo import load_tolerances, parse_tolerance

    p = scratch / ("tol.json" if as_json else "tol.csv")
    p.write_bytes(text.encode("utf-8", errors="surrogatepass"))
    _only_input_errors(load_tolerances, p)
    _only_input_errors(parse_tolerance, text.replace("\n", ":"))


@fuzz(60)
@given(text=csv_texts(["factor", "low", "center", "high", "unit", "error"]))
def test_fuzz_levels_table(scratch: Path, text: str) -> None:
    from rvstudy.study import load_factors

    p = scratch / "levels.csv"
    p.write_bytes(text.encode("utf-8", errors="surrogatepass"))
    _only_input_errors(load_factors, str(p), None)


# ------------------------------------------------------------------------- measured datasets
RUN_COLS = ["run", "load_Nm", "direction", "temperature_C", "speed_rpm", "pin_radius", "pin_pitch"]


@st.composite
def dataset_texts(draw) -> tuple[str, str]:
    runs = draw(csv_texts(RUN_COLS))
    if draw(st.booleans()):
        # a plausible record: one output revolution of a given length, with a perturbation
        ratio = Design().ratio
        n = draw(st.integers(2, 60))
        revs = draw(st.sampled_from([0.5, 1.0, 1.5, 2.0]))
        direction = draw(st.sampled_from([1, -1]))
        scale = draw(st.sampled_from([1.0, 3.141592653589793 / 180, 180 / 3.141592653589793]))
        lines = ["run,input_deg,output_deg"]
        for i in range(n):
            x = direction * i * revs * ratio * 360.0 / n
            lines.append(f"{draw(st.sampled_from(['1', 'a']))},{x},{scale * x / ratio}")
        if draw(st.booleans()):
            lines.insert(draw(st.integers(1, len(lines))), ",".join(draw(st.lists(CELL, min_size=3, max_size=3))))
        samples = "\n".join(lines)
        runs = "run,load_Nm,direction\n1,20,%d" % direction if draw(st.booleans()) else runs
    else:
        samples = draw(csv_texts(["run", "input_deg", "output_deg", "time_s"]))
    return runs, samples


@fuzz(60)
@given(texts=dataset_texts())
def test_fuzz_measured_dataset(scratch: Path, texts: tuple[str, str]) -> None:
    from rvrig.dataset import read_dataset

    root = scratch / "ds"
    root.mkdir(exist_ok=True)
    (root / "runs.csv").write_bytes(texts[0].encode("utf-8", errors="surrogatepass"))
    (root / "samples.csv").write_bytes(texts[1].encode("utf-8", errors="surrogatepass"))
    _only_input_errors(read_dataset, root)
