"""Benchmark of ``rvcad export``: one case, every part, STEP + STL.

Run: ``python benchmarks/bench_export.py [CASE.json] [--tolerance-um 0.1] [--out DIR] [--keep]``.
Prints the wall time of the whole export (including the CAD-kernel import, as a user sees it; the
design check, BRepCheck of every solid and the overlap report are part of it) and per file
(seconds, faces or triangles, size), the time of the design check alone and of the build123d parts
(``rvcad.reducer``), then reads the disc and gear STEP files back with
OpenCASCADE and samples their B-rep edges to measure the largest deviation from the exact cycloid
envelope and involute flanks (um), next to the STL figure (vertices and chord midpoints, float32).
"""
from __future__ import annotations

import sys
import argparse
import resource
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a clone without installing

from results_log import record, slug  # noqa: E402
import rvcad  # noqa: E402
from rvcad.check import check_case  # noqa: E402
from rvcad.errors import load_case  # noqa: E402
from rvcad.export import export_case  # noqa: E402
from rvcad.overlap import overlap_summary  # noqa: E402
from rvcad.parts import Assembly, CycloidDisc, GearPart  # noqa: E402
from rvcad.step import edge_samples, read_step  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("case", nargs="?", default=None, help="case JSON (default nominal)")
    ap.add_argument("--tolerance-um", type=float, default=0.1)
    ap.add_argument("--out", default=None, help="output folder (default a temporary one)")
    ap.add_argument("--keep", action="store_true", help="keep the temporary output folder")
    a = ap.parse_args()
    case = load_case(a.case)
    out = Path(a.out) if a.out else Path(tempfile.mkdtemp(prefix="bench_export_"))
    t0, c0 = time.perf_counter(), time.process_time()
    rep = export_case(case, out, tolerance_um=a.tolerance_um, force=True)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    mb = sum(f.bytes for f in rep.files) / 1e6
    print(f"case {case.name!r}, tolerance {a.tolerance_um} um: {len(rep.files)} files, "
          f"{mb:.1f} MB, {wall:.2f} s wall, {cpu:.2f} s CPU "
          f"(includes importing OpenCASCADE)")
    tag = f"{case.name} {a.tolerance_um:g} um"
    figures = [(slug(f"{tag} export wall"), wall, "s"), (slug(f"{tag} export cpu"), cpu, "s"),
               (slug(f"{tag} export size"), mb, "MB")]
    print(f"{'file':16s} {'seconds':>8s} {'faces':>8s} {'MB':>8s} {'dev um':>8s}")
    groups: dict[str, list] = {}
    for f in rep.files:
        key = "pin*." + f.format if f.part.startswith("pin") else f.file
        groups.setdefault(key, []).append(f)
    for key, fs in groups.items():
        sec = sum(f.seconds for f in fs)
        faces = sum(f.faces or 0 for f in fs)
        mb = sum(f.bytes for f in fs) / 1e6
        dev = max((f.max_deviation_um or 0.0) for f in fs)
        n = f" (x{len(fs)})" if len(fs) > 1 else ""
        print(f"{key + n:16s} {sec:8.2f} {faces:8d} {mb:8.2f} {dev:8.4f}")
    by_fmt = {fmt: sum(f.seconds for f in rep.files if f.format == fmt) for fmt in ("step", "stl")}
    print(f"time by format: STEP {by_fmt['step']:.2f} s, STL {by_fmt['stl']:.2f} s")
    print(f"{overlap_summary(rep.overlaps)}; smallest reachable pin penetration "
          f"{rep.design_check['geometry']['pin_penetration_mm'] * 1e3:.3f} um")
    t = time.perf_counter()
    check_case(case, cache=False)
    figures.append((slug(f"{tag} design check"), time.perf_counter() - t, "s"))
    print(f"design check alone: {figures[-1][1]:.2f} s")
    t = time.perf_counter()
    r = rvcad.reducer(case, check=False)
    vol = sum(r.parts[n].volume for n in r.names)
    print(f"rvcad.reducer: {len(r.names)} build123d solids in {time.perf_counter() - t:.2f} s (total volume "
          f"{vol:.1f} mm^3)")

    asm = Assembly(case)
    tol = a.tolerance_um * 1e-3
    print("read back (OpenCASCADE STEP reader, B-rep edges sampled 200 times each):")
    for name in ("disc0", "disc1", "sun", "planet0"):
        part = asm[name]
        t = time.perf_counter()
        shape = read_step(out / f"{name}.step")
        pts = np.concatenate([p for _, p in edge_samples(shape, 200, kinds=("BSplineCurve",))])
        if isinstance(part, CycloidDisc):
            d = np.abs(part.boundary_distance(pts[:, :2]))
        else:
            assert isinstance(part, GearPart)
            d = part.flank_distance(pts[:, :2])
        stl = part.outline_deviation(tol) * 1e3
        print(f"  {name:8s} STEP max deviation {d.max() * 1e3:.4f} um over {len(pts)} points; "
              f"STL {stl:.4f} um; {time.perf_counter() - t:.2f} s")
        figures += [(slug(f"{tag} {name} step max deviation"), float(d.max() * 1e3), "um"),
                    (slug(f"{tag} {name} stl max deviation"), float(stl), "um")]
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"peak RSS {rss:.0f} MB")
    figures.append((slug(f"{tag} peak rss"), rss, "MB"))
    record("bench_export", figures)
    if not a.out and not a.keep:
        shutil.rmtree(out, ignore_errors=True)
    elif not a.out:
        print(f"kept {out}")


if __name__ == "__main__":
    main()
