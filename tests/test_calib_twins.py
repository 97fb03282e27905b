"""The swap test (rvcalib.twins) on a small nonlinear stand-in: two candidates that give the same TE are twins,
one whose TE differs by more than the noise allows is not, and the reading coefficients are refitted in a swap."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from rvcalib.library import Candidate
from rvcalib.loop import Projector
from rvcalib.result import twin_group
from rvcalib.twins import DELTA_CHI2, swap_twins

N = 200
PHI = np.linspace(0.0, 2.0 * np.pi, N, endpoint=False)


class KinkedModel:
    """te(theta) = sum_j shape_j * max(theta_j, 0): a pin that acts only when pushed in (a kink at zero)."""

    def __init__(self, shapes: np.ndarray) -> None:
        self.shapes = shapes
        self.n_params = shapes.shape[1]
        self._lower = np.zeros(self.n_params)
        self._upper = np.full(self.n_params, 10.0)
        self.calls = 0

    def te(self, theta: np.ndarray) -> np.ndarray:
        self.calls += 1
        return self.shapes @ np.maximum(theta, 0.0)


def _problem(shapes: np.ndarray, theta_true: np.ndarray, sigma: float, R: np.ndarray | None = None,
             b_true: np.ndarray | None = None, seed: int = 5):
    rng = np.random.default_rng(seed)
    model = KinkedModel(shapes)
    R = np.zeros((N, 0)) if R is None else R
    y = model.te(theta_true) + (R @ b_true if b_true is not None else 0.0) + rng.normal(0.0, sigma, N) + 3.0
    p = shapes.shape[1]
    return SimpleNamespace(model=model, y=y, proj=Projector(np.ones((N, 1))), R=R,
                           feature_cands=[[f"c{j}"] for j in range(p + R.shape[1])],
                           starts=np.arange(p + R.shape[1] + 1), fixed=())


def test_two_candidates_with_the_same_te_are_twins_and_a_different_one_is_not():
    a = np.cos(3 * PHI) + 0.3 * np.sin(7 * PHI)
    near = a + 0.02 * np.cos(11 * PHI)              # alike to 0.99 in shape, but told apart by 400 readings
    shapes = np.column_stack([a, a, near, np.sin(2 * PHI)])
    pb = _problem(shapes, np.array([2.0, 0.0, 0.0, 0.0]), sigma=0.05)
    X0 = pb.proj(shapes)
    got = swap_twins(pb, X0, np.array([2.0, 0.0, 0.0, 0.0]), 0.05, np.array([0]), np.zeros(0, int))
    assert list(got) == [0]
    assert [g for g, *_ in got[0]] == [1]                   # the exact twin; not the near one, not the other order
    assert got[0][0][1] == pytest.approx(0.0, abs=1e-9)
    chi_near = float(np.sum(pb.proj(0.02 * 2.0 * np.cos(11 * PHI)) ** 2)) / 0.05 ** 2
    assert chi_near > DELTA_CHI2                            # why the near one is not a twin: it fits worse


def test_a_swap_refits_the_reading_coefficients_and_leaves_the_model_at_the_estimate():
    a = np.cos(3 * PHI)
    shapes = np.column_stack([a, a + 0.1 * np.sin(PHI)])    # differ by an order-1 term a reading column holds
    R = np.column_stack([np.sin(PHI)])
    pb = _problem(shapes, np.array([1.0, 0.0]), sigma=0.05, R=R, b_true=np.array([0.8]))
    theta = np.array([1.0, 0.0])
    got = swap_twins(pb, pb.proj(np.column_stack([shapes, R])), theta, 0.05, np.array([0]), np.array([0]))
    assert [g for g, *_ in got[0]] == [1]                   # the reading coefficient takes the difference
    assert np.allclose(pb.model.te(theta), shapes @ theta)
    plain = _problem(shapes, theta, sigma=0.05)             # no reading column: the order-1 term tells them apart
    assert swap_twins(plain, plain.proj(shapes), theta, 0.05, np.array([0]), np.zeros(0, int)) == {}


def test_a_twin_of_the_opposite_sign_is_found_at_its_own_size():
    """A candidate whose TE is the named one's with the opposite sign and half the scale (a crank-indexed error
    and the same error on the opposite crank of a two-crank reducer are such look-alikes to first order): its swap
    size is minus twice the named size, and it is a twin."""
    a = np.cos(3 * PHI) + 0.3 * np.sin(7 * PHI)
    shapes = np.column_stack([a, -0.5 * a, np.sin(2 * PHI)])
    model = np.column_stack([a, -0.5 * a, np.sin(2 * PHI)])
    pb = _problem(shapes, np.array([2.0, 0.0, 0.0]), sigma=0.05)
    pb.model = LinearModel(model)
    theta = np.array([2.0, 0.0, 0.0])
    got = swap_twins(pb, pb.proj(shapes), theta, 0.05, np.array([0]), np.zeros(0, int))
    assert [g for g, *_ in got[0]] == [1]
    assert got[0][0][2] == pytest.approx((-4.0,))
    assert got[0][0][1] == pytest.approx(0.0, abs=1e-9)


class LinearModel(KinkedModel):
    """te(theta) = shapes theta, both signs (a twin of the opposite sign needs a negative size)."""

    def __init__(self, shapes: np.ndarray) -> None:
        super().__init__(shapes)
        self._lower = np.full(self.n_params, -10.0)

    def te(self, theta: np.ndarray) -> np.ndarray:
        self.calls += 1
        return self.shapes @ theta


def test_a_partial_alias_with_another_chosen_parameter_refitted_is_a_twin():
    """The named candidate's TE is another's once a third chosen parameter moves (``a = (a - h / 2) + h / 2``):
    their columns are only 0.90 alike, so the first-linearisation screen misses them; the last linearisation's
    screen, which refits the other chosen parameters, admits the alias, and the swap moves the third parameter too.
    The three columns are linearly dependent, so the third is as much the alias's twin as the first."""
    a = np.cos(3 * PHI) + 0.3 * np.sin(7 * PHI)
    h = np.sin(2 * PHI)
    shapes = np.column_stack([a, a - 0.5 * h, h, np.cos(5 * PHI)])
    pb = _problem(shapes, np.array([2.0, 0.0, 1.0, 0.0]), sigma=0.05)
    pb.model = LinearModel(shapes)
    theta = np.array([2.0, 0.0, 1.0, 0.0])
    X = pb.proj(shapes)
    corr = abs(X[:, 0] @ X[:, 1]) / np.linalg.norm(X[:, 0]) / np.linalg.norm(X[:, 1])
    assert 0.85 < corr < 0.95
    assert swap_twins(pb, X, theta, 0.05, np.array([0, 2]), np.zeros(0, int)) == {}
    got = swap_twins(pb, X, theta, 0.05, np.array([0, 2]), np.zeros(0, int), X_last=X)
    assert [g for g, *_ in got[0]] == [1]
    assert got[0][0][2] == pytest.approx((2.0,))
    assert got[0][0][1] == pytest.approx(0.0, abs=1e-6)
    assert [g for g, *_ in got[2]] == [1]                   # three dependent columns: h = 2 a - 2 (a - h / 2)
    assert got[2][0][2] == pytest.approx((-2.0,))
    assert np.allclose(pb.model.te(theta), shapes @ theta)


