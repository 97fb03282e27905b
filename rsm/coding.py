"""Coded <-> actual factor units from a levels table.

A levels table has one row per factor with the columns ``factor, low, center, high`` and,
optionally, ``unit`` and ``meaning`` (the layout of ``paper_table5_levels.csv``). The coded
value ``z`` and the actual value ``x`` are related by

    x = center + z * half_range,   half_range = (high - low) / 2,

so ``low``/``center``/``high`` are coded -1/0/+1 (for the paper: EA = +-0.06 deg,
EB = +-14 um, EC = +-7 um, ED = +-14 um). ``center`` must be the midpoint of ``low`` and
``high`` (a linear coding cannot map an off-centre middle level to 0).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from .csvio import read_csv_strict

__all__ = ["FactorLevels", "Levels"]


@dataclass(frozen=True)
class FactorLevels:
    """Levels of one factor.

    Attributes
    ----------
    name : str
        Factor name (column name in the data).
    low, center, high : float
        Actual values at coded -1, 0 and +1.
    unit : str
        Unit of the actual values (e.g. ``deg``, ``um``); informational.
    meaning : str
        Free-text description.
    """

    name: str
    low: float
    center: float
    high: float
    unit: str = ""
    meaning: str = ""

    @property
    def half_range(self) -> float:
        """Actual-unit change per coded unit, ``(high - low) / 2``."""
        return (self.high - self.low) / 2.0


class Levels:
    """Coded/actual conversion for a set of factors.

    Parameters
    ----------
    factors : sequence of FactorLevels
        One entry per factor.

    Examples
    --------
    >>> lv = Levels.from_csv("paper_table5_levels.csv")          # doctest: +SKIP
    >>> lv.to_actual(pd.DataFrame({"EA": [1.0], "EB": [0.0]}))   # doctest: +SKIP
    """

    def __init__(self, factors: Sequence[FactorLevels]):
        self._by_name: dict[str, FactorLevels] = {}
        for f in factors:
            if f.name in self._by_name:
                raise ValueError(f"levels table lists factor '{f.name}' twice")
            for attr in ("low", "center", "high"):
                v = getattr(f, attr)
                if not np.isfinite(v):
                    raise ValueError(f"levels table: '{attr}' of factor '{f.name}' is not a finite number")
            if not f.high > f.low:
                raise ValueError(
                    f"levels table: factor '{f.name}' needs high > low (got low={f.low}, high={f.high})"
                )
            mid = 0.5 * (f.low + f.high)
            if abs(f.center - mid) > 1e-9 * max(1.0, abs(f.high - f.low)):
                raise ValueError(
                    f"levels table: centre of factor '{f.name}' ({f.center}) is not the midpoint "
                    f"of low and high ({mid}); linear coding needs a symmetric range"
                )
            self._by_name[f.name] = f

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_frame(cls, df: pd.DataFrame) -> "Levels":
        """Build from a DataFrame with columns ``factor, low, [center,] high[, unit, meaning]``."""
        cols = {c.strip().lower(): c for c in df.columns}
        for need in ("factor", "low", "high"):
            if need not in cols:
                raise ValueError(
                    f"levels table has no '{need}' column; columns are {list(df.columns)}"
                )
        out = []
        for i, row in df.iterrows():
            name = str(row[cols["factor"]]).strip()
            vals = {}
            for key in ("low", "center", "high"):
                if key not in cols:
                    continue
                raw = row[cols[key]]
                try:
                    vals[key] = float(raw)
                except (TypeError, ValueError):
                    raise ValueError(
                        f"levels table: '{key}' of factor '{name}' is not numeric ({raw!r})"
                    ) from None
            if "center" not in vals:
                vals["center"] = 0.5 * (vals["low"] + vals["high"])
            unit = str(row[cols["unit"]]) if "unit" in cols and pd.notna(row[cols["unit"]]) else ""
            meaning = (
                str(row[cols["meaning"]]) if "meaning" in cols and pd.notna(row[cols["meaning"]]) else ""
            )
            out.append(FactorLevels(name, vals["low"], vals["center"], vals["high"], unit, meaning))
        return cls(out)

    @classmethod
    def from_csv(cls, path: str | Path) -> "Levels":
        """Read a levels CSV (``factor,meaning,unit,low,center,high`` as in Table 5)."""
        return cls.from_frame(read_csv_strict(path, "levels file"))

    @classmethod
    def coerce(cls, levels: "Levels | pd.DataFrame | str | Path | None") -> "Levels | None":
        """Accept a Levels object, a DataFrame, a CSV path or None."""
        if levels is None or isinstance(levels, Levels):
            return levels
        if isinstance(levels, pd.DataFrame):
            return cls.from_frame(levels)
        return cls.from_csv(levels)

    # ------------------------------------------------------------------ access
    @property
    def names(self) -> list[str]:
        """Factor names in table order."""
        return list(self._by_name)

    def __getitem__(self, name: str) -> FactorLevels:
        try:
            return self._by_name[name]
        except KeyError:
            raise ValueError(
                f"levels table has no row for factor '{name}'; it lists {self.names}"
            ) from None

    def __contains__(self, name: object) -> bool:
        return name in self._by_name

    def __len__(self) -> int:
        return len(self._by_name)

    def subset(self, factors: Sequence[str]) -> "Levels":
        """Levels of the given factors, in that order (ValueError names a missing one)."""
        return Levels([self[f] for f in factors])

    def center(self, factors: Sequence[str]) -> np.ndarray:
        """Centre (coded 0) in actual units for ``factors``."""
        return np.array([self[f].center for f in factors], dtype=float)

    def half_range(self, factors: Sequence[str]) -> np.ndarray:
        """Actual units per coded unit for ``factors``."""
        return np.array([self[f].half_range for f in factors], dtype=float)

    def unit(self, factor: str) -> str:
        """Unit string of a factor ('' if none)."""
        return self[factor].unit

    # ------------------------------------------------------------------ conversion
    def coded_to_actual(self, z: np.ndarray, factors: Sequence[str]) -> np.ndarray:
        """Array conversion coded -> actual; columns follow ``factors``."""
        z = np.asarray(z, dtype=float)
        return self.center(factors) + z * self.half_range(factors)

    def actual_to_coded(self, x: np.ndarray, factors: Sequence[str]) -> np.ndarray:
        """Array conversion actual -> coded; columns follow ``factors``."""
        x = np.asarray(x, dtype=float)
        return (x - self.center(factors)) / self.half_range(factors)

    def to_actual(self, df: pd.DataFrame, factors: Sequence[str] | None = None) -> pd.DataFrame:
        """Copy of ``df`` with the factor columns converted coded -> actual.

        Parameters
        ----------
        df : DataFrame
            Data with coded factor columns.
        factors : sequence of str, optional
            Columns to convert; default: every column of ``df`` that is in the table.
        """
        factors = [c for c in df.columns if c in self] if factors is None else list(factors)
        out = df.copy()
        for f in factors:
            if f not in df.columns:
                raise ValueError(f"factor column '{f}' not found; columns are {list(df.columns)}")
            out[f] = self[f].center + df[f].astype(float) * self[f].half_range
        return out

    def to_coded(self, df: pd.DataFrame, factors: Sequence[str] | None = None) -> pd.DataFrame:
        """Copy of ``df`` with the factor columns converted actual -> coded."""
        factors = [c for c in df.columns if c in self] if factors is None else list(factors)
        out = df.copy()
        for f in factors:
            if f not in df.columns:
                raise ValueError(f"factor column '{f}' not found; columns are {list(df.columns)}")
            out[f] = (df[f].astype(float) - self[f].center) / self[f].half_range
        return out

    def to_frame(self) -> pd.DataFrame:
        """The table as a DataFrame (``factor, meaning, unit, low, center, high``)."""
        return pd.DataFrame(
            [
                {"factor": f.name, "meaning": f.meaning, "unit": f.unit, "low": f.low,
                 "center": f.center, "high": f.high}
                for f in self._by_name.values()
            ]
        )

    def __repr__(self) -> str:
        inner = ", ".join(f"{f.name}=[{f.low}, {f.center}, {f.high}] {f.unit}".rstrip()
                          for f in self._by_name.values())
        return f"Levels({inner})"
