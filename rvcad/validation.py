"""One validation layer for every input: the error family, value checks, strict JSON, size budgets.

Every rejection of user input is an :class:`InputError` (a ``ValueError``) whose message names the
field, the value given and what is allowed, e.g.::

    design.z_planet 10000000 is out of range; allowed: an integer in [6, 300]

The subclasses say which input it was (:class:`CaseError`, :class:`DesignError`, :class:`TableError`,
:class:`DatasetError`, :class:`OptionError`); the command lines catch ``ValueError``, print the message
as one line on stderr and exit with status 2. This module is a leaf: it imports nothing of the
project, so every package may use it.

Size budgets
------------
Every size option has an upper bound derived from a stated memory and time budget (the arithmetic
is in the comments below the constants); the bound is quoted in the refusal message.
"""
from __future__ import annotations

import argparse
import json
import math
import numbers
import sys
from collections.abc import Mapping
from pathlib import Path
from typing import Any, NoReturn


# ------------------------------------------------------------------------------------ error family
class InputError(ValueError):
    """Bad user input. The message names the field, the value and what is allowed.

    Attributes
    ----------
    field : str or None
        Dotted name of the offending field (``design.z_planet``, ``--steps``, ``runs.csv:load_Nm``).
    value : Any
        The value given (``None`` when not applicable).
    allowed : str or None
        What would have been accepted.
    """

    def __init__(self, message: str, *, field: str | None = None, value: Any = None,
                 allowed: str | None = None) -> None:
        super().__init__(message)
        self.field = field
        self.value = value
        self.allowed = allowed


class CaseError(InputError):
    """A bad case JSON (top level, ``errors``, ``model``, ``load_Nm``, ``direction``, ``name``)."""


class DesignError(InputError):
    """A bad reducer design (``design`` object of a case, or a design JSON file)."""


class JSONInputError(InputError):
    """A JSON text that is not valid JSON, repeats a key or uses NaN/Infinity."""


class TableError(InputError):
    """A bad levels or tolerance table (``--levels``, ``--tolerances``, ``--tolerance``)."""


class DatasetError(InputError):
    """A bad measured dataset (``runs.csv``, ``samples.csv``, ``design.json``)."""


class OptionError(InputError):
    """A bad command-line option value."""


# ------------------------------------------------------------------------------------ size budgets
#: Memory one solve (one process) may use, bytes.
MEMORY_BUDGET_BYTES = 2 * 1024 ** 3
#: Memory the analytic solver keeps per solved step, bytes. Measured: ``rvdyn te --steps 360`` and
#: ``--steps 3600`` peak at 156 MB and 212 MB resident (/usr/bin/time -f %M), i.e.
#: (212 - 156) MB / 3240 steps = 17 kB per step.
BYTES_PER_STEP = 17_000
#: Seconds per solved step of the analytic solver (same measurement: 3.99 s solver time for 3600
#: steps on one core of a 2-core machine, 1.1 ms per step).
SECONDS_PER_STEP = 1.1e-3
#: Largest step count of one solve: MEMORY_BUDGET_BYTES / BYTES_PER_STEP = 2.15e9 / 1.7e4 = 126,000,
#: rounded down to 100,000 (1.7 GB, and 100,000 * 1.1 ms = 110 s per curve).
MAX_STEPS = 100_000
#: Largest number of output revolutions of one TE record: with at most MAX_STEPS steps that leaves
#: at least 100 steps per output revolution (2.5 per pin pitch of the 40-pin design); longer records
#: are undersampled.
MAX_REVOLUTIONS = 1_000.0
#: Largest number of full-solver cases one option may ask for (validation cases, Monte Carlo checks):
#: at the default 360 steps a case takes 360 * 1.1 ms = 0.4 s plus ~0.6 s set-up, so 10,000 cases
#: are ~3 h on one worker -- a day's budget at most.
MAX_CASES = 10_000
#: Largest number of points of one factor sweep (each point is one full-solver case per factor):
#: 4 factors * 1,000 points = 4,000 cases, inside MAX_CASES.
MAX_SWEEP_POINTS = 1_000
#: Largest number of centre runs of a response-surface design (each one full-solver case).
MAX_CENTER_RUNS = 1_000
#: Largest Monte Carlo sample through the surfaces: one sample matrix holds 11 float64 columns
#: (88 bytes per draw); the Sobol estimator holds A, B and k + 2 <= 9 evaluation sets for up to
#: 7 factors, about 11 * 88 = 1 kB per draw, so 2,000,000 draws = 2 GB = MEMORY_BUDGET_BYTES.
MAX_MC_SAMPLES = 2_000_000
#: Largest number of full-solver Monte Carlo draws: each draw keeps one row of its drawn features
#: (every pin, hole, cam and crank: about 250 float64 = 2 kB) and its responses, so 1,000,000 draws hold
#: about 2 GB = MEMORY_BUDGET_BYTES; at ~0.2 s a solve that is ~55 worker-hours, a Dask cluster's job.
MAX_MC_DRAWS = 1_000_000
#: Largest number of local worker processes: each holds about 160 MB before solving (the 156 MB
#: peak of a 360-step run above) plus up to MEMORY_BUDGET_BYTES per solve at MAX_STEPS; 32 workers
#: at the default steps need 32 * 0.16 = 5 GB.
MAX_WORKERS = 32
#: Largest model grid of the loop, points per output revolution: a calibration solves the model on
#: the grid about 30 times per distinct run condition (6 terms * top 4 candidates + the fits), so
#: 14,400 points * 30 * 1.1 ms = 8 min per condition; 14,400 points = 0.025 deg of output angle.
MAX_GRID_STEPS = 14_400
#: Largest number of terms the loop may add: each term is one iteration (a screen of the library
#: and up to 4 nonlinear validations, 30 grid solves above); 40 terms = the pin count of the paper's
#: reducer, beyond which the loop would be fitting pin-by-pin noise.
MAX_TERMS = 40

