"""Candidate terms for augmenting a response surface: the libraries, kept apart from the selection rule.

A :class:`CandidateTerm` is one column that may be added to a fitted model, written in rsm's term
syntax (:mod:`rsm.terms`). Two libraries build them; :mod:`rsm.augment` tests them and its
:class:`rsm.augment.SelectionRule` decides, without knowing where a candidate came from beyond
its ``kind``:

* :func:`polynomial_candidates` -- higher-order polynomial terms of the factors: ``Xi^2:Xj``
  (curvature of one factor changing with another), ``Xi^2:Xj^2``, three-factor products
  ``Xi:Xj:Xk`` and cubes ``Xi^3``. In a three-level design ``Xi^3`` equals ``Xi`` at every run, and
  in a Box-Behnken design of four factors no run has three factors away from 0 at once; such terms
  are reported as not estimable, not silently dropped.
* :func:`pin_clearance_candidates` -- physical terms of the RV reducer's pin factors (the paper's
  EB = pin distribution circle diameter error and EC = pin radius error, both in um): the magnitude
  of the radial pin clearance change ``|EB/2 - EC|`` (a larger pin circle moves every pin out by
  EB/2, a larger pin moves its flank in by EC; the contact is one-sided, so the TE is V-shaped in
  this difference, which no polynomial of degree 2 is) and its products with ``EA`` (the pin pitch
  error acting through the clearance). A physical term enters the model through a *derived column*
  (:class:`DerivedColumn`, computed from the actual-unit factors) that rsm treats as one more
  factor with identity coding (-1/0/+1 = -1/0/+1 in its own unit).

Example
-------
>>> from rsm.candidates import polynomial_candidates
>>> [c.name for c in polynomial_candidates(["A", "B"])]
['A^2:B', 'A:B^2', 'A^2:B^2', 'A^3', 'B^3']
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd

from .coding import Levels

__all__ = ["DerivedColumn", "CandidateTerm", "polynomial_candidates", "pin_clearance_candidates",
           "default_candidates"]

KINDS = ("polynomial", "physical")


@dataclass(frozen=True)
class DerivedColumn:
    """A column computed from the factors in actual units, entered in models as one more factor.

    Attributes
    ----------
    name : str
        Column name, a valid rsm factor name (no spaces, ``:``, ``*``, ``^``, ``+``, brackets).
    unit : str
        Unit of its values.
    meaning : str
        What it is.
    func : callable
        ``func(actual: DataFrame) -> ndarray``: the column from a frame of the factor columns in
        actual units (one row per run).
    """

    name: str
    unit: str
    meaning: str
    func: Callable[[pd.DataFrame], np.ndarray]


@dataclass(frozen=True)
class CandidateTerm:
    """One term that may be added to a model.

    Attributes
    ----------
    name : str
        Display name (``EB^2:EC``, ``|EB/2-EC|``, ``EA:|EB/2-EC|``).
    kind : {'polynomial', 'physical'}
        Where it comes from; a selection rule may prefer one kind among terms the runs cannot
        tell apart.
    meaning : str
        One line on what the term describes.
    term : str
        The term in rsm syntax as it enters the model (for a physical term it names the derived
        column, e.g. ``EA:pin_clearance``).
    derived : DerivedColumn or None
        The derived column the term needs, if any.
    """

    name: str
    kind: str
    meaning: str
    term: str
    derived: DerivedColumn | None = None

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"candidate '{self.name}': kind must be one of {KINDS}, not '{self.kind}'")


def polynomial_candidates(factors: Sequence[str]) -> list[CandidateTerm]:
    """Third- and fourth-order polynomial terms of the factors (see the module docstring).

    Parameters
    ----------
    factors : sequence of str
        Factor names, in model order.

    Returns
    -------
    list of CandidateTerm
        ``Xi^2:Xj`` for every ordered pair, ``Xi^2:Xj^2`` for every pair, ``Xi:Xj:Xk`` for every
        triple, ``Xi^3`` for every factor.
    """
    f = list(factors)
    out: list[CandidateTerm] = []
    for i, j in itertools.permutations(range(len(f)), 2):
        a, b = (f[i], f[j]) if i < j else (f[j], f[i])
        name = f"{a}^2:{b}" if a == f[i] else f"{a}:{b}^2"
        out.append(CandidateTerm(name, "polynomial",
                                 f"third order: the curvature in {f[i]} changes with {f[j]}", name))
    for i, j in itertools.combinations(range(len(f)), 2):
        name = f"{f[i]}^2:{f[j]}^2"
        out.append(CandidateTerm(name, "polynomial", "fourth order: interaction of two curvatures", name))
    for c in itertools.combinations(range(len(f)), 3):
        name = ":".join(f[k] for k in c)
        out.append(CandidateTerm(name, "polynomial", "three-factor interaction", name))
    for i in range(len(f)):
        name = f"{f[i]}^3"
        out.append(CandidateTerm(name, "polynomial", f"cubic in {f[i]}", name))
    return out


#: Name of the derived column ``|EB/2 - EC|`` (um) in augmented models.
PIN_CLEARANCE = "pin_clearance"


def pin_clearance_candidates(factors: Sequence[str], levels: Levels | None) -> list[CandidateTerm]:
    """Physical terms of the radial pin clearance, for models with the paper's factors EB and EC.

    Parameters
    ----------
    factors : sequence of str
        Factor names; the terms are built only if ``EB`` (pin distribution circle diameter error,
        um) and ``EC`` (pin radius error, um) are among them.
    levels : Levels or None
        Levels table giving the actual units; without it no physical term is built (the clearance
        is defined in um, not in coded units).

    Returns
    -------
    list of CandidateTerm
        ``|EB/2-EC|``, and with ``EA`` also ``EA:|EB/2-EC|`` and ``EA^2:|EB/2-EC|``.
    """
    f = list(factors)
    if not ({"EB", "EC"} <= set(f)) or levels is None:
        return []
    col = DerivedColumn(
        PIN_CLEARANCE, "um",
        "|EB/2 - EC|: radial pin clearance change (pin circle radius error minus pin radius error)",
        lambda a: np.abs(a["EB"].to_numpy(dtype=float) / 2.0 - a["EC"].to_numpy(dtype=float)),
    )
    out = [CandidateTerm("|EB/2-EC|", "physical",
                         "magnitude of the radial pin clearance change (um): one-sided contact makes the TE "
                         "V-shaped in it", PIN_CLEARANCE, col)]
    if "EA" in f:
        out.append(CandidateTerm("EA:|EB/2-EC|", "physical", "pin pitch error acting through the radial "
                                 "clearance", f"EA:{PIN_CLEARANCE}", col))
        out.append(CandidateTerm("EA^2:|EB/2-EC|", "physical", "pin pitch curvature changed by the radial "
                                 "clearance", f"EA^2:{PIN_CLEARANCE}", col))
    return out


def default_candidates(factors: Sequence[str], levels: Levels | None,
                       physical: bool = True) -> list[CandidateTerm]:
    """:func:`polynomial_candidates` followed (if ``physical``) by :func:`pin_clearance_candidates`."""
    out = polynomial_candidates(factors)
    if physical:
        out += pin_clearance_candidates(factors, levels)
    return out
