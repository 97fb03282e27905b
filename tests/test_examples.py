"""Every script in examples/ runs with its small settings and writes its figure (a PNG a person can open)."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = sorted((ROOT / "examples").glob("*.py"))
#: Files an example writes besides its figure.
ALSO_WRITES = {"perturbed_parts": ["disc0.step", "disc0.stl"], "calibrate_loop": ["record/runs.csv", "record/samples.csv"]}


def test_there_are_at_least_five_examples_each_with_a_small_setting_and_a_run_line():
    assert len(EXAMPLES) >= 5
    for p in EXAMPLES:
        text = p.read_text(encoding="utf-8")
        assert '"--small"' in text and f"python examples/{p.name}" in text, p.name


@pytest.mark.slow
@pytest.mark.parametrize("script", EXAMPLES, ids=[p.stem for p in EXAMPLES])
def test_example_writes_its_figure(script, tmp_path):
    from matplotlib.image import imread

    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]),
           "MPLBACKEND": "Agg"}
    done = subprocess.run([sys.executable, str(script), "--small", "--out", str(tmp_path / "out")], cwd=tmp_path,
                          env=env, capture_output=True, text=True, timeout=1200)
    assert done.returncode == 0, done.stderr[-3000:]
    png = tmp_path / "out" / f"{script.stem}.png"
    assert f"wrote {png}" in done.stdout
    img = imread(png)
    assert img.shape[0] > 200 and img.shape[1] > 400 and img.std() > 0.01  # a drawn figure, not a blank canvas
    for name in ALSO_WRITES.get(script.stem, []):
        assert (tmp_path / "out" / name).stat().st_size > 0, name
    assert [p.name for p in tmp_path.iterdir()] == ["out"]  # nothing written beside the output folder
