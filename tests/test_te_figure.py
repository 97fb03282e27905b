"""The stack-up report's TE figure (rvstudy.te_figure): order spectrum against closed forms, and the figure's
rows, panels and shared axes."""
from __future__ import annotations

import numpy as np
import pytest

from rvstudy.te_figure import order_spectrum, plot_te_figure, te_figure

N = 360
THETA = np.arange(N) * 2.0 * np.pi / N  # output angle, one revolution


def test_order_spectrum_gives_each_cosine_its_amplitude():
    te = -9.0 + 3.0 * np.cos(40 * THETA + 0.3) + 0.5 * np.sin(THETA) + 0.02 * np.cos(121 * THETA)
    orders, amp = order_spectrum(te)
    assert orders[0] == 1 and orders[-1] == N // 2 and amp.shape == orders.shape
    expect = np.zeros(N // 2)
    expect[[39, 0, 120]] = [3.0, 0.5, 0.02]
    np.testing.assert_allclose(amp, expect, atol=1e-12)  # the mean (an offset) is no order
    nyq = order_spectrum(np.cos(np.pi * np.arange(8)))[1]  # +1, -1, ...: order 4 of 8 samples, amplitude 1
    np.testing.assert_allclose(nyq, [0, 0, 0, 1.0], atol=1e-12)


@pytest.mark.parametrize("bad, match", [(np.ones(3), "at least 4"), (np.array([0, 1, np.nan, 2.0]), "finite"),
                                        (np.ones((2, 4)), "1-D")])
def test_order_spectrum_refuses_what_is_not_one_curve(bad, match):
    with pytest.raises(ValueError, match=match):
        order_spectrum(bad)


def test_figure_rows_panels_and_shared_axes(tmp_path):
    curves = {"screen-A": np.zeros(N), "screen-D+": 5.0 * np.cos(40 * THETA) - 16.0,
              "screen-D-": -5.0 * np.cos(40 * THETA) + 3.0}
    fig = te_figure(curves, crank_order=40, titles={"screen-D": "D cam_phase"})
    axes = np.array(fig.axes).reshape(2, 3)  # rows A and D; revolution, zoom, spectrum
    rev, zoom, spec = axes[1]
    assert rev.get_title(loc="left").startswith("D cam_phase") and "pp 9.7\"" in rev.get_title(loc="left")  # 5 (1 + cos(pi/9)): 9 samples a period
    x, y = rev.lines[0].get_data()
    np.testing.assert_allclose(y, 5.0 * np.cos(40 * THETA))  # mean removed, one line per case
    assert len(rev.lines) == 2 and x[-1] < 360.0
    assert zoom.get_xlim() == (0.0, 9.0) and zoom.lines[0].get_xdata().max() <= 9.0  # one crank period
    assert spec.get_yscale() == "log" and spec.get_xlim() == (0.0, N // 2)
    stems = spec.collections[0].get_segments()
    assert max(seg[1][1] for seg in stems) == pytest.approx(5.0)
    assert axes[0, 0].get_shared_y_axes().joined(axes[0, 0], zoom)  # rows and both curve columns compare
    assert axes[0, 2].get_shared_x_axes().joined(axes[0, 2], spec)
    path = plot_te_figure(curves, tmp_path / "te.png")
    assert path.stat().st_size > 0 and [p.name for p in tmp_path.iterdir()] == ["te.png"]


@pytest.mark.parametrize("kw, match", [({"curves": {}}, "curves is empty"),
                                       ({"crank_order": 0}, "crank_order 0")])
def test_figure_bad_input_names_the_field(kw, match):
    args = {"curves": {"a": np.zeros(8)}, **kw}
    with pytest.raises(ValueError, match=match):
        te_figure(**args)
