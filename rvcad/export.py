"""Export of one case: a STEP and an STL file per part, the assembly, and a manifest.

Layout of the output folder (``rvcad export --out DIR``)::

    DIR/sun.step  sun.stl         stage I sun gear          (own frame, see below)
    DIR/planet0.* planet1.*       planet gears              (own frames)
    DIR/crank0.*  crank1.*        crankshafts               (own frames)
    DIR/flange.*  carrier.*       flange and carrier plates (own frame: main axis, output angle 0)
    DIR/disc0.*   disc1.*         cycloid discs             (own frames)
    DIR/housing.* pin00..pin39.*  pin housing and pins      (world frame, fixed)
    DIR/assembly.step             every part placed at the input angle, labelled by part name
    DIR/assembly.stl              every part placed at the input angle, one mesh
    DIR/case.json                 the validated case that was exported
    DIR/manifest.json             content key and size of every file (for the rerun cache)

Own frame: the frame that :meth:`rvcad.geometry.ReducerGeometry.placement` moves (rotate about +z
by the placement angle, then translate); z is already the assembly's axial position. Fixed parts
are in the world frame. Placing the own-frame files with the placements gives the assembly files.

Every file is written to a temporary file in the same folder and renamed (``os.replace``), so an
interrupted export never leaves a half-written file under a final name. A rerun skips every file
whose content key (case key, tolerance, format, input angle for the assembly, exporter version) is
unchanged and whose size matches the manifest.
"""
from __future__ import annotations

import fnmatch
import hashlib
import json
import math
import os
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Callable, Sequence

from rvcad.atomic import atomic_path
from rvcad.errors import Case
from rvcad.assembly import Assembly
from rvcad.atomic import remove_stale_temps
from rvcad.check import check_case
from rvcad.geometry import ReducerGeometry
from rvcad.occ import check_solid
from rvcad.overlap import overlap_summary, overlaps
from rvcad.plan import Part
from rvcad.step import count_faces, edge_samples, read_step, step_writer
from rvcad.stl import stl_bytes

#: Default tolerance of the export, um: chord sagitta of the STL and budget of the STEP B-splines.
DEFAULT_TOLERANCE_UM = 0.1

#: Accepted tolerance range, um (below 0.01 um float32 STL rounding dominates; above 100 um the
#: parts are no longer the analysed geometry).
TOLERANCE_RANGE_UM = (0.01, 100.0)

#: File formats.
FORMATS = ("step", "stl")

#: Version of the exported content; bump when the geometry or file layout changes so that cached
#: files are rewritten.
EXPORT_VERSION = "1"

#: Name of the cache manifest in the output folder.
MANIFEST = "manifest.json"


@dataclass
class ExportedFile:
    """One output file.

    Attributes
    ----------
    file : str
        File name inside the output folder.
    part : str
        Part name (``assembly`` for the assembly files, ``case`` for case.json).
    format : str
        ``step``, ``stl`` or ``json``.
    bytes : int
        File size.
    seconds : float
        Time spent building and writing it (0 when skipped).
    skipped : bool
        True when the manifest showed it up to date.
    faces : int or None
        B-rep faces (STEP) or triangles (STL).
    max_deviation_um : float or None
        Largest distance of the exact-curve outline (cycloid envelope, involute flanks) from the
        exact curve: STL vertices and chord midpoints after float32 rounding, STEP B-splines of
        each distinct curve piece sampled 32 times per knot span; 0 for parts made of lines and
        circles only (exact in STEP, chords within the sagitta in STL).
    """

    file: str
    part: str
    format: str
    bytes: int = 0
    seconds: float = 0.0
    skipped: bool = False
    faces: int | None = None
    max_deviation_um: float | None = None


