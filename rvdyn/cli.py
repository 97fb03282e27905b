"""Command line of rvdyn: ``rvdyn te`` (TE of one case) and ``rvdyn stiffness`` (the hysteresis curve and
datasheet figures).

The single-factor screen and factor sweeps belong to the study: ``rv-stackup --stages screen``.

Each command prints a human summary by default; ``--json`` prints one JSON object on stdout.
Bad input prints a message naming the field to stderr and exits with status 2.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from typing import Any

from rvcad.errors import MAX_LOAD_NM, load_case
from rvcad import validation as v
from rvdyn.contacts import ContactLaw
from rvdyn.options import CONTACT_LAWS
from rvdyn.solver import law_from_model
from rvdyn.te import SOLVERS, backlash, run_te


def _finite(x: float) -> Any:
    return x if isinstance(x, (int, str)) or (isinstance(x, float) and math.isfinite(x)) else None


def _law(args: argparse.Namespace, case) -> ContactLaw:
    """The contact law: the case's ``model`` (contact, contact_K_N_per_mm_n, contact_n), each overridden
    by the command line's --contact, --K, --n, --rigid."""
    base = law_from_model(case.model)
    kind = args.contact if args.contact is not None else base.kind
    if kind == "physical" and (args.K is not None or args.n is not None):
        raise ValueError("--K and --n set the impact law; they need --contact impact (the physical law "
                         "takes its stiffness from the geometry and the materials)")
    return ContactLaw(K=base.K if args.K is None else args.K, n=base.n if args.n is None else args.n,
                      rigid=args.rigid, kind=kind)


def build_parser() -> argparse.ArgumentParser:
    p = v.ArgumentParser(prog="rvdyn", description="Quasi-static transmission error of an RV reducer.")
    sub = p.add_subparsers(dest="command", required=True)
    te = sub.add_parser("te", help="TE curve of one case (CSV) and its statistics",
                        description="Solve the quasi-static meshing equilibrium at N input angles and write "
                                    "TE.csv with input_deg, output_deg, te_arcsec (TE = theta_out - theta_in/121, "
                                    "arcsec, positive = output leads), contacts and peak_force_N.")
    te.add_argument("case", nargs="?", default=None, help="case JSON (conventions.md); default: nominal, no errors")
    te.add_argument("--solver", choices=SOLVERS, default="analytic",
                    help="fcl: python-fcl distances on the exported meshes; analytic: exact envelope (default)")
    te.add_argument("--steps", type=int, default=720, help="steps over the revolutions (>= 2, default 720)")
    te.add_argument("--revolutions", type=float, default=1.0, help="output revolutions (default 1)")
    te.add_argument("--out", default=None, help="TE.csv to write (atomically); omitted: no file")
    te.add_argument("--load-Nm", dest="load_Nm", type=float, default=None,
                    help="output load torque in N m (default: the case's, 20); 0 = rigid single-flank limit")
    te.add_argument("--direction", type=int, choices=(1, -1), default=None, help="+1 or -1 (default: the case's)")
    te.add_argument("--contact", choices=CONTACT_LAWS, default=None,
                    help="contact law: physical (Hertz line contact, ISO 6336 mesh stiffness, bearing and crankshaft "
                         "compliance) or impact (paper Eq. 1, F = K delta^n, to reproduce the paper); default: the "
                         "case's model.contact, else physical")
    te.add_argument("--K", type=float, default=None,
                    help="impact-law stiffness, N/mm^n (default 2e5; needs --contact impact or the case's "
                         "model.contact impact)")
    te.add_argument("--n", type=float, default=None, help="impact-law force exponent (default 1.5)")
    te.add_argument("--rigid", action="store_true", help="rigid single-flank limit (K -> infinity)")
    te.add_argument("--backlash", action="store_true",
                    help="also compute backlash = mean TE(-1) - mean TE(+1) in the rigid limit (the play at zero "
                         "torque); the datasheet's lost motion is 'rvdyn stiffness'")
    te.add_argument("--lost-motion", dest="old_lost_motion", action="store_true",
                    help="old name of --backlash (kept; prints a note)")
    te.add_argument("--json", action="store_true", help="print one JSON object instead of the summary")

    st = sub.add_parser("stiffness", help="hysteresis curve (input locked) and the datasheet figures",
                        description="The maker's torque sweep: input locked, output torque -rated -> +rated -> "
                                    "-rated. Prints torsional rigidity (b/a), lost motion (+-3 %% rated), backlash "
                                    "(zero torque, rigid play), hysteresis loss and the compliance budget (arcsec at "
                                    "rated torque).")
    st.add_argument("case", nargs="?", default=None, help="case JSON; default: nominal, no errors")
    st.add_argument("--rated-Nm", dest="rated_Nm", type=float, default=None,
                    help="rated output torque, N m (default 167, the RV-20E class of the default design)")
    st.add_argument("--out", default=None, help="CURVE.csv to write (torque_Nm, torsion_arcmin, branch)")
    st.add_argument("--plot", default=None, help="PNG of the hysteresis curve")
    st.add_argument("--contact", choices=CONTACT_LAWS, default=None,
                    help="contact law: physical or impact (default: the case's model.contact, else physical)")
    st.add_argument("--solver", choices=SOLVERS, default="analytic")
    st.add_argument("--input-deg", dest="input_deg", type=float, default=0.0, help="locked input angle, deg")
    st.add_argument("--points", type=int, default=41, help="points per sweep branch (default 41)")
    st.add_argument("--sensitivity", action="store_true",
                    help="also the elasticity d ln(rigidity) / d ln(size) of each size the paper does not give "
                         "(rvdyn.sensitivity.ASSUMED_SIZES; two more sweeps per size, about 12 s)")
    st.add_argument("--json", action="store_true", help="print one JSON object instead of the summary")

    return p


