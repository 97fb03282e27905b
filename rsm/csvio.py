"""One strict CSV reader for every table the tools read (data, levels, tolerances, measured runs).

``pandas.read_csv`` reads a file whose rows have more fields than the header by taking the first
column(s) as the index and shifting the rest: ``a,b`` over ``1,2,3`` becomes a = 2, b = 3, and a
trailing comma on every row (a common spreadsheet export) silently moves every value one column.
:func:`read_csv_strict` reads with ``index_col=False`` (a trailing empty field is dropped, as it
carries nothing) and refuses a row with extra non-empty fields, naming the line, the number of
fields and the header's columns. Empty, unreadable and non-UTF-8 files are refused the same way.
Every refusal is raised through the caller's ``error`` factory, so each command keeps its own error
class (``TableError``, ``DatasetError``, ``ValueError``).
"""
from __future__ import annotations

import csv
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pandas as pd

__all__ = ["read_csv_strict"]


def _first_long_row(path: Path) -> tuple[int, int, int] | None:
    """(line number, field count, header columns) of the first row with non-empty fields beyond the header's.

    None when no such row is found (or the file is not plain CSV to the ``csv`` module either).
    """
    try:
        with path.open(newline="", encoding="utf-8") as fh:
            reader = csv.reader(fh)
            ncols = len(next(reader, []))
            for row in reader:
                if len(row) > ncols and any(f.strip() for f in row[ncols:]):
                    return reader.line_num, len(row), ncols
    except (csv.Error, UnicodeDecodeError):
        return None
    return None


def read_csv_strict(path: str | Path, what: str, error: Callable[[str], Exception] = ValueError,
                    **kwargs: Any) -> pd.DataFrame:
    """Read a CSV file with a header row; one field per header column on every row.

    Parameters
    ----------
    path : str or Path
        The file.
    what : str
        How the messages name the file (``"--levels file"``, ``"runs file"``).
    error : callable
        Makes the exception raised for a refusal from its message (default ``ValueError``).
    **kwargs
        Passed to :func:`pandas.read_csv` (``dtype``, ``skipinitialspace``, ...); ``index_col`` is
        always False.

    Returns
    -------
    pandas.DataFrame
        The table, with the column names stripped of surrounding blanks.

    Raises
    ------
    Exception
        Made by ``error``: the file is missing or a folder, empty, not UTF-8, not CSV, or a row has
        more fields than the header has columns.
    """
    p = Path(path)
    if not p.is_file():
        raise error(f"{what} '{p}' does not exist" if not p.exists() else f"{what} '{p}' is a folder, not a CSV file")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error", pd.errors.ParserWarning)
            df = pd.read_csv(p, index_col=False, **kwargs)
    except (pd.errors.ParserWarning, pd.errors.ParserError) as exc:
        # the first data row too long: a ParserWarning (index_col=False); a later one: a ParserError
        where = _first_long_row(p)
        if where is None:
            raise error(f"{what} '{p}' cannot be read as CSV: {' '.join(str(exc).split())}") from None
        raise error(f"{what} '{p}': line {where[0]} has {where[1]} fields but the header has {where[2]} columns; "
                    "allowed: one field per column of the header") from None
    except pd.errors.EmptyDataError:
        raise error(f"{what} '{p}' is empty; allowed: a CSV file with a header row") from None
    except UnicodeDecodeError as exc:
        raise error(f"{what} '{p}' cannot be read as CSV: not UTF-8 text ({exc.reason} at byte {exc.start}); "
                    "allowed: a UTF-8 CSV file") from None
    except ValueError as exc:
        raise error(f"{what} '{p}' cannot be read as CSV: {' '.join(str(exc).split())}") from None
    df.columns = [str(c).strip() for c in df.columns]
    return df
