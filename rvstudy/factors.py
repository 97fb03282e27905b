"""The factors of the study's response surface: the levels table, the error each factor sets and its pin
pattern (``rv-stackup --levels``, ``--factors``)."""
from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import pandas as pd

import rsm
import rvpaper as paper
from rsm.csvio import read_csv_strict
from rvcad.errors import ERROR_TYPES, MAX_ABS
from rvcad.params import Design
from rvcad.validation import TableError
from rvstudy.screen import RSM_FACTORS

#: Pin patterns a factor of a pin-wise error (pin_pitch, pin_circle_diameter, pin_radius) can take,
#: written ``key[pattern]`` in the levels table's ``error`` column: ``all`` = every pin gets the
#: factor's value (for pin_pitch a rotation of the whole pin ring), ``alternate`` = the even pins
#: 0, 2, ..., 38 get it and the odd pins none. Without a pattern the value goes to the error's
#: default instance (pin_pitch: pin 0 only; the radius errors: all pins).
PIN_PATTERNS = ("all", "alternate")


def pattern_value(key: str, pattern: str | None, value: float, z_pins: int | None = None) -> float | list[float]:
    """The case-JSON value of a factor setting: the number itself, or the list of ``z_pins`` pin values
    (default: the default design's 40) of a pin pattern (see :data:`PIN_PATTERNS`), in the error's unit."""
    if pattern is None:
        return value
    z_pins = Design().z_pins if z_pins is None else int(z_pins)
    if pattern == "all":
        return [value] * z_pins
    if pattern == "alternate":
        return [value if i % 2 == 0 else 0.0 for i in range(z_pins)]
    raise ValueError(f"pattern {pattern!r} of {key} is unknown; allowed: {list(PIN_PATTERNS)}")


@dataclass
class FactorSet:
    """RSM factors: names, the error type of each (and its pin pattern), and the levels table
    (actual units = error units)."""

    names: list[str]
    errors: dict[str, str]
    levels: rsm.Levels
    table: pd.DataFrame
    is_paper: bool
    patterns: dict[str, str | None] = field(default_factory=dict)
    z_pins: int = field(default_factory=lambda: Design().z_pins)

    @property
    def error_keys(self) -> list[str]:
        return [self.errors[f] for f in self.names]

    def spec(self, f: str) -> str:
        """``key`` or ``key[pattern]`` of factor ``f``."""
        p = self.patterns.get(f)
        return self.errors[f] + (f"[{p}]" if p else "")

    def case_errors(self, values: dict[str, float]) -> dict[str, float | list[float]]:
        """Case-JSON errors of error values keyed by error type: a factor's pattern is applied to its
        error type's value; other error types keep their default instance."""
        pat = {self.errors[f]: self.patterns.get(f) for f in self.names}
        return {k: pattern_value(k, pat.get(k), float(v), self.z_pins) for k, v in values.items()}


def load_factors(levels_path: str | None, factors: list[str] | None) -> FactorSet:
    """Levels table (paper Table 5 by default) and the error type of each factor.

    The error type comes from an ``error`` column, else from the paper's map (EA = pin_pitch,
    EB = pin_circle_diameter, EC = pin_radius, ED = disc_hole_eccentricity), else from the factor
    name itself when it is a Table 4 error key. A ``unit`` column must match the error's unit.
    """
    if levels_path is None:
        df = paper.table5_levels()
    else:
        p = Path(levels_path)
        if not p.is_file():
            raise TableError(f"--levels file {str(p)!r} does not exist")
        df = read_csv_strict(p, "--levels file", lambda m: TableError(m, field="--levels", value=str(p),
                                                                         allowed="CSV factor,unit,low,center,high"))
    df.columns = [str(c).strip() for c in df.columns]
    if "factor" not in df.columns:
        raise TableError(f"--levels file needs a 'factor' column; columns are {list(df.columns)}")
    try:
        levels = rsm.Levels.from_frame(df)
    except ValueError as exc:
        raise TableError(f"--levels: {exc}") from None
    names = levels.names if not factors else list(factors)
    for f in names:
        if f not in levels:
            raise TableError(f"--factors {f!r} is not in the levels table; it lists {levels.names}")
    if len(set(names)) != len(names):
        raise TableError(f"--factors {names} lists a factor twice")
    if not 3 <= len(names) <= 7:
        raise TableError(f"--factors: the designs need 3 to 7 factors, got {len(names)} ({names})")
    errors: dict[str, str] = {}
    patterns: dict[str, str | None] = {}
    for f in names:
        row = df[df["factor"].astype(str).str.strip() == f].iloc[0]
        key = str(row["error"]).strip() if "error" in df.columns and pd.notna(row.get("error")) else (
            RSM_FACTORS.get(f, f))
        m = re.fullmatch(r"([A-Za-z_]+)\s*\[\s*([A-Za-z_]+)\s*\]", key)
        pattern = None
        if m:
            key, pattern = m.group(1), m.group(2)
            if pattern not in PIN_PATTERNS:
                raise TableError(f"--levels: factor {f!r} has pin pattern {pattern!r}; allowed: {list(PIN_PATTERNS)}")
            if key in ERROR_TYPES and not ERROR_TYPES[key].pinwise:
                raise TableError(f"--levels: factor {f!r}: a pin pattern needs a pin-wise error "
                                 f"({sorted(k for k, e in ERROR_TYPES.items() if e.pinwise)}), not {key!r}")
        patterns[f] = pattern
        if key not in ERROR_TYPES:
            raise TableError(f"--levels: factor {f!r} maps to no Table 4 error (error {key!r}); add an 'error' "
                             f"column with one of {sorted(ERROR_TYPES)}")
        unit = str(row["unit"]).strip() if "unit" in df.columns and pd.notna(row.get("unit")) else ""
        if unit and unit != ERROR_TYPES[key].unit:
            raise TableError(f"--levels: factor {f!r} ({key}) has unit {unit!r}; the error's unit is "
                             f"{ERROR_TYPES[key].unit!r}")
        lim = MAX_ABS[ERROR_TYPES[key].unit]
        for lev in ("low", "center", "high"):
            x = getattr(levels[f], lev)
            if not (math.isfinite(x) and abs(x) <= lim):
                raise TableError(f"--levels: factor {f!r} ({key}) {lev} {x!r} {ERROR_TYPES[key].unit} is out of range; allowed: a finite "
                                 f"value with |value| <= {lim:g} {ERROR_TYPES[key].unit}", field=f"{f}.{lev}", value=x)
        errors[f] = key
    if len(set(errors.values())) != len(errors):
        raise TableError(f"--levels: two factors map to the same error type ({errors})")
    levels = levels.subset(names)
    ptab = paper.table5_levels().set_index("factor")
    is_paper = names == list(ptab.index) and all(
        errors[f] == ptab.loc[f, "error"] and patterns[f] is None and levels[f].low == ptab.loc[f, "low"]
        and levels[f].center == ptab.loc[f, "center"] and levels[f].high == ptab.loc[f, "high"] for f in names)
    table = levels.to_frame()
    table["error"] = [errors[f] for f in table["factor"]]
    table["pattern"] = [patterns[f] or "default instance" for f in table["factor"]]
    return FactorSet(names, errors, levels, table, is_paper, patterns)


