"""Which runs of a dataset share one rig zero: the tests.

A TE rig zeroes its readings at a homing position before each test, so the absolute TE level of a test
is the rig's, not the reducer's (conventions, "Measured data"): every run measured after one homing
shares one unknown constant. :func:`group_tests` gives each run its test:

* an explicit ``test`` column of ``runs.csv`` (any text; empty cells are refused), else
* one test per (load, speed, temperature): the runs a rig measures in one go, forward and backward,
  after one homing. Runs without a speed or temperature column are grouped by what is given.

The estimator gives each test its own constant; the per-test table (:mod:`rvrig.rigtable`) takes
differences only within a test (backward minus forward), where the constant cancels.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from rvcad.validation import DatasetError

__all__ = ["TestGroups", "group_tests", "default_test_id"]


@dataclass(frozen=True)
class TestGroups:
    """Runs grouped by test (one homing of the rig each).

    Attributes
    ----------
    of_run : dict of str to str
        Run id -> test id.
    ids : tuple of str
        The test ids, in order of first appearance in ``runs.csv``.
    source : str
        How the tests were formed (the ``test`` column, or one per load, speed and temperature).
    """

    __test__ = False  # not a pytest test class

    of_run: dict[str, str]
    ids: tuple[str, ...]
    source: str

    def runs(self, test: str) -> tuple[str, ...]:
        """Run ids of one test, in file order."""
        if test not in self.ids:
            raise KeyError(f"no test {test!r}; tests are {list(self.ids)}")
        return tuple(r for r, t in self.of_run.items() if t == test)

    def index(self, runs: "list[str] | tuple[str, ...]") -> np.ndarray:
        """Test index (position in :attr:`ids`) of each run id given, int array."""
        pos = {t: i for i, t in enumerate(self.ids)}
        return np.array([pos[self.of_run[r]] for r in runs], dtype=int)

    def __len__(self) -> int:
        return len(self.ids)


def default_test_id(load_Nm: float, speed_rpm: float | None = None, temperature_C: float | None = None) -> str:
    """The test id of runs grouped by their conditions, e.g. ``1800Nm_1800rpm_25C``."""
    parts = [f"{load_Nm:g}Nm"]
    if speed_rpm is not None and np.isfinite(speed_rpm):
        parts.append(f"{speed_rpm:g}rpm")
    if temperature_C is not None and np.isfinite(temperature_C):
        parts.append(f"{temperature_C:g}C")
    return "_".join(parts)


def group_tests(runs: pd.DataFrame, fname: str = "runs.csv") -> TestGroups:
    """The tests of a validated runs table.

    Parameters
    ----------
    runs : DataFrame
        Columns ``run``, ``load_Nm`` and optionally ``test`` (text), ``speed_rpm``, ``temperature_C``.
    fname : str
        How messages name the file.

    Returns
    -------
    TestGroups

    Raises
    ------
    DatasetError
        An empty ``test`` cell, naming the file, the column, the row and the run.
    """
    rid = [str(r) for r in runs["run"]]
    if "test" in runs.columns:
        raw = runs["test"]
        vals = ["" if pd.isna(v) else str(v).strip() for v in raw]
        for i, v in enumerate(vals):
            if v == "" or v.lower() == "nan":
                raise DatasetError(f"{fname}: column 'test' row {i + 2} (run {rid[i]}) is empty; give every run "
                                   "the id of the test (homing) it was measured in, or drop the column to group the "
                                   "runs by load, speed and temperature")
        source = f"column 'test' of {fname}"
    else:
        speed = runs["speed_rpm"].to_numpy(dtype=float) if "speed_rpm" in runs.columns else [None] * len(rid)
        temp = runs["temperature_C"].to_numpy(dtype=float) if "temperature_C" in runs.columns else [None] * len(rid)
        vals = [default_test_id(float(ld), s, t) for ld, s, t in zip(runs["load_Nm"], speed, temp)]
        given = ["load"] + (["speed"] if "speed_rpm" in runs.columns else []) + (
            ["temperature"] if "temperature_C" in runs.columns else [])
        source = f"one test per {', '.join(given)} (no 'test' column in {fname})"
    ids = tuple(dict.fromkeys(vals))
    return TestGroups(of_run=dict(zip(rid, vals)), ids=ids, source=source)
