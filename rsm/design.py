"""Response-surface designs: Box-Behnken, central composite and 3^k full factorial.

All designs are generated in coded units (factorial levels -1/0/+1; CCD axial points at
+-alpha) and can be converted to actual units with a :class:`rsm.coding.Levels` table.

Box-Behnken generating blocks (Box & Behnken, Technometrics 2, 1960): for 3, 4 and 5
factors every pair of factors forms a block (12, 24, 40 runs); for 6 factors the six
triples {1,2,4}, {2,3,5}, {3,4,6}, {1,4,5}, {2,5,6}, {1,3,6} (48 runs; each factor in three
blocks); for 7 factors the seven triples of the balanced incomplete block design
{4,5,6}, {1,6,7}, {2,5,7}, {1,2,4}, {3,4,7}, {1,3,5}, {2,3,6} (56 runs; every pair of factors
together exactly once, which makes the 7-factor design rotatable). Each block is crossed
with the 2^m factorial in +-1 with the remaining factors at 0. The pair orders for 4 and 5
factors are the published ones that allow orthogonal blocking.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from .coding import Levels

__all__ = [
    "BBD_BLOCKS",
    "Design",
    "box_behnken",
    "central_composite",
    "full_factorial_3",
    "make_design",
]

#: Published Box-Behnken generating blocks (1-based factor indices), k = 3..7.
BBD_BLOCKS: dict[int, tuple[tuple[int, ...], ...]] = {
    3: ((1, 2), (1, 3), (2, 3)),
    4: ((1, 2), (3, 4), (1, 4), (2, 3), (1, 3), (2, 4)),
    5: ((1, 2), (1, 3), (3, 4), (4, 5), (2, 5), (1, 4), (1, 5), (2, 3), (2, 4), (3, 5)),
    6: ((1, 2, 4), (2, 3, 5), (3, 4, 6), (1, 4, 5), (2, 5, 6), (1, 3, 6)),
    7: ((4, 5, 6), (1, 6, 7), (2, 5, 7), (1, 2, 4), (3, 4, 7), (1, 3, 5), (2, 3, 6)),
}


@dataclass
class Design:
    """A design in coded units.

    Attributes
    ----------
    kind : str
        ``bbd``, ``ccd`` or ``ff3``.
    factors : list of str
        Factor names.
    coded : DataFrame
        One row per run: ``run`` (execution order, 1-based), ``std_order`` (1-based order
        before randomisation), ``point_type`` (``edge``, ``factorial``, ``axial``, ``center``)
        and one coded column per factor.
    alpha : float or None
        CCD axial distance (coded units); None for other designs.
    levels : Levels or None
        Levels table for actual units.
    seed : int or None
        Seed used to randomise the run order (None: standard order).
    """

    kind: str
    factors: list[str]
    coded: pd.DataFrame
    alpha: float | None = None
    levels: Levels | None = None
    seed: int | None = None
    notes: list[str] = field(default_factory=list)

    @property
    def n_runs(self) -> int:
        """Number of runs."""
        return len(self.coded)

    def matrix(self) -> np.ndarray:
        """Coded design matrix, shape (n_runs, k), rows in run order."""
        return self.coded[self.factors].to_numpy(dtype=float)

    def actual(self) -> pd.DataFrame:
        """The design with factor columns in actual units (requires ``levels``)."""
        if self.levels is None:
            raise ValueError("this design has no levels table; pass levels= to convert to actual units")
        return self.levels.to_actual(self.coded, self.factors)

    def to_frame(self, units: str = "coded") -> pd.DataFrame:
        """Table for writing.

        Parameters
        ----------
        units : {'coded', 'actual', 'both'}
            ``both`` appends actual columns named ``<factor>_actual``.
        """
        if units == "coded":
            return self.coded.copy()
        if units == "actual":
            return self.actual()
        if units == "both":
            out = self.coded.copy()
            act = self.actual()
            for f in self.factors:
                out[f"{f}_actual"] = act[f]
            return out
        raise ValueError(f"units must be 'coded', 'actual' or 'both', not '{units}'")

    def to_csv(self, path: str | Path, units: str = "coded") -> Path:
        """Write :meth:`to_frame` to CSV and return the path."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        self.to_frame(units).to_csv(path, index=False)
        return path


