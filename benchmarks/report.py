"""Print the newest measured value of each (benchmark, figure) in ``benchmarks/results.csv``.

The benchmark scripts append every figure they print to the table through :mod:`results_log` (one row per
figure and run: ``benchmark, figure, value, unit, commit, date, machine``); this prints, per benchmark and
figure, the row of the latest run with the checkout and the machine it was measured on.

Run: ``python benchmarks/report.py [--benchmark NAME ...] [--figure TEXT] [--csv PATH] [--all]``
(``--all``: every run of each figure, oldest first, instead of the newest only).
"""
from __future__ import annotations

import argparse
import csv
import sys
from pathlib import Path

from results_log import COLUMNS, RESULTS


def read_results(path: Path) -> list[dict[str, str]]:
    """The rows of the results table, in the order they were appended; checks the header."""
    with open(path, encoding="utf-8", newline="") as fh:
        reader = csv.DictReader(fh)
        if tuple(reader.fieldnames or ()) != COLUMNS:
            raise ValueError(f"{path}: header {reader.fieldnames} is not {list(COLUMNS)}")
        return list(reader)


def newest(rows: list[dict[str, str]]) -> list[dict[str, str]]:
    """The latest row of each (benchmark, figure) by its date (ISO 8601, UTC; later in the file wins a tie),
    sorted by benchmark and figure."""
    best: dict[tuple[str, str], tuple[str, int]] = {}
    for i, r in enumerate(rows):
        key = (r["benchmark"], r["figure"])
        if key not in best or (r["date"], i) >= best[key]:
            best[key] = (r["date"], i)
    return [rows[i] for _, (_, i) in sorted(best.items())]


def format_table(rows: list[dict[str, str]]) -> str:
    """Aligned text table: benchmark, figure, value (6 significant digits), unit, date, commit, machine."""
    head = ("benchmark", "figure", "value", "unit", "date", "commit", "machine")
    body = [(r["benchmark"], r["figure"], f"{float(r['value']):.6g}", r["unit"], r["date"], r["commit"], r["machine"])
            for r in rows]
    widths = [max(len(x[i]) for x in [head, *body]) for i in range(len(head))]
    line = "  ".join("{:<%d}" % w for w in widths[:-1]) + "  {}"
    return "\n".join(line.format(*x) for x in [head, *body])


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--benchmark", nargs="+", default=None, help="only these benchmarks (script names, no .py)")
    ap.add_argument("--figure", default=None, help="only figures whose name contains this text")
    ap.add_argument("--csv", type=Path, default=RESULTS, help=f"the table (default {RESULTS})")
    ap.add_argument("--all", action="store_true", help="every run of each figure, oldest first")
    a = ap.parse_args(argv)
    if not a.csv.exists():
        print(f"report: no results table at {a.csv}; run a benchmark script first", file=sys.stderr)
        return 2
    try:
        rows = read_results(a.csv)
    except ValueError as exc:
        print(f"report: {exc}", file=sys.stderr)
        return 2
    rows = [r for r in rows if (a.benchmark is None or r["benchmark"] in a.benchmark)
            and (a.figure is None or a.figure in r["figure"])]
    shown = sorted(rows, key=lambda r: (r["benchmark"], r["figure"], r["date"])) if a.all else newest(rows)
    if not shown:
        print("report: no figure matches", file=sys.stderr)
        return 1
    print(format_table(shown))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