def _check_te_options(args: argparse.Namespace) -> None:
    """Bounds of the size options and the output path, before anything is solved (OptionError)."""
    v.steps_option(args.steps)
    v.option_real(args.revolutions, "--revolutions", 0.0, v.MAX_REVOLUTIONS, lo_open=True,
                  why=f"at most {v.MAX_STEPS} steps over them")
    if args.load_Nm is not None:
        v.option_real(args.load_Nm, "--load-Nm", 0.0, MAX_LOAD_NM, unit="N m")
    if not args.rigid and args.K is not None:
        v.option_real(args.K, "--K", 0.0, v.MAX_CONTACT_K, lo_open=True, unit="N/mm^n",
                      why="stiffer is the rigid limit, --rigid")
    if args.out:
        v.output_file(args.out)


def _check_stiffness_options(args: argparse.Namespace) -> None:
    """Bounds of ``rvdyn stiffness``'s options and its output paths, before anything is solved."""
    v.option_int(args.points, "--points", 5, v.MAX_SWEEP_POINTS, why="each point is one solve per branch")
    if args.rated_Nm is not None:
        v.option_real(args.rated_Nm, "--rated-Nm", 0.0, MAX_LOAD_NM, lo_open=True, unit="N m")
    v.option_real(args.input_deg, "--input-deg", -v.MAX_ANGLE_DEG, v.MAX_ANGLE_DEG, unit="deg")
    for name, path in (("--out", args.out), ("--plot", args.plot)):
        if path:
            v.output_file(path, name)


def _te(args: argparse.Namespace) -> int:
    _check_te_options(args)
    case = load_case(args.case)
    law = _law(args, case)
    res = run_te(case, args.solver, args.steps, args.revolutions, args.load_Nm, args.direction, law)
    out: dict[str, Any] = {"case": case.name, **{k: (v if k == "warnings" else _finite(v))
                                                  for k, v in res.stats.items()}}
    for w in res.stats["warnings"]:
        print(f"rvdyn: warning: {w}", file=sys.stderr)
    if args.old_lost_motion:
        print("rvdyn: note: --lost-motion is now --backlash (the rigid play at zero torque, key backlash_arcsec); "
              "the datasheet's lost motion (+-3 % rated torque) is 'rvdyn stiffness'", file=sys.stderr)
    if args.backlash or args.old_lost_motion:
        out["backlash_arcsec"] = backlash(case, args.solver, args.steps, law=law)["backlash_arcsec"]
    if args.out:
        out["csv"] = str(res.to_csv(args.out))
    if args.json:
        print(json.dumps(out))
    else:
        print(f"case {case.name}: solver {args.solver}, {args.steps} steps, {args.revolutions:g} rev, "
              f"load {res.stats['load_Nm']:g} N m, direction {res.stats['direction']:+d}")
        print(f"  TE pp {out['pp']:.4f} arcsec  mean {out['mean']:.4f}  mean|.| {out['mean_abs']:.4f}  "
              f"rms {out['rms']:.4f}  ratio {res.stats['ratio']:.7f}  ({res.stats['seconds']:.2f} s)")
        if "backlash_arcsec" in out:
            print(f"  backlash {out['backlash_arcsec']:.4f} arcsec (rigid play at zero torque)")
        if args.out:
            print(f"  wrote {out['csv']}")
    return 0