def _factor_names(k: int, factors: Sequence[str] | None, levels: Levels | None) -> list[str]:
    if factors is not None:
        names = [str(f) for f in factors]
        if len(names) != k:
            raise ValueError(f"{k} factors requested but {len(names)} names given: {names}")
    elif levels is not None:
        if len(levels) < k:
            raise ValueError(
                f"{k} factors requested but the levels table lists only {len(levels)}: {levels.names}"
            )
        names = levels.names[:k]
    else:
        names = [f"x{i + 1}" for i in range(k)]
    if len(set(names)) != k:
        raise ValueError(f"factor names must be unique: {names}")
    if levels is not None:
        levels.subset(names)  # raises naming a missing factor
    return names


def _finish(
    kind: str,
    rows: list[np.ndarray],
    types: list[str],
    k: int,
    center: int,
    factors: Sequence[str] | None,
    levels: Levels | pd.DataFrame | str | Path | None,
    randomize: bool,
    seed: int | None,
    alpha: float | None = None,
) -> Design:
    lv = Levels.coerce(levels)
    names = _factor_names(k, factors, lv)
    if int(center) != center or center < 0:
        raise ValueError(f"number of centre points must be a non-negative integer, not {center}")
    rows = list(rows) + [np.zeros(k)] * int(center)
    types = list(types) + ["center"] * int(center)
    mat = np.vstack(rows).astype(float) + 0.0  # +0.0 turns -0.0 into 0.0
    df = pd.DataFrame(mat, columns=names)
    df.insert(0, "point_type", types)
    df.insert(0, "std_order", np.arange(1, len(df) + 1))
    if randomize:
        rng = np.random.default_rng(seed)
        df = df.iloc[rng.permutation(len(df))].reset_index(drop=True)
    df.insert(0, "run", np.arange(1, len(df) + 1))
    return Design(kind=kind, factors=names, coded=df, alpha=alpha, levels=lv,
                  seed=seed if randomize else None)


def _check_k(k: int, lo: int, hi: int, what: str) -> int:
    if int(k) != k or not lo <= k <= hi:
        raise ValueError(f"{what} is available for {lo} to {hi} factors, not {k}")
    return int(k)


def box_behnken(
    k: int,
    center: int = 3,
    *,
    factors: Sequence[str] | None = None,
    levels: Levels | pd.DataFrame | str | Path | None = None,
    randomize: bool = False,
    seed: int | None = None,
) -> Design:
    """Box-Behnken design for 3 to 7 factors.

    Parameters
    ----------
    k : int
        Number of factors (3..7). Runs before centre points: 12, 24, 40, 48, 56.
    center : int, default 3
        Number of centre runs (the paper's Table 6 has 3).
    factors : sequence of str, optional
        Factor names; default the first ``k`` names of ``levels`` or ``x1..xk``.
    levels : Levels, DataFrame or path, optional
        Levels table for actual units.
    randomize : bool, default False
        Shuffle the run order (``std_order`` keeps the standard order).
    seed : int, optional
        Seed of the shuffle (``numpy.random.default_rng``).

    Returns
    -------
    Design
    """
    k = _check_k(k, 3, 7, "the Box-Behnken design")
    rows: list[np.ndarray] = []
    for block in BBD_BLOCKS[k]:
        idx = [b - 1 for b in block]
        # standard order: first factor of the block changes fastest
        for signs in itertools.product((-1.0, 1.0), repeat=len(idx)):
            r = np.zeros(k)
            r[idx] = signs[::-1]
            rows.append(r)
    return _finish("bbd", rows, ["edge"] * len(rows), k, center, factors, levels, randomize, seed)


