"""README.md and docs/ stay true to the code: the README's blocks run (or, for the long ones, their options exist),
its shown output is what the commands print, links resolve, and docs/conventions.md lists every field the code
reads.

README conventions: a ```bash block is run by these tests in an empty folder (the commands as ``python -m``), and
the ```text block right after it is compared with what it printed (numbers to 1e-3 relative, times not compared);
the ```python block is the five-line API, run by tests/test_api.py; a ```console block is too long to run here: the
first must be the CI's commands, and every other line's options (and those of the commands quoted inline) must
appear in the command's ``--help``.
"""
from __future__ import annotations

import contextlib
import io
import json
import math
import os
import re
import runpy
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
#: Command name -> module run as ``python -m`` (pyproject's [project.scripts], checked below).
COMMANDS = {"rvcad": "rvcad", "rvdyn": "rvdyn", "rsm": "rsm", "rv-stackup": "rvstudy", "rv-calibrate": "rvcalib"}


def blocks(path: Path = README) -> list[tuple[str, str]]:
    """(language, code) of every fenced block, in order."""
    return re.findall(r"^```(\w*)\n(.*?)^```", path.read_text(encoding="utf-8"), re.S | re.M)


def runnable() -> list[tuple[int, str, str, str | None]]:
    """(index, language, code, shown output or None) of the README's bash and python blocks."""
    bs = blocks()
    return [(i, lang, code, bs[i + 1][1] if i + 1 < len(bs) and bs[i + 1][0] == "text" else None)
            for i, (lang, code) in enumerate(bs) if lang in ("bash", "python")]


def _env() -> dict[str, str]:
    return {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]),
            "MPLBACKEND": "Agg"}


TIME = re.compile(r"\d+(\.\d+)? s\b")
NUMBER = re.compile(r"[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?")


def same_output(shown: str, printed: str, rel: float = 1e-3) -> list[str]:
    """Lines where ``printed`` differs from ``shown``: the words must be equal, the numbers within ``rel``
    (or 1e-3 absolute), durations (``7.4 s``) are not compared. Returns the differing lines (empty: same)."""
    a, b = shown.strip().splitlines(), printed.strip().splitlines()
    if len(a) != len(b):
        return [f"{len(a)} lines shown, {len(b)} printed:\n{printed}"]
    bad = []
    for x, y in zip(a, b):
        x, y = TIME.sub("T s", x), TIME.sub("T s", y)
        nx, ny = [float(m.group(0)) for m in NUMBER.finditer(x)], [float(m.group(0)) for m in NUMBER.finditer(y)]
        if NUMBER.sub("#", x).split() != NUMBER.sub("#", y).split() or len(nx) != len(ny) or not all(
                math.isclose(p, q, rel_tol=rel, abs_tol=1e-3) for p, q in zip(nx, ny)):
            bad.append(f"shown:   {x}\nprinted: {y}")
    return bad


def test_same_output_compares_words_and_numbers_but_not_times():
    shown = "cases: 47 solved; wall time 7.4 s\n  TE pp 15.6779 arcsec"
    assert same_output(shown, "cases: 47 solved; wall time 12.0 s\n  TE pp 15.67795 arcsec") == []
    assert same_output(shown, "cases: 46 solved; wall time 7.4 s\n  TE pp 15.6779 arcsec")
    assert same_output(shown, "cases: 47 solved; wall time 7.4 s\n  TE mean 15.6779 arcsec")
    assert same_output(shown, "cases: 47 solved; wall time 7.4 s")


def test_readme_is_short_and_has_its_picture():
    text = README.read_text(encoding="utf-8")
    assert len(text.splitlines()) <= 250
    pictures = re.findall(r"!\[[^\]]*\]\(([^)]+)\)", text)
    assert len(pictures) == 1 and (ROOT / pictures[0]).stat().st_size < 400_000
    assert "../shared" not in text


def test_readme_commands_are_the_ci_commands_and_the_packaged_scripts():
    first = [b for lang, b in blocks() if lang == "console"][0].strip().splitlines()
    assert first == ["pip install . && rv-stackup --out rv-stackup-out",
                     "pip install '.[test]' && python -m pytest -q -n 2 --dist loadgroup tests"]
    ci = (ROOT / ".ci" / "run").read_text(encoding="utf-8").strip().splitlines()
    assert ci[-1] == first[1]  # CI runs exactly the README's test command
    with open(ROOT / "pyproject.toml", "rb") as fh:
        scripts = tomllib.load(fh)["project"]["scripts"]
    assert scripts == {name: f"{mod}.cli:main" for name, mod in COMMANDS.items()}
    assert all((ROOT / mod / "__main__.py").is_file() for mod in COMMANDS.values())


