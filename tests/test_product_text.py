"""Product text speaks of the product: no lab notes in README.md, docs/, examples/ or any package's modules.

A lab note is text about how the code came to be rather than what it does: numbered run headings ("stop 12"),
dates of runs or machines ("2026-11-27"), the seeds a past development was tried on ("realistic seed 6",
"seeds 1-4"), issue numbers, commit hashes and branch names. Measured figures live in benchmarks/results.csv
(``python benchmarks/report.py``), which this test does not read.
"""
from __future__ import annotations

import re
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

#: What a lab note looks like (case-insensitive), each with what it stands for.
LAB_NOTES: dict[str, str] = {
    r"\bstops? \d+": "a numbered run heading (stop 12)",
    r"\b(19|20)\d\d-[01]\d-[0-3]\d\b": "a date (2026-11-27)",
    r"(?<![-\w.])(realistic |unseen |development )?seeds? \d+(\s*(-|to|and|,)\s*\d+)*\b(?!\s*[=:])":
        "a seed of past development (seed 6, seeds 1-4)",
    r"\bissues? #?\d+\b": "an issue number",
    r"\b(commit|merge|version) [0-9a-f]{7,40}\b": "a commit hash",
    r"\bbranch `[\w./-]+`": "a branch name",
    r"\b(on|of) (the|this) (\d-core )?machine of\b|\bthe machine of \d": "a dated machine",
}
PATTERN = re.compile("|".join(f"(?:{p})" for p in LAB_NOTES), re.IGNORECASE)


def _packages() -> list[str]:
    with open(ROOT / "pyproject.toml", "rb") as fh:
        return list(tomllib.load(fh)["tool"]["setuptools"]["packages"])


def _scopes() -> dict[str, list[Path]]:
    """Scope name -> files: README.md, docs/ (Markdown), examples/ (scripts and Markdown), each package's .py."""
    scopes = {"README.md": [ROOT / "README.md"],
              "docs": sorted((ROOT / "docs").rglob("*.md")),
              "examples": sorted(p for ext in ("*.py", "*.md") for p in (ROOT / "examples").rglob(ext))}
    scopes.update({pkg: sorted((ROOT / pkg).rglob("*.py")) for pkg in _packages()})
    return scopes


def lab_notes(text: str) -> list[tuple[int, str]]:
    """(line number, matched text) of every lab note in ``text``."""
    return [(text.count("\n", 0, m.start()) + 1, m.group(0)) for m in PATTERN.finditer(text)]


@pytest.mark.parametrize("text", [
    "## Stop 31", "the code of stop 29 took 113.9 s", "on the machine of 2026-11-27", "realistic seed 6 fails",
    "seeds 1-4 name every effect", "Seeds 1, 2 and 8 pass", "(issue 10)", "issue #12", "commit 197f86f",
    "not kept (branch `small-trials`)", "before (merge 3fa90c3)", "on the 2-core machine of 2026-11-26",
    "seed 5 (development set)",
])
def test_lab_notes_are_found(text):
    assert lab_notes(text), text


@pytest.mark.parametrize("text", [
    "rv-stackup --seed 1", "`--seed 20240` makes a rerun bit-identical", "rng = np.random.default_rng(seed=3)",
    "the loop stops at the term limit", "stop the refits", "raise an issue", "the seed: 7",
    "a loading branch ``tau = tau_el + tau_f``", "0.1 deg at 2.5e-6 and 40 pins", "a 12-tooth sun",
])
def test_product_wording_is_not_a_lab_note(text):
    assert lab_notes(text) == [], text


def test_every_scope_has_files():
    scopes = _scopes()
    assert scopes["README.md"][0].is_file() and scopes["docs"] and scopes["examples"]
    assert {"rvcad", "rvdyn", "rsm", "rvstudy", "rvpaper", "rvcalib"} <= set(scopes)
    assert all(scopes[p] for p in _packages())


@pytest.mark.parametrize("scope", list(_scopes()))
def test_no_lab_notes_in_product_text(scope):
    found = {str(p.relative_to(ROOT)): hits for p in _scopes()[scope]
             if (hits := lab_notes(p.read_text(encoding="utf-8")))}
    shown = "; ".join(f"{f}:{ln}: {m!r}" for f, hits in found.items() for ln, m in hits[:5])
    assert not found, f"{sum(map(len, found.values()))} lab notes in {scope} (first per file): {shown}"