def _stiffness(args: argparse.Namespace) -> int:
    from rvdyn.stiffness import DEFAULT_RATED_NM, hysteresis, write_curve

    case = load_case(args.case)
    law = None
    if args.contact is not None:
        base = law_from_model(case.model)
        law = ContactLaw(K=base.K, n=base.n, kind=args.contact)
    res = hysteresis(case, args.rated_Nm, args.input_deg, args.solver, law, args.points)
    f = res.figures
    for w in f["warnings"]:
        print(f"rvdyn: warning: {w}", file=sys.stderr)
    if args.out:
        f["csv"] = str(write_curve(res, args.out))
    if args.plot:
        f["png"] = str(res.plot(args.plot))
    if args.sensitivity:
        from rvdyn.sensitivity import rigidity_elasticities

        tab = rigidity_elasticities(case, rated_Nm=args.rated_Nm, law=law, solver=args.solver,
                                    theta_in_deg=args.input_deg)
        f["sensitivity"] = [{"size": r.size, "value": r.value, "elasticity": _finite(r.elasticity), "note": r.note}
                            for r in tab.itertuples()]
    if args.json:
        print(json.dumps({"case": case.name, **f}))
        return 0
    ds = f["datasheet_class"]
    print(f"case {case.name}: hysteresis curve, input locked at {f['input_angle_deg']:g} deg, rated torque "
          f"{f['rated_torque_Nm']:g} N m, {f['contact']} contact law, supports {f['supports']}, friction "
          f"mu_pin {f['pin_friction_coefficient']:g}, mu_bearing {f['bearing_friction_coefficient']:g}")
    if args.rated_Nm is None and case.design != type(case.design)():
        print(f"  note: rated torque {DEFAULT_RATED_NM:g} N m is the default design's (RV-20E class); give "
              "--rated-Nm for this design")
    print(f"  torsional rigidity {f['torsional_rigidity_Nm_per_arcmin']:.1f} N m/arcmin   (datasheet class "
          f"{ds['model']}: about {ds['torsional_rigidity_Nm_per_arcmin']:g})")
    print(f"  lost motion        {f['lost_motion_arcmin']:.4f} arcmin      (datasheet class: <= "
          f"{ds['lost_motion_arcmin_max']:g})")
    print(f"  backlash           {f['backlash_arcmin']:.4f} arcmin")
    print(f"  hysteresis loss    {f['hysteresis_loss_arcmin']:.4f} arcmin")
    print(f"  compliance budget at rated torque (arcsec, total {f['budget_total_arcsec']:.2f}):")
    per_crank = f.get("budget_per_crank", {})
    if per_crank:
        n = len(next(iter(per_crank.values())))
        print(f"    {'part':21s} {'arcsec':>8s}  {'share':>7s}   per crank " + " ".join(f"{j:>7d}" for j in range(n)))
    for part, arcsec in sorted(f["budget"].items(), key=lambda kv: -kv[1]):
        cranks = " ".join(f"{v:7.3f}" for v in per_crank.get(part, []))
        print(f"    {part:21s} {arcsec:8.3f}  ({100 * arcsec / max(f['budget_total_arcsec'], 1e-300):5.1f} %)"
              + (f"             {cranks}" if cranks else ""))
    if "sensitivity" in f:
        print("  rigidity's elasticity to each assumed size (d ln k / d ln s: +1 % size -> about E % rigidity):")
        for r in sorted(f["sensitivity"], key=lambda r: -abs(r["elasticity"] or 0.0)):
            e = "nan" if r["elasticity"] is None else f"{r['elasticity']:+.3f}"
            print(f"    {r['size']:44s} {r['value']:8.4g}  {e:>7s}" + (f"  {r['note']}" if r["note"] else ""))
    for k in ("csv", "png"):
        if k in f:
            print(f"  wrote {f[k]}")
    return 0


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``rvdyn``; returns the exit status."""
    args = build_parser().parse_args(argv)
    try:
        if args.command == "stiffness":
            _check_stiffness_options(args)
            return _stiffness(args)
        return _te(args)
    except (ValueError, OSError) as exc:
        return v.refuse("rvdyn", exc)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
