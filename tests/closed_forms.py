"""Closed forms shared by several test files (derivations in docs/physics.md)."""
from __future__ import annotations

import math

import numpy as np

from rvcad.geometry import ReducerGeometry


def pin_levers(geom: ReducerGeometry, theta_in: np.ndarray) -> np.ndarray:
    """Closed-form lever lam_i = (i Z1/Z2) e (n_i . u'(psi + k pi - theta_out)) of every pin at the ideal
    pose, mm, shape (steps, discs, pins).

    With the input held and stage I rigid, turning the output by dtheta turns the crank by
    (1 + Z1/Z2) dtheta; subtracting the conjugate motion (dpsi = -Zc dtheta, no gap change) leaves a
    pure crank turn of (i Z1/Z2) dtheta, which moves each disc by e u'(psi + k pi) per radian, so the
    gap of pin i changes by -lam_i dtheta. A common clearance dr is taken up at the largest lever:
    TE = -dr / max(lam). Since |n . u'| <= 1, max(lam) <= e i Z1/Z2.
    """
    d = geom.design
    to, ps = geom.ideal_state(theta_in)
    _, nrm, _, _ = geom.pin_gaps(to, ps)  # normals in the profile frames (= fixed frame rotated by theta_out)
    lam = np.empty(nrm.shape[:-1])
    for k in range(d.n_discs):
        a = ps[:, 0] + k * math.pi - to  # u' expressed in the disc frame
        up = np.stack([-np.sin(a), np.cos(a)], -1)
        lam[:, k] = d.ratio * d.z_sun / d.z_planet * d.eccentricity_mm * np.einsum("nzi,ni->nz", nrm[:, k], up)
    return lam


def disc_offset_gaps(geom: ReducerGeometry, theta_in: np.ndarray, shift: np.ndarray, turn: np.ndarray) -> np.ndarray:
    """Closed-form change of every pin gap (steps, discs, pins), mm, when each disc is moved from its ideal pose by
    ``shift`` (steps, discs, 2) mm (fixed frame) and turned by ``turn`` (steps, discs) rad, to first order.

    A translation s changes the gap of pin i by ``n_i . s`` (n_i the disc's outward normal at the pin's foot
    point). A turn dphi is the conjugate motion (turn dphi with the translation ``-Zc e dphi u'(psi + k pi)``,
    which changes no gap) plus the translation ``Zc e dphi u'(psi + k pi)``, so it changes the gaps by
    ``Zc e dphi (n_i . u'(psi + k pi))``. Signs as :func:`pin_levers`: a gap is ``dr + lam_i x + dg_i`` after an
    output turn x (docs/physics.md, section 6).
    """
    d = geom.design
    to, ps = geom.ideal_state(theta_in)
    _, nrm, _, _ = geom.pin_gaps(to, ps)          # profile frames (= fixed frame turned by theta_out)
    c, s = np.cos(to)[:, None], np.sin(to)[:, None]
    sx = c * shift[..., 0] + s * shift[..., 1]    # the shift in the disc frames
    sy = -s * shift[..., 0] + c * shift[..., 1]
    dg = np.empty(nrm.shape[:-1])
    for k in range(d.n_discs):
        a = ps[:, 0] + k * math.pi - to
        t = d.z_disc * d.eccentricity_mm * turn[:, k]
        dg[:, k] = (nrm[:, k, :, 0] * (sx[:, k, None] - t[:, None] * np.sin(a)[:, None])
                    + nrm[:, k, :, 1] * (sy[:, k, None] + t[:, None] * np.cos(a)[:, None]))
    return dg


def first_contact_te(lam: np.ndarray, dg: np.ndarray, dr: float, direction: int) -> np.ndarray:
    """Output angle (rad) of the rigid single-flank limit per step: the output turns against the load until the
    first pin closes its gap ``dr + lam_i x + dg_i`` (lam, dg (steps, discs, pins), dr mm: the uniform pin
    clearance). Direction +1 turns it back (the pins with lam > 0 close), -1 forward."""
    x = np.divide(-(dr + dg), lam, out=np.zeros_like(lam), where=lam != 0.0)
    if direction == 1:
        return np.where(lam > 0, x, -np.inf).max(axis=(1, 2))
    return np.where(lam < 0, x, np.inf).min(axis=(1, 2))


def free_crank_te(X: np.ndarray, c: np.ndarray, play: tuple[float, float], direction: int) -> np.ndarray:
    """Rigid single-flank output angle (rad) per step when one crank may turn within a play of its stage I mesh.

    ``X`` (steps, discs): each disc's first-contact output angle with the crank at its kinematic angle
    (:func:`first_contact_te` of one disc); turning the crank by y relative to it moves disc k as an output turn
    of ``c_k y`` would (``c`` (steps, discs), :func:`crank_turn_equivalent`), so disc k closes at ``X_k - c_k y``
    and the output stops at the first disc to close. The crank turns within ``play = (lo, hi)`` rad to where the
    load takes the output furthest: ``min_y max_k`` (direction +1) or ``max_y min_k`` (-1) of ``X_k - c_k y``,
    a piecewise-linear function of y whose extremum lies at a bound of the play or where two discs close
    together."""
    lo, hi = play
    cand = [np.full(X.shape[0], lo), np.full(X.shape[0], hi)]
    with np.errstate(divide="ignore", invalid="ignore"):
        cross = (X[:, 0] - X[:, 1]) / (c[:, 0] - c[:, 1])
    cand.append(np.clip(np.nan_to_num(cross, nan=lo, posinf=hi, neginf=lo), lo, hi))
    vals = [(X - c * y[:, None]).max(axis=1) if direction == 1 else (X - c * y[:, None]).min(axis=1) for y in cand]
    return np.min(vals, axis=0) if direction == 1 else np.max(vals, axis=0)


def crank_turn_equivalent(geom: ReducerGeometry, theta_in: np.ndarray, crank: int) -> np.ndarray:
    """``c_k`` (steps, discs): the output turn (rad) that moves disc k as a turn of crank ``crank`` by 1 rad
    relative to its kinematic angle does, with the disc's pose the least-squares fit of its n holes to its cams.

    The cam of disc k moves by ``e y u'(chi_k)`` (chi_k = psi + k pi): the fit moves the disc by ``e y u'/n``
    and turns it by ``e y cos(chi_k - beta_j - theta_out)/(n a)`` (the cam's offset across the hole arm
    ``a u(beta_j + theta_out)``, over ``sum |h|^2 = n a^2``). A translation ``s u'`` is the output turn
    ``s/(e i Z1/Z2)`` (docs/physics.md, section 6); a turn dphi the translation ``Zc e dphi u'``, so
    ``c_k = (1 + (Zc e / a) cos(chi_k - beta_j - theta_out)) / (n i Z1/Z2)``."""
    d = geom.design
    to, ps = geom.ideal_state(theta_in)
    k2 = d.ratio * d.z_sun / d.z_planet
    beta = geom.crank_angles[crank]
    n, e, a = d.n_cranks, d.eccentricity_mm, d.center_distance_mm
    cos = np.stack([np.cos(ps[:, crank] + k * math.pi - beta - to) for k in range(d.n_discs)], axis=1)
    return (1.0 + d.z_disc * e / a * cos) / (n * k2)