def central_composite(
    k: int,
    center: int = 3,
    alpha: str | float = "rotatable",
    *,
    factors: Sequence[str] | None = None,
    levels: Levels | pd.DataFrame | str | Path | None = None,
    randomize: bool = False,
    seed: int | None = None,
) -> Design:
    """Central composite design with a full 2^k factorial part.

    Parameters
    ----------
    k : int
        Number of factors (2..8). Runs: ``2^k + 2k + center``.
    center : int, default 3
        Number of centre runs.
    alpha : {'rotatable', 'face'} or float, default 'rotatable'
        Axial distance in coded units: ``(2^k)^(1/4)`` for ``rotatable``, ``1`` for
        ``face`` (face-centred, three levels), or a given positive number.
    factors, levels, randomize, seed
        As for :func:`box_behnken`.

    Returns
    -------
    Design
        ``point_type`` is ``factorial``, ``axial`` or ``center``; ``alpha`` is recorded.
    """
    k = _check_k(k, 2, 8, "the central composite design")
    if isinstance(alpha, str):
        key = alpha.strip().lower()
        if key in ("rotatable", "r"):
            a = float(2**k) ** 0.25
        elif key in ("face", "faced", "face-centred", "face-centered", "fcd", "f"):
            a = 1.0
        else:
            raise ValueError(f"alpha must be 'rotatable', 'face' or a positive number, not '{alpha}'")
    else:
        a = float(alpha)
        if not (np.isfinite(a) and a > 0):
            raise ValueError(f"alpha must be a positive number, not {alpha}")
    rows = [np.array(s[::-1], dtype=float) for s in itertools.product((-1.0, 1.0), repeat=k)]
    types = ["factorial"] * len(rows)
    for i in range(k):
        for s in (-a, a):
            r = np.zeros(k)
            r[i] = s
            rows.append(r)
            types.append("axial")
    return _finish("ccd", rows, types, k, center, factors, levels, randomize, seed, alpha=a)


def full_factorial_3(
    k: int,
    center: int = 1,
    *,
    factors: Sequence[str] | None = None,
    levels: Levels | pd.DataFrame | str | Path | None = None,
    randomize: bool = False,
    seed: int | None = None,
) -> Design:
    """Three-level full factorial 3^k.

    Parameters
    ----------
    k : int
        Number of factors (1..7).
    center : int, default 1
        Total number of centre runs; the grid already contains one, so ``center - 1``
        replicates are appended (``center`` must be at least 1).
    factors, levels, randomize, seed
        As for :func:`box_behnken`.

    Returns
    -------
    Design
        ``3^k + center - 1`` runs.
    """
    k = _check_k(k, 1, 7, "the 3^k full factorial")
    if int(center) != center or center < 1:
        raise ValueError(f"the 3^k grid contains its centre point, so center must be >= 1, not {center}")
    rows, types = [], []
    for combo in itertools.product((-1.0, 0.0, 1.0), repeat=k):
        r = np.array(combo[::-1], dtype=float)
        rows.append(r)
        types.append("center" if not r.any() else "factorial")
    return _finish("ff3", rows, types, k, int(center) - 1, factors, levels, randomize, seed)


def make_design(kind: str, k: int, center: int | None = None, **kwargs) -> Design:
    """Dispatch by name: ``bbd``, ``ccd`` (``alpha=`` keyword) or ``ff3``.

    Parameters
    ----------
    kind : {'bbd', 'ccd', 'ff3'}
    k : int
        Number of factors.
    center : int, optional
        Centre runs; default 3 for bbd/ccd and 1 for ff3.
    **kwargs
        Passed to the generator.
    """
    kind = kind.strip().lower()
    gens = {"bbd": (box_behnken, 3), "ccd": (central_composite, 3), "ff3": (full_factorial_3, 1)}
    if kind not in gens:
        raise ValueError(f"unknown design '{kind}'; use one of {sorted(gens)}")
    fn, default_center = gens[kind]
    return fn(k, default_center if center is None else center, **kwargs)