#: Largest contact stiffness K of the impact law, N/mm^n: stiffer is the rigid limit (--rigid). At the
#: default 20 N m a pin carries about 20e3 N mm / 64 mm / 20 contacts = 16 N, which deflects
#: (16 / 1e9)^(1/1.5) mm = 0.006 um at K = 1e9 (n = 1.5); beyond, the Newton steps overflow.
MAX_CONTACT_K = 1.0e9
#: Largest input angle of a placement, degrees: beyond it float64 (ulp 1.2e-10 deg at 1e6 deg) starts
#: to lose the sub-arcsecond positions; 1e6 deg is 23 output revolutions of the 121:1 reducer.
MAX_ANGLE_DEG = 1.0e6

#: Longest text quoted back in a message, characters.
_QUOTE = 60


def quote(value: Any) -> str:
    """Short ``repr`` of a value for a message (cut to 60 characters, strings to 300)."""
    try:
        text = repr(value)
    except Exception:  # noqa: BLE001 - a broken __repr__ must not hide the real error
        text = f"<{type(value).__name__}>"
    limit = 5 * _QUOTE if isinstance(value, str) else _QUOTE  # paths and names in full
    return text if len(text) <= limit else text[:limit - 3] + "..."


def reject(field: str, value: Any, allowed: str, problem: str = "is not allowed",
           cls: type[InputError] = InputError) -> NoReturn:
    """Raise ``cls`` with the message ``"{field} {value} {problem}; allowed: {allowed}"``."""
    raise cls(f"{field} {quote(value)} {problem}; allowed: {allowed}", field=field, value=value, allowed=allowed)


def _interval(lo: float | None, hi: float | None, lo_open: bool, hi_open: bool) -> str:
    if lo is not None and hi is not None:
        return f"in {'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'}"
    if lo is not None:
        return f"{'>' if lo_open else '>='} {lo:g}"
    if hi is not None:
        return f"{'<' if hi_open else '<='} {hi:g}"
    return ""


def as_real(value: Any, field: str, *, lo: float | None = None, hi: float | None = None,
            lo_open: bool = False, hi_open: bool = False, unit: str = "",
            cls: type[InputError] = InputError, why: str = "") -> float:
    """A finite real number (not a bool) inside the given range, as float64.

    Parameters
    ----------
    value : Any
        The value to check.
    field : str
        Its name in messages.
    lo, hi : float or None
        Range bounds (closed unless ``lo_open`` / ``hi_open``).
    unit : str
        Unit quoted in messages.
    cls : type
        Error class raised.
    why : str
        Reason of the range, appended to the message.

    Raises
    ------
    InputError
        Of class ``cls``.
    """
    rng = " ".join(x for x in (_interval(lo, hi, lo_open, hi_open), unit, f"({why})" if why else "") if x)
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        reject(field, value, f"a number {rng}".strip(), f"is of type {type(value).__name__}, not a number", cls)
    try:
        x = float(value)
    except (OverflowError, ValueError, TypeError):
        reject(field, value, f"a finite number {rng}".strip(), "is too large for a float64", cls)
    if not math.isfinite(x):
        reject(field, value, f"a finite number {rng}".strip(), "is not finite (NaN and infinity are not allowed)", cls)
    if (lo is not None and (x < lo or (lo_open and x == lo))) or (
            hi is not None and (x > hi or (hi_open and x == hi))):
        reject(field, value, f"a number {rng}".strip(), "is out of range", cls)
    return x