class CoupledModel(LinearModel):
    """te(theta) = shapes theta + q (theta_0 theta_2 + theta_1 theta_3): two pairs of look-alikes (0, 1) and
    (2, 3) whose members interact within their arrangement, as a pin and a cam share the load of their crank."""

    def __init__(self, shapes: np.ndarray, q: np.ndarray) -> None:
        super().__init__(shapes)
        self.q = q

    def te(self, theta: np.ndarray) -> np.ndarray:
        return super().te(theta) + self.q * (theta[0] * theta[2] + theta[1] * theta[3])


def test_look_alikes_that_fit_only_moved_together_are_twins():
    """Each of two chosen effects moved alone to its look-alike loses their interaction and fits worse; both moved
    together give the same TE, so each is a twin of its look-alike."""
    a, b, q = np.cos(3 * PHI), np.sin(7 * PHI), 0.5 * np.sin(5 * PHI)
    shapes = np.column_stack([a, a, b, b])
    pb = _problem(shapes, np.zeros(4), sigma=0.05)
    pb.model = CoupledModel(shapes, q)
    theta = np.array([2.0, 0.0, 1.5, 0.0])
    pb.y = pb.model.te(theta) + np.random.default_rng(3).normal(0.0, 0.05, N)
    alone = np.array([0.0, 2.0, 1.5, 0.0])                  # the first moved alone: the interaction is lost
    assert float(np.sum(pb.proj(pb.model.te(alone) - pb.model.te(theta)) ** 2)) / 0.05 ** 2 > 100 * DELTA_CHI2
    got = swap_twins(pb, pb.proj(shapes), theta, 0.05, np.array([0, 2]), np.zeros(0, int))
    assert {f: [g for g, *_ in t] for f, t in got.items()} == {0: [1], 2: [3]}
    assert got[0][0][2] == pytest.approx((2.0,)) and got[2][0][2] == pytest.approx((1.5,))
    assert got[0][0][1] == pytest.approx(0.0, abs=1e-6)
    assert np.allclose(pb.model.te(theta), shapes @ theta + q * 3.0)    # the model left at the estimate