@dataclass
class ExportReport:
    """What an export did (the ``--json`` object of ``rvcad export``)."""

    out_dir: str
    case_name: str
    case_key: str
    tolerance_um: float
    theta_in_deg: float
    formats: list[str]
    files: list[ExportedFile] = field(default_factory=list)
    seconds: float = 0.0
    design_check: dict[str, Any] = field(default_factory=dict)
    pose: str = "ideal"
    overlaps: dict[str, Any] = field(default_factory=dict)
    cleaned: list[str] = field(default_factory=list)
    removed_temps: list[str] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["written"] = sum(1 for f in self.files if not f.skipped)
        d["skipped"] = sum(1 for f in self.files if f.skipped)
        d["total_bytes"] = sum(f.bytes for f in self.files)
        return d

    def summary(self) -> str:
        """Human summary (several lines)."""
        w = [f for f in self.files if not f.skipped]
        s = [f for f in self.files if f.skipped]
        tot = sum(f.bytes for f in self.files)
        dev = [f.max_deviation_um for f in self.files if f.max_deviation_um]
        lines = [f"rvcad export: case {self.case_name!r} (key {self.case_key}) -> {self.out_dir}",
                 f"  {len(w)} file(s) written, {len(s)} up to date, {tot / 1e6:.1f} MB, {self.seconds:.1f} s; "
                 f"formats {','.join(self.formats)}, tolerance {self.tolerance_um:g} um, "
                 f"input angle {self.theta_in_deg:g} deg, {self.pose} pose"]
        if self.cleaned:
            lines.append(f"  --force: removed {len(self.cleaned)} file(s) of another export from the folder")
        if self.removed_temps:
            lines.append(f"  removed {len(self.removed_temps)} temporary file(s) left by an interrupted export")
        if self.overlaps:
            lines.append(f"  {overlap_summary(self.overlaps)}")
        if dev:
            lines.append(f"  largest exact-curve deviation {max(dev):.4f} um (cycloid envelope, involute flanks)")
        dc = self.design_check
        if dc:
            lines.append(f"  design check: {'ok' if dc.get('ok') else 'PROBLEMS'}; undercut: "
                         f"{'yes' if dc.get('undercut') else 'no'}; min pin gap {dc['pins']['min_gap_mm']:.4f} mm; "
                         f"disc tip to housing bore {dc['disc_tip_to_housing_bore_mm']:.4f} mm")
            if dc.get("geometry"):
                lines.append(f"    contact overlap no solver pose avoids: "
                             f"{max(dc['geometry']['pin_penetration_mm'], 0.0) * 1e3:.2f} um (refused above 100 um)")
            for m in dc.get("messages", []):
                lines.append(f"    {m}")
        big = sorted(w, key=lambda f: -f.seconds)[:5]
        if big:
            lines.append("  slowest: " + ", ".join(f"{f.file} {f.seconds:.2f} s" for f in big))
        return "\n".join(lines)


def atomic_write(path: Path, writer: Callable[[Path], None]) -> int:
    """Run ``writer(tmp)`` on a temporary file in the same folder, then rename it to ``path``."""
    with atomic_path(path) as tmp:
        writer(tmp)
        size = tmp.stat().st_size
        if size == 0:
            raise RuntimeError(f"writing {path.name} produced an empty file")
    return size


