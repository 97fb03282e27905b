"""Figures are written as non-blank PNGs (Agg canvas, no pyplot state)."""

from __future__ import annotations

from pathlib import Path

import matplotlib.image as mpimg
import numpy as np
import pandas as pd
import pytest

import rsm
from rsm import plots
from rvpaper import DATA_DIR as PAPER_DATA

DATA = PAPER_DATA
FACTORS = ["EA", "EB", "EC", "ED"]


@pytest.fixture(scope="module")
def paper_fit() -> rsm.RSMResults:
    return rsm.fit(pd.read_csv(DATA / "paper_table6_bbd_runs.csv"), FACTORS, "te_arcmin",
                   levels=DATA / "paper_table5_levels.csv")


def _check_png(path: Path, min_px: int = 250) -> np.ndarray:
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    img = mpimg.imread(path)
    assert img.shape[0] >= min_px and img.shape[1] >= min_px
    assert float(np.std(img[..., :3])) > 0.02  # not a blank canvas
    return img


@pytest.fixture(scope="module")
def rendered(paper_fit, tmp_path_factory) -> list[Path]:
    hold = pd.read_csv(DATA / "paper_table6_bbd_runs.csv").iloc[::4]
    return plots.plot_all(paper_fit, tmp_path_factory.mktemp("figs"), validation=hold, dpi=72)


def test_surfaces_for_every_pair(rendered):
    surf = [p for p in rendered if p.name.startswith("surface_")]
    assert sorted(p.name for p in surf) == sorted(
        f"surface_{a}_{b}.png" for a, b in [("EA", "EB"), ("EA", "EC"), ("EA", "ED"), ("EB", "EC"),
                                            ("EB", "ED"), ("EC", "ED")])
    for p in surf:
        img = _check_png(p)
        assert img.shape[1] > img.shape[0]  # surface and contour side by side


def test_predicted_vs_observed_and_residuals(rendered):
    names = [p.name for p in rendered]
    assert len(rendered) == 8 and names[-2:] == ["predicted_vs_observed.png", "residuals.png"]
    for p in rendered[-2:]:
        _check_png(p)


def test_plot_bad_factor(paper_fit, tmp_path):
    with pytest.raises(ValueError, match="factor 'EZ' is not in the model"):
        plots.plot_surface_pair(paper_fit, "EA", "EZ", tmp_path / "x.png")