def _two_component_problem(shapes: np.ndarray, widths: list, theta: np.ndarray):
    """A problem whose features have ``widths`` parameters each (an eccentricity has two)."""
    pb = _problem(shapes, theta, sigma=0.05)
    pb.model = LinearModel(shapes)
    pb.feature_cands = [[f"f{i}"] for i in range(len(widths))]
    pb.starts = np.concatenate([[0], np.cumsum(widths)])
    return pb


def test_an_eccentricity_and_its_image_on_the_other_crank_are_twins_with_their_own_direction():
    """Two components each: the second feature's columns are the first's with the opposite sign (a planet
    eccentricity and the same on the crank half a turn away, to first order); a third two-component feature holds
    the x column but not the y one. The twin's size is the named one's turned by 180 deg; the third is no twin."""
    ax, ay, b = np.cos(3 * PHI), np.sin(3 * PHI) + 0.2 * np.cos(7 * PHI), np.sin(2 * PHI)
    shapes = np.column_stack([ax, ay, -ax, -ay, ax, np.cos(9 * PHI), b])
    theta = np.array([2.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    pb = _two_component_problem(shapes, [2, 2, 2, 1], theta)
    got = swap_twins(pb, pb.proj(shapes), theta, 0.05, np.array([0, 1]), np.zeros(0, int))
    assert [g for g, *_ in got[0]] == [1]
    assert got[0][0][2] == pytest.approx((-2.0, -1.0))
    assert got[0][0][1] == pytest.approx(0.0, abs=1e-9)
    cands = [Candidate(f"e{i}", "planet_eccentricity", "table4", "um", "", ("x", "y")) for i in range(3)]
    eff = SimpleNamespace(value=float(np.hypot(2.0, 1.0)), angle_deg=float(np.degrees(np.arctan2(1.0, 2.0))),
                          ci95=(2.0, 2.5))
    members = twin_group(eff, cands, 0, got[0], 0.95)["members"]
    assert [m["value"] for m in members] == pytest.approx([np.hypot(2.0, 1.0)] * 2)
    assert members[1]["angle_deg"] == pytest.approx(members[0]["angle_deg"] - 180.0)
    assert [m["probability"] for m in members] == pytest.approx([0.5, 0.5])