@pytest.mark.slow
def test_readme_console_lines_use_options_the_commands_have():
    """The blocks too long to run here: each line's command exists and has every option the line names."""
    lines = [ln for lang, b in blocks()[1:] if lang == "console" for ln in b.strip().splitlines()]
    lines += [b.strip() for b in re.findall(r"`((?:rv-stackup|rv-calibrate|rvdyn|rvcad|rsm) [^`]*)`", README.read_text())]
    assert any(ln.startswith("rv-calibrate") for ln in lines)
    helps: dict[tuple[str, ...], str] = {}
    for ln in lines:
        words = ln.split()
        cmd = (words[0],) + ((words[1],) if words[0] in ("rvdyn", "rvcad", "rsm") and len(words) > 1
                             and not words[1].startswith(("-", "[")) else ())
        if cmd not in helps:
            helps[cmd] = _help(cmd)
        for opt in re.findall(r"(?<![\w-])--[a-z][\w-]*", ln):
            assert opt in helps[cmd], f"{ln!r}: {opt} is not an option of {' '.join(cmd)}"


def _help(cmd: tuple[str, ...]) -> str:
    """What ``python -m <module> [sub] --help`` prints, run in this process (the module as ``__main__``): the same
    parser, without a new interpreter's imports."""
    out, argv = io.StringIO(), sys.argv
    sys.argv = [cmd[0], *cmd[1:], "--help"]
    try:
        with contextlib.redirect_stdout(out), pytest.raises(SystemExit) as done:
            runpy.run_module(COMMANDS[cmd[0]], run_name="__main__", alter_sys=False)
    finally:
        sys.argv = argv
    assert done.value.code in (0, None), (cmd, out.getvalue())
    return out.getvalue()


@pytest.mark.slow
@pytest.mark.parametrize("index", [i for i, lang, _, _ in runnable() if lang == "bash"])
def test_readme_bash_block_prints_what_the_readme_shows(index, tmp_path):
    _, _, code, shown = next(r for r in runnable() if r[0] == index)
    shims = "".join(f'{name}() {{ "{sys.executable}" -m {mod} "$@"; }}\n' for name, mod in COMMANDS.items())
    done = subprocess.run(["bash", "-euo", "pipefail", "-c", shims + code], cwd=tmp_path, env=_env(),
                          capture_output=True, text=True, timeout=1200)
    assert done.returncode == 0, done.stderr[-3000:]
    assert shown is not None, "a bash block is followed by the text block of its output"
    assert same_output(shown, done.stdout) == []


def test_readme_and_docs_links_resolve():
    for doc in [README, *sorted((ROOT / "docs").glob("*.md"))]:
        for target in re.findall(r"\]\(([^)#]+)(?:#[^)]*)?\)", doc.read_text(encoding="utf-8")):
            if target.startswith(("http://", "https://")):
                continue
            path = (doc.parent / target).resolve()
            assert path.exists(), f"{doc.name}: link {target} does not resolve"


# ---------------------------------------------------------------------------------------------- conventions
def test_conventions_lists_every_field_the_code_reads():
    import dataclasses

    from rvcad.errors import CASE_KEYS, ERROR_TYPES
    from rvcad.params import Design
    from rvdyn.options import MODEL_OPTIONS

    text = (ROOT / "docs" / "conventions.md").read_text(encoding="utf-8")
    names = {f.name for f in dataclasses.fields(Design)} | set(MODEL_OPTIONS) | set(ERROR_TYPES) | set(CASE_KEYS)
    missing = sorted(n for n in names if f"`{n}`" not in text)
    assert missing == [], f"docs/conventions.md does not list {missing}"
    for key, et in ERROR_TYPES.items():  # the error table: letter and unit as the code has them
        row = re.search(rf"^\| `{key}` \| (\w)[^|]* \| (µm|deg) \|", text, re.M)
        assert row and row.group(1) == et.letter and row.group(2) == {"um": "µm", "deg": "deg"}[et.unit], key
    for key, o in MODEL_OPTIONS.items():  # the model table: the default as the code has it
        row = re.search(rf"^\| `{key}` \| [^|]* \| ([^|]+) \|", text, re.M)
        if row:
            shown = row.group(1).strip().strip('`"')
            assert shown == str(o.default) or (not o.choices and float(shown) == float(o.default)), key


@pytest.mark.parametrize("doc", ["conventions.md", "guide.md"])
def test_docs_json_examples_are_valid_cases(doc):
    from rvcad.errors import Case

    found = [b for lang, b in blocks(ROOT / "docs" / doc) if lang == "json"]
    assert found
    for b in found:
        Case.from_dict(json.loads(b))