def as_int(value: Any, field: str, *, lo: int | None = None, hi: int | None = None,
           cls: type[InputError] = InputError, why: str = "") -> int:
    """An integer (a float with an integral value is accepted, a bool is not) inside ``[lo, hi]``."""
    rng = " ".join(x for x in (_interval(lo, hi, False, False), f"({why})" if why else "") if x)
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        reject(field, value, f"an integer {rng}".strip(), f"is of type {type(value).__name__}, not an integer", cls)
    if isinstance(value, numbers.Integral):
        n = int(value)
    else:
        try:
            x = float(value)
        except (OverflowError, ValueError, TypeError):
            reject(field, value, f"an integer {rng}".strip(), "is not a finite number", cls)
        if not math.isfinite(x) or not x.is_integer():
            reject(field, value, f"an integer {rng}".strip(), "is not an integer", cls)
        n = int(x)
    if (lo is not None and n < lo) or (hi is not None and n > hi):
        reject(field, value, f"an integer {rng}".strip(), "is out of range", cls)
    return n


def as_mapping(value: Any, field: str, allowed: str, cls: type[InputError] = InputError) -> dict[str, Any]:
    """A JSON object (a ``dict`` with string keys), copied."""
    if not isinstance(value, Mapping):
        kind = "null" if value is None else type(value).__name__
        reject(field, value, allowed, f"is {kind}, not an object" if value is None else f"is of type {kind}, not an object", cls)
    out: dict[str, Any] = {}
    for k, v in value.items():
        if not isinstance(k, str):
            reject(f"{field} key", k, "string keys", "is not a string", cls)
        out[k] = v
    return out


def as_text(value: Any, field: str, *, max_len: int = 200, cls: type[InputError] = InputError) -> str:
    """A printable string of at most ``max_len`` characters."""
    allowed = f"a printable string of at most {max_len} characters"
    if not isinstance(value, str):
        reject(field, value, allowed, f"is of type {type(value).__name__}, not a string", cls)
    if len(value) > max_len:
        reject(field, value, allowed, f"has {len(value)} characters", cls)
    if not value.isprintable():
        reject(field, value, allowed, "holds control characters", cls)
    return value


