"""Laplace's intervals widened through the model (rvcalib.regions), against closed forms."""
from __future__ import annotations

import math
import re
from types import SimpleNamespace

import numpy as np
import pytest
from scipy import optimize

from rvcalib.gaussian import Posterior, rise_function
from rvcalib.regions import BISECTIONS, widen, widener
from rvcalib.result import named_effect

SIGMA = 0.05
T = np.linspace(0.0, 1.0, 60, endpoint=False)
G = SIGMA * math.sqrt(2.5 / 30.0) * np.cos(2 * np.pi * T)          # |g|^2 / sigma^2 = 2.5
H = SIGMA * np.sin(2 * np.pi * T)                                  # |h|^2 / sigma^2 = 30


def _cand(name, polar=False, n=1):
    size = (lambda v: (float(np.hypot(*v)), float(np.degrees(np.arctan2(v[1], v[0]))))) if polar else \
        (lambda v: (float(v[0]), None))
    return SimpleNamespace(effect_name=name, key=name, family="table4", instance=(), unit="um", meaning="",
                           polar=polar, n_params=n, lower=-50.0, upper=50.0, size=size)


def _problem(te, n, x0):
    """The MAP, its Laplace posterior and the rise function of ``y = te(truth)`` (noise-free, sigma 0.05, prior
    scale 10 on each parameter)."""
    y = te(np.ones(n))
    sd = np.full(n, 10.0)
    pb = SimpleNamespace(proj=lambda v: v, y=y, R=np.zeros((T.size, 0)), tests=[])
    model = SimpleNamespace(n_params=n, _lower=np.full(n, -50.0), _upper=np.full(n, 50.0), te=te)
    x = optimize.least_squares(lambda th: np.concatenate([(y - te(th)) / SIGMA, th / sd]), x0,
                               xtol=1e-14, ftol=1e-14).x
    J = np.column_stack([(te(x + 1e-6 * e) - te(x - 1e-6 * e)) / 2e-6 for e in np.eye(n)])     # central
    C = np.linalg.inv(J.T @ J / SIGMA ** 2 + np.diag(1 / sd ** 2))
    post = Posterior(np.arange(n), x, C)
    return pb, post, rise_function(pb, model, np.zeros(0, dtype=int), sd, post, te(x), SIGMA)


def test_an_interval_the_tangent_makes_too_narrow_reaches_the_profile():
    """``y = a^3 g + b h`` at a = b = 1: the criterion in a is ``2.5 (a^3 - 1)^2`` (plus the prior's 0.01 a^2),
    which reaches the chi-square quantile 3.84 at a = -0.621 below the MAP, where Laplace's interval (the tangent
    3 g) ends at 0.587. The widened lower end lies within one bisection step inside -0.621; the upper end, where
    the tangent's interval is already wider than the profile's, is kept (an interval is never narrowed); b, linear,
    keeps Laplace's interval."""
    pb, post, rise = _problem(lambda th: th[0] ** 3 * G + th[1] * H, 2, [0.5, 0.5])
    a = named_effect(_cand("a"), 1.0, post.mean[:1], post.cov[:1, :1], 0.95)
    b = named_effect(_cand("b"), 1.0, post.mean[1:], post.cov[1:, 1:], 0.95)
    assert a.ci95[0] == pytest.approx(0.587, abs=0.01) and a.ci95[1] == pytest.approx(1.413, abs=0.01)
    profile = optimize.brentq(lambda v: rise(np.array([0]), np.array([v])) - 3.841459, -2.0, 0.5)
    assert profile == pytest.approx(-0.621, abs=0.005)
    wide, n = widen(a, _cand("a"), np.array([0]), post.mean[:1], rise, 0.95)
    step = (a.ci95[0] - post.mean[0]) * 2 ** 2 / 2 ** BISECTIONS        # the bracket after two doublings
    assert profile <= wide.ci95[0] <= profile + abs(step)
    assert wide.ci95[1] == a.ci95[1] and n > 2
    same, _ = widen(b, _cand("b"), np.array([1]), post.mean[1:], rise, 0.95)
    assert same.ci95 == b.ci95


def test_a_polar_size_widens_along_its_direction_and_not_below_zero():
    """``y = (p^2 + q^2) g + (p + q) h / 10`` (the size enters squared in g): along the direction of (p, q) the
    criterion rises more slowly toward zero than the tangent at the MAP says, so the size's lower end moves down,
    never below zero; the angle is kept."""
    def te(th):
        return (th[0] ** 2 + th[1] ** 2) * G + 0.1 * (th[0] + th[1]) * H

    pb, post, rise = _problem(te, 2, [0.8, 0.8])
    c = _cand("p", polar=True, n=2)
    eff = named_effect(c, 1.0, post.mean, post.cov, 0.95)
    wide, _ = widen(eff, c, np.array([0, 1]), post.mean, rise, 0.95)
    assert 0.0 <= wide.ci95[0] < eff.ci95[0] and wide.ci95[1] >= eff.ci95[1]
    assert wide.angle_deg == eff.angle_deg
    assert rise(np.array([0, 1]), post.mean * wide.ci95[0] / eff.value) < 3.841459


def test_the_widener_says_which_interval_moved():
    pb, post, rise = _problem(lambda th: th[0] ** 3 * G + th[1] * H, 2, [0.5, 0.5])
    named = [named_effect(_cand(n), 1.0, post.mean[i:i + 1], post.cov[i:i + 1, i:i + 1], 0.95)
             for i, n in enumerate("ab")]
    notes, lines = [], []
    widen = widener(post, rise, 0.95, notes.append, lines.append)
    out = [widen(eff, _cand(eff.name), [i]) for i, eff in enumerate(named)]
    assert out[0].ci95[0] < named[0].ci95[0] and out[1] == named[1]
    assert len(notes) == 1 and notes[0].startswith("the interval of a is widened through the model from [0.58")
    assert [re.fullmatch(r"(\w): its interval through the model in \d+ model evaluations", x).group(1)
            for x in lines] == ["a", "b"]


def test_read_named_gives_the_widened_interval():
    """The estimator's reading of the named effects passes each through ``widen`` with its posterior positions."""
    from rvcalib.gaussian import read_named

    pb, post, rise = _problem(lambda th: th[0] ** 3 * G + th[1] * H, 2, [0.5, 0.5])
    pb.feature_cands, pb.starts, pb.fixed = [[_cand("a")], [_cand("b")]], np.arange(3), ()
    pb.empirical = np.zeros(2, dtype=bool)
    seen = []

    def widen(eff, cand, positions):
        seen.append((eff.name, cand.effect_name, list(positions)))
        return eff

    named, _ = read_named(pb, post, 0.95, None, widen)
    assert sorted(e.name for e in named) == ["a", "b"]
    assert sorted(seen) == [("a", "a", [0]), ("b", "b", [1])]