def _write_bytes(data: bytes) -> Callable[[Path], None]:
    def w(p: Path) -> None:
        with open(p, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
    return w


def content_key(case: Case, tolerance_um: float, fmt: str, file: str, theta_in_deg: float | None = None,
                state: tuple[float, Sequence[float]] | None = None) -> str:
    """Cache key of one file: sha256 of case key, tolerance, format, file, input angle, explicit state
    (output and crank angles, when the assembly is not placed by the ideal kinematics), version."""
    d = {"case": case.key(), "tolerance_um": float(tolerance_um), "format": fmt, "file": file,
         "theta_in_deg": theta_in_deg, "version": EXPORT_VERSION}
    if state is not None:
        d["state_rad"] = [float(state[0])] + [float(v) for v in state[1]]
    return hashlib.sha256(json.dumps(d, sort_keys=True).encode()).hexdigest()[:24]


def _load_manifest(out: Path) -> dict[str, Any]:
    p = out / MANIFEST
    try:
        m = json.loads(p.read_text(encoding="utf-8"))
        if isinstance(m, dict) and isinstance(m.get("files"), dict):
            return m
    except (OSError, ValueError):
        pass
    return {"files": {}}


class ExportFolderError(ValueError):
    """The output folder holds the export of another case (or tolerance); refused without ``force``."""


def output_names(assembly: Assembly) -> list[str]:
    """Every file name an export of this assembly may write."""
    names = [f"{n}.{x}" for n in list(assembly.parts) + ["assembly"] for x in FORMATS]
    return names + ["case.json", MANIFEST]


def _claim_folder(out: Path, case: Case, tol_um: float, force: bool) -> list[str]:
    """Refuse (or with ``force`` clean) a folder whose manifest belongs to another case or tolerance.

    Returns the names of the removed files (only those the old manifest lists, plus its case.json
    and manifest).
    """
    if not (out / MANIFEST).is_file():
        return []
    m = _load_manifest(out)
    old_key, old_tol = m.get("case_key"), m.get("tolerance_um")
    if old_key is None or (old_key == case.key() and old_tol == tol_um):
        return []
    listed = [f for f in m["files"] if isinstance(f, str) and "/" not in f and not f.startswith(".")]
    present = [f for f in dict.fromkeys(listed + ["case.json", MANIFEST]) if (out / f).is_file()]
    if not force:
        raise ExportFolderError(
            f"--out {str(out)!r} holds the export of case {m.get('case_name')!r} (key {old_key}, tolerance "
            f"{old_tol} um) in {len(present)} file(s); refusing to mix case {case.name!r} (key {case.key()}, "
            f"tolerance {tol_um:g} um) into it: use another folder, or --force to remove those files first")
    for f in present:
        (out / f).unlink(missing_ok=True)
    return present


def select_parts(assembly: Assembly, patterns: Sequence[str] | None) -> list[str]:
    """Part names matching any of the shell patterns (``disc*``, ``pin0?``), plus ``assembly``.

    ``None`` selects everything. Raises ``ValueError`` for a pattern that matches nothing.
    """
    names = list(assembly.parts) + ["assembly"]
    if not patterns:
        return names
    out: list[str] = []
    for pat in patterns:
        hit = [n for n in names if fnmatch.fnmatchcase(n, pat)]
        if not hit:
            raise ValueError(f"--parts pattern {pat!r} matches no part; parts are: {', '.join(names[:12])}, ... "
                             f"pin00..pin{len(assembly.geometry.pin_centers) - 1:02d}, assembly")
        out += [h for h in hit if h not in out]
    return [n for n in names if n in out]


def check_tolerance(tolerance_um: float) -> float:
    """Validate the export tolerance (um); returns it as float."""
    lo, hi = TOLERANCE_RANGE_UM
    if isinstance(tolerance_um, bool) or not isinstance(tolerance_um, (int, float)) \
            or not math.isfinite(tolerance_um) or not lo <= tolerance_um <= hi:
        raise ValueError(f"tolerance {tolerance_um!r} um must be a number in [{lo}, {hi}] um")
    return float(tolerance_um)


def _check_formats(formats: Sequence[str]) -> list[str]:
    """The requested formats in the order of :data:`FORMATS` (``ValueError`` for an unknown or no format)."""
    fmts = [f.strip().lower() for f in formats]
    for f in fmts:
        if f not in FORMATS:
            raise ValueError(f"format {f!r} is unknown; allowed: {', '.join(FORMATS)}")
    if not fmts:
        raise ValueError("no format given; allowed: step, stl")
    return [f for f in FORMATS if f in fmts]


def _prepare_folder(out: Path, case: Case, tol_um: float, force: bool, asm: Assembly
                    ) -> tuple[list[str], list[str], dict[str, Any]]:
    """Claim (or with ``force`` clean) the output folder, remove stale temporary files and create it; returns
    the removed files of another export, the removed temp files and the manifest (empty if missing or outdated)."""
    if out.exists() and not out.is_dir():
        raise ValueError(f"--out {str(out)!r} exists and is not a folder")
    cleaned = _claim_folder(out, case, tol_um, force)
    temps = [p.name for p in remove_stale_temps(out, output_names(asm))]
    out.mkdir(parents=True, exist_ok=True)
    manifest = _load_manifest(out)
    if manifest.get("version") != EXPORT_VERSION:
        manifest = {"files": {}}
    return cleaned, temps, manifest


@dataclass
class _Emitter:
    """Writes the files of one export into ``out``, skipping those the manifest shows up to date
    (unless ``force``), and records each one in the manifest, the report and ``progress``."""

    out: Path
    case: Case
    tol_um: float
    theta_in_deg: float
    force: bool
    manifest: dict[str, Any]
    report: ExportReport
    progress: Callable[[ExportedFile], None] | None
    valid: set[str] = field(default_factory=set)

    def checked(self, shape: Any, name: str) -> Any:
        """``shape`` after BRepCheck (once per part and run)."""
        if name not in self.valid:
            check_solid(shape, name)
            self.valid.add(name)
        return shape

    def save_manifest(self) -> None:
        """Write the manifest (atomically) with the case, tolerance (um) and input angle (deg)."""
        self.manifest.update({"version": EXPORT_VERSION, "case_name": self.case.name, "case_key": self.case.key(),
                              "tolerance_um": self.tol_um, "theta_in_deg": float(self.theta_in_deg)})
        data = json.dumps(self.manifest, indent=1, sort_keys=True).encode()
        atomic_write(self.out / MANIFEST, _write_bytes(data))

    def emit(self, fname: str, part: str, fmt: str, key: str,
             build: Callable[[], tuple[Callable[[Path], None], int | None, float | None]]) -> None:
        """Write ``fname`` with the writer ``build()`` returns (with its face count and deviation, um),
        unless the manifest holds it under ``key`` with the size on disk."""
        path = self.out / fname
        entry = self.manifest["files"].get(fname)
        if (not self.force and entry and entry.get("key") == key and path.is_file()
                and path.stat().st_size == entry.get("bytes")):
            ef = ExportedFile(fname, part, fmt, bytes=int(entry["bytes"]), skipped=True,
                              faces=entry.get("faces"), max_deviation_um=entry.get("max_deviation_um"))
        else:
            t0 = time.perf_counter()
            writer, faces, dev = build()
            size = atomic_write(path, writer)
            ef = ExportedFile(fname, part, fmt, bytes=size, seconds=time.perf_counter() - t0, faces=faces,
                              max_deviation_um=dev)
            self.manifest["files"][fname] = {"key": key, "bytes": size, "faces": faces, "max_deviation_um": dev}
            self.save_manifest()
        self.report.files.append(ef)
        if self.progress is not None:
            self.progress(ef)


def _emit_parts(em: _Emitter, asm: Assembly, names: Sequence[str], fmts: Sequence[str], tol: float) -> None:
    """Write the own-frame STEP and STL files of the selected parts (``tol``: tolerance, mm)."""
    case, tol_um = em.case, em.tol_um
    for name in names:
        if name == "assembly":
            continue
        part: Part = asm[name]
        if "step" in fmts:
            def build_step(part: Part = part) -> tuple[Callable[[Path], None], int | None, float | None]:
                s = em.checked(part.shape(tol), part.name)
                return step_writer([(part.name, s, None)], part.name), count_faces(s), part.spline_deviation(tol) * 1e3
            em.emit(f"{name}.step", name, "step", content_key(case, tol_um, "step", f"{name}.step"), build_step)
        if "stl" in fmts:
            def build_stl(part: Part = part) -> tuple[Callable[[Path], None], int | None, float | None]:
                m = part.mesh(tol)
                dev = part.outline_deviation(tol) * 1e3
                return _write_bytes(stl_bytes(m, f"rvcad {case.name} {part.name} own frame mm")), len(m.faces), dev
            em.emit(f"{name}.stl", name, "stl", content_key(case, tol_um, "stl", f"{name}.stl"), build_stl)


def _emit_assembly(em: _Emitter, asm: Assembly, fmts: Sequence[str], tol: float) -> None:
    """Write the assembly files, every part placed at the assembly's pose (``tol``: tolerance, mm)."""
    case, tol_um = em.case, em.tol_um
    th = float(em.theta_in_deg)
    if "step" in fmts:
        def build_asm_step() -> tuple[Callable[[Path], None], int | None, float | None]:
            items = asm.shapes(tol)
            for n, sh, _ in items:
                em.checked(sh, n)
            return (step_writer(items, f"rv-reducer {case.name}"), sum(count_faces(s) for _, s, _ in items),
                    None)
        em.emit("assembly.step", "assembly", "step", content_key(case, tol_um, "step", "assembly.step", th, asm.state),
                build_asm_step)
    if "stl" in fmts:
        def build_asm_stl() -> tuple[Callable[[Path], None], int | None, float | None]:
            m = asm.mesh(tol)
            return (_write_bytes(stl_bytes(m, f"rvcad {case.name} assembly theta_in {th:g} deg mm")),
                    len(m.faces), None)
        em.emit("assembly.stl", "assembly", "stl", content_key(case, tol_um, "stl", "assembly.stl", th, asm.state),
                build_asm_stl)


def export_case(case: Case | None, out_dir: str | Path, formats: Sequence[str] = FORMATS,
                tolerance_um: float = DEFAULT_TOLERANCE_UM, theta_in_deg: float = 0.0,
                parts: Sequence[str] | None = None, force: bool = False,
                progress: Callable[[ExportedFile], None] | None = None,
                state: tuple[float, Sequence[float]] | None = None, pose: str | None = None) -> ExportReport:
    """Write the STEP and STL files of every part and of the assembly.

    Parameters
    ----------
    case : Case or None
        Validated case (``None``: nominal design).
    out_dir : str or Path
        Output folder (created if missing).
    formats : sequence of {"step", "stl"}
        Formats to write.
    tolerance_um : float
        Largest deviation of the exported geometry from the exact one, um (default 0.1): chord
        sagitta of the STL, fit budget of the STEP B-splines (lines and circles are exact in STEP).
    theta_in_deg : float
        Input angle at which the assembly files place the moving parts, degrees.
    parts : sequence of str or None
        Shell patterns of the parts to write (``disc*``, ``pin00``, ``assembly``); default all.
    force : bool
        Rewrite files even when the manifest shows them up to date, and clean a folder that holds
        the export of another case or tolerance (otherwise refused).
    progress : callable or None
        Called with each :class:`ExportedFile` when it is done.
    state : (theta_out rad, (psi_0, ..., psi_(n-1)) rad: one per crank) or None
        Place the assembly at this state (e.g. the pose solved by ``rvdyn``) instead of the ideal
        kinematics at ``theta_in_deg``.
    pose : str or None
        Name of the pose for the report (default ``ideal``, or ``state`` when one is given).

    Returns
    -------
    ExportReport

    Raises
    ------
    ValueError
        Bad format, tolerance, angle or part pattern (the message names it);
        :class:`rvcad.check.DesignError` for a case that cannot give valid solids (the message
        names the field; nothing is written); :class:`ExportFolderError` for a folder of another
        export; :class:`rvcad.occ.InvalidSolidError` if a built solid fails BRepCheck.
    OSError
        The output folder cannot be created or written.
    """
    t_start = time.perf_counter()
    case = case if case is not None else Case.from_dict({"name": "nominal"})
    fmts = _check_formats(formats)
    tol_um = check_tolerance(tolerance_um)
    if isinstance(theta_in_deg, bool) or not isinstance(theta_in_deg, (int, float)) or not math.isfinite(theta_in_deg):
        raise ValueError(f"theta_in_deg {theta_in_deg!r} must be a finite number of degrees")
    tol = tol_um * 1e-3
    geometry = ReducerGeometry(case)
    margins = check_case(case, geometry)  # refuses a case that cannot give valid solids: nothing written yet
    asm = Assembly(case, float(theta_in_deg), state=state, geometry=geometry)
    names = select_parts(asm, parts)
    out = Path(out_dir)
    cleaned, temps, manifest = _prepare_folder(out, case, tol_um, force, asm)
    report = ExportReport(out_dir=str(out), case_name=case.name, case_key=case.key(), tolerance_um=tol_um,
                          theta_in_deg=float(theta_in_deg), formats=fmts,
                          design_check={**asm.design_check(), "geometry": margins},
                          pose=pose or ("ideal" if state is None else "state"), overlaps=overlaps(asm, tol),
                          cleaned=cleaned, removed_temps=temps)
    report.overlaps["pose"] = report.pose
    em = _Emitter(out, case, tol_um, theta_in_deg, force, manifest, report, progress)
    case_json = json.dumps(case.to_dict(), indent=1, sort_keys=True).encode()
    em.emit("case.json", "case", "json", content_key(case, tol_um, "json", "case.json"),
            lambda: (_write_bytes(case_json), None, None))
    _emit_parts(em, asm, names, fmts, tol)
    if "assembly" in names:
        _emit_assembly(em, asm, fmts, tol)
    report.seconds = time.perf_counter() - t_start
    return report


__all__ = ["DEFAULT_TOLERANCE_UM", "EXPORT_VERSION", "FORMATS", "ExportFolderError", "ExportReport", "ExportedFile",
           "content_key", "edge_samples", "export_case", "output_names", "read_step", "select_parts"]