# ------------------------------------------------------------------------------------------ JSON
def _no_duplicates(source: str, cls: type[InputError]):
    def hook(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
        out: dict[str, Any] = {}
        for k, v in pairs:
            if k in out:
                raise cls(f"{source}: key {k!r} appears twice in one object (the JSON would keep only the last); "
                          "allowed: each key once", field=k, value=v, allowed="each key once")
            out[k] = v
        return out
    return hook


def _no_constant(source: str, cls: type[InputError]):
    def hook(name: str) -> Any:
        raise cls(f"{source}: {name} is not a JSON number; allowed: finite numbers", field=name, value=name,
                  allowed="finite numbers")
    return hook


def loads_json(text: str, source: str, cls: type[InputError] = JSONInputError) -> Any:
    """Parse JSON strictly: a repeated key in one object, ``NaN`` / ``Infinity`` and bad syntax are errors.

    Parameters
    ----------
    text : str
        The JSON text.
    source : str
        What it is (``"case file 'x.json'"``), the start of every message.
    cls : type
        Error class raised.
    """
    try:
        return json.loads(text, object_pairs_hook=_no_duplicates(source, cls),
                          parse_constant=_no_constant(source, cls))
    except InputError:
        raise
    except json.JSONDecodeError as exc:
        raise cls(f"{source} is not valid JSON: {exc}", field=source, allowed="JSON text") from None
    except RecursionError:
        raise cls(f"{source} nests too deeply to read", field=source, allowed="JSON nested < 500 levels") from None
    except ValueError as exc:  # e.g. an integer literal longer than Python's 4300-digit limit
        raise cls(f"{source} is not readable JSON: {exc}", field=source, allowed="JSON text") from None


def read_json_file(path: str | Path, what: str, cls: type[InputError] = JSONInputError) -> Any:
    """Read and strictly parse a JSON file; a missing, unreadable or non-UTF-8 file is an error of ``cls``."""
    p = Path(path)
    source = f"{what} {str(p)!r}"
    if not p.exists():
        raise cls(f"{source} does not exist", field=what, value=str(p), allowed="an existing JSON file")
    if p.is_dir():
        raise cls(f"{source} is a folder; allowed: a JSON file", field=what, value=str(p), allowed="a JSON file")
    try:
        text = p.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise cls(f"{source} is not UTF-8 text ({exc.reason} at byte {exc.start}); allowed: a UTF-8 JSON file",
                  field=what, value=str(p), allowed="UTF-8 JSON") from None
    except OSError as exc:
        raise cls(f"{source} cannot be read: {exc.strerror or exc}", field=what, value=str(p),
                  allowed="a readable JSON file") from None
    return loads_json(text, source, cls)


# ------------------------------------------------------------------------------------------ options
def option_int(value: Any, name: str, lo: int, hi: int, why: str = "") -> int:
    """A command-line integer option inside ``[lo, hi]`` (:class:`OptionError` naming ``name``)."""
    return as_int(value, name, lo=lo, hi=hi, cls=OptionError, why=why)


def option_real(value: Any, name: str, lo: float | None = None, hi: float | None = None, *,
                lo_open: bool = False, hi_open: bool = False, unit: str = "", why: str = "") -> float:
    """A command-line real option inside the given range (:class:`OptionError` naming ``name``)."""
    return as_real(value, name, lo=lo, hi=hi, lo_open=lo_open, hi_open=hi_open, unit=unit, cls=OptionError, why=why)


def steps_option(value: Any, name: str = "--steps", lo: int = 2) -> int:
    """A step count in ``[lo, MAX_STEPS]`` (see :data:`MAX_STEPS` for the memory and time budget)."""
    return option_int(value, name, lo, MAX_STEPS,
                      why=f"the upper bound keeps one solve within {MEMORY_BUDGET_BYTES / 1024 ** 3:g} GiB at "
                          f"{BYTES_PER_STEP / 1000:g} kB per step")


def _folders_above(p: Path, name: str) -> None:
    """Refuse a path that lies under an existing file (its parents must be folders where they exist)."""
    for parent in p.parents:
        if parent.exists() and not parent.is_dir():
            reject(name, str(p), "a path whose folders are folders", f"lies under the file {str(parent)!r}",
                   OptionError)


def output_file(path: str | Path, name: str = "--out") -> Path:
    """An output file path: not an existing folder, and its parent not an existing file."""
    p = Path(path)
    if p.is_dir():
        reject(name, str(p), "a file path (the folder is not overwritten)", "is an existing folder, not a file", OptionError)
    _folders_above(p, name)
    return p


def output_dir(path: str | Path, name: str = "--out") -> Path:
    """An output folder path: not an existing file (nor under one)."""
    p = Path(path)
    if p.exists() and not p.is_dir():
        reject(name, str(p), "a folder (created if missing)", "is an existing file, not a folder", OptionError)
    _folders_above(p, name)
    return p


def one_line(exc: BaseException) -> str:
    """The message of an exception on one line (newlines folded), for the command lines' stderr."""
    return " ".join(str(exc).split())


def refuse(prog: str, exc: Exception) -> int:
    """Print a bad input (a ``ValueError``, or an ``OSError`` naming its file) as one line of stderr,
    ``PROG: error: MESSAGE``, and return the command lines' exit status for it, 2."""
    if isinstance(exc, OSError):
        msg = f"{exc.strerror or exc}: {exc.filename or ''}".rstrip(": ")
    else:
        msg = one_line(exc)
    print(f"{prog}: error: {msg}", file=sys.stderr)
    return 2


class ArgumentParser(argparse.ArgumentParser):
    """``argparse.ArgumentParser`` whose usage errors are one line on stderr (exit status 2).

    argparse prints the usage block and then the error; the project's command lines print only
    ``PROG: error: MESSAGE (see PROG --help)`` so every bad-input exit is one line. Subcommand parsers
    created with ``add_subparsers`` inherit the class.
    """

    def error(self, message: str) -> NoReturn:  # noqa: D401 - argparse API
        self.exit(2, f"{self.prog}: error: {' '.join(message.split())} (see {self.prog} --help)\n")
