"""Data checks and typed errors of :mod:`rsm`: a leaf module (numpy and pandas only).

Every module of the package that reads a column or refuses a model imports from here, so the
modules that use each other (:mod:`rsm.model`, :mod:`rsm.results`, :mod:`rsm.surface`) need no
import of one another for these helpers.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd

__all__ = ["NotEstimableError", "check_numeric_column"]


class NotEstimableError(ValueError):
    """Model terms that the runs cannot estimate (their columns are linear combinations of others).

    Parameters
    ----------
    terms : sequence of str
        The terms that cannot be estimated, in model order. Removing all of them leaves a model
        matrix of full column rank (each one is dependent on the terms before it that are kept).
    message : str, optional
        The message; by default it names the first term and lists the others.

    Attributes
    ----------
    terms : list of str
        As given.
    """

    def __init__(self, terms: Sequence[str], message: str | None = None) -> None:
        self.terms: list[str] = [str(t) for t in terms]
        if not self.terms:
            raise ValueError("NotEstimableError needs at least one term")
        if message is None:
            first = self.terms[0]
            message = (
                f"term '{first}' cannot be estimated from these runs: its column is a linear "
                "combination of the earlier terms (e.g. a factor with only two levels "
                "cannot carry a square term); remove it or add runs"
            )
            if len(self.terms) > 1:
                message += f" (also not estimable: {', '.join(self.terms[1:])})"
        super().__init__(message)


def check_numeric_column(df: pd.DataFrame, column: str, role: str = "factor") -> np.ndarray:
    """Return a column as float array or raise a ValueError that names it.

    Parameters
    ----------
    df : DataFrame
        The data.
    column : str
        Column name.
    role : str
        ``factor`` or ``response``; used in the messages.

    Returns
    -------
    ndarray of float

    Raises
    ------
    ValueError
        If the column is missing or holds a missing, non-numeric or infinite cell
        (the message names the column, the row (1-based) and the value).
    """
    if column not in df.columns:
        raise ValueError(
            f"{role} column '{column}' not found in the data; columns are {list(df.columns)}"
        )
    raw = df[column]
    if isinstance(raw, pd.DataFrame):
        raise ValueError(f"{role} column '{column}' appears more than once in the data")
    values = pd.to_numeric(raw, errors="coerce")
    bad = values.isna() | ~np.isfinite(values.to_numpy(dtype=float, na_value=np.nan))
    if bad.any():
        pos = int(np.flatnonzero(bad.to_numpy())[0])
        cell = raw.iloc[pos]
        if pd.isna(cell):
            raise ValueError(f"{role} column '{column}' has a missing value in data row {pos + 1}")
        raise ValueError(
            f"{role} column '{column}' has a non-numeric value {str(cell)!r} in data row {pos + 1}"
        )
    return values.to_numpy(dtype=float)
