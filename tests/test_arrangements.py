"""The half-turn image of the crank-indexed errors and the one answer over several minima (rvcalib.arrangements)."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from scipy import stats

from rvcalib.arrangements import Minimum, combine, half_turn_image
from rvcalib.result import NamedEffect

CHI2_1 = float(stats.chi2.ppf(0.95, 1))                  # 3.841


def _cand(key, family="table4", n=1, **instance):
    return SimpleNamespace(key=key, family=family, n_params=n, instance=tuple(instance.items()))


def test_half_turn_image_moves_crank_errors_to_the_opposite_crank_with_the_sign_reversed():
    cands = [_cand("torsional_compliance_arcsec_per_Nm", family="model"),
             _cand("carrier_hole_eccentricity", crank=0), _cand("carrier_hole_eccentricity", crank=1),
             _cand("disc_hole_eccentricity", disc=1, hole=0), _cand("disc_hole_eccentricity", disc=1, hole=1),
             _cand("planet_eccentricity", n=2, crank=0), _cand("planet_eccentricity", n=2, crank=1),
             _cand("pin_pitch", pin=3)]
    theta = np.array([0.2, 7.0, 0.5, -3.0, 0.0, 1.0, 2.0, 0.0, 0.0, 0.004])
    image = half_turn_image(cands, theta, (0.0, 180.0))
    np.testing.assert_array_equal(image, [0.2, -0.5, -7.0, -0.0, 3.0, -0.0, -0.0, -1.0, -2.0, 0.004])
    np.testing.assert_array_equal(half_turn_image(cands, image, (0.0, 180.0)), theta)
    assert half_turn_image(cands, theta, (0.0, 120.0, 240.0)) is None
    four = [_cand("cam_phase", crank=c, disc=0) for c in range(4)]
    np.testing.assert_array_equal(half_turn_image(four, np.arange(1.0, 5.0), (90, 180, 270, 0)),
                                  [-3.0, -4.0, -1.0, -2.0])


def _effect(key, value, ci, **instance) -> NamedEffect:
    name = key + ("[" + ",".join(f"{k}={v}" for k, v in instance.items()) + "]" if instance else "")
    return NamedEffect(name, key, "table4", dict(instance), "um", value, None, [value], [[1.0]], list(ci), 1.0, "")


def _minimum(label, crit, named, sigma=0.2, stopped="converged") -> Minimum:
    return Minimum(label, np.zeros(1), np.zeros(0), np.zeros(3), sigma, stopped, named, [], [],
                   {"criterion": crit})


def _phi(m, sigma):
    """A criterion whose data part scales as 1/sigma^2 (the common noise matters)."""
    return m.extra["criterion"] * (0.2 / sigma) ** 2


def test_a_minimum_beyond_the_quantile_is_dropped_and_the_least_answers_alone():
    """Own end 1234.5, the image's end 1068.1 (a difference far above 3.84): the image's end answers, its effects
    and intervals as read there, whichever search found it."""
    own = _minimum("own start", 1234.5, [_effect("carrier_hole_eccentricity", -6.1, (-7.0, -5.2), crank=0)])
    img = _minimum("half-turn image", 1068.1, [_effect("carrier_hole_eccentricity", 5.6, (4.6, 6.6), crank=1)])
    ans = combine([own, img], _phi, 0.95)
    assert ans.best is img and ans.kept == [img]
    assert [(e.name, e.ci95) for e in ans.named] == [("carrier_hole_eccentricity[crank=1]", [4.6, 6.6])]
    assert ans.groups == []
    assert ans.criteria == pytest.approx([1234.5, 1068.1])


def test_minima_the_data_cannot_split_give_hulls_and_arrangement_groups():
    """Two ends 0.7 apart (below 3.84): an effect both name gets the least's value and the hull of both intervals;
    an error one end puts on crank 0 and the other on crank 1 is a group with both; an effect whose hull holds zero
    is a group, not a name."""
    both_a = _effect("sun_eccentricity", 2.1, (1.5, 2.7))
    both_b = _effect("sun_eccentricity", 2.4, (1.9, 3.1))
    flip_a = _effect("carrier_hole_eccentricity", -6.1, (-7.0, -5.2), crank=0)
    flip_b = _effect("carrier_hole_eccentricity", 5.6, (4.6, 6.6), crank=1)
    sign_a = _effect("cam_phase", 0.8, (0.1, 1.5), crank=0, disc=0)
    sign_b = _effect("cam_phase", -0.5, (-0.9, -0.1), crank=0, disc=0)
    own = _minimum("own start", 1229.2, [both_a, flip_a, sign_a])
    img = _minimum("half-turn image", 1229.9, [both_b, flip_b, sign_b])
    ans = combine([own, img], _phi, 0.95)
    assert ans.best is own and ans.kept == [own, img]
    assert [(e.name, e.value, e.ci95) for e in ans.named] == [("sun_eccentricity", 2.1, [1.5, 3.1])]
    by_key = {g["members"][0]["key"]: g for g in ans.groups}
    assert set(by_key) == {"carrier_hole_eccentricity", "cam_phase"}
    assert all(g["kind"] == "arrangement" for g in ans.groups)
    flips = by_key["carrier_hole_eccentricity"]["members"]
    assert [(m["instance"], m["value"], m["minimum"]) for m in flips] == \
        [({"crank": 0}, -6.1, "own start"), ({"crank": 1}, 5.6, "half-turn image")]
    assert any("2 minima are within the chi-square quantile 3.84" in n for n in ans.notes), ans.notes


def test_minima_are_compared_at_the_larger_noise():
    """At 0.2 arcsec the ends differ by 5 (split); at the larger noise of 0.25 by 3.2 (not split): the comparison
    is made at the larger, so a difference is not read finer than the noisier fit allows."""
    own = _minimum("own start", 100.0, [_effect("sun_eccentricity", 2.1, (1.5, 2.7))], sigma=0.2)
    img = _minimum("half-turn image", 105.0, [], sigma=0.25)
    ans = combine([own, img], _phi, 0.95)
    assert ans.criteria == pytest.approx([64.0, 67.2])
    assert len(ans.kept) == 2 and ans.named == [] and len(ans.groups) == 1
    assert combine([own, _minimum("half-turn image", 105.0, [], sigma=0.2)], _phi, 0.95).named[0].ci95 == [1.5, 2.7]
