"""What an engineer reads from loaded tests, measured before any model.

:func:`test_table`: one row per test and load (the runs of one homing at one load, speed and
temperature): the mean TE per direction (over whole output revolutions, evenly in angle), backward
minus forward (B - F: the rig's zero of the test cancels), peak-to-peak per direction, and the main
orders of the reducer (:func:`rvrig.spectrum.separate`) with amplitude and phase per direction.
:func:`load_changes`: how each of these changes between the lowest and the highest load.

:func:`measured_datasheet`: the maker's figures as far as the loads allow (docs/physics.md section 15):
a rotating test at load T, direction d, sits on the hysteresis curve at torque ``-d T`` (the load
resists the motion), so B - F at load T is the curve's span between -T and +T, i.e. twice the
mid-curve angle ``m(T)`` of an antisymmetric curve. Hence

* secant torsional rigidity between loads T1 < T2: ``(T2 - T1) / ((BF2 - BF1) / 2)`` (N m/arcmin);
* lost motion (``m(+3 %) - m(-3 %)`` of the rated torque) = B - F at 3 % rated: measured there or
  interpolated linearly between the loads that bracket it, never extrapolated;
* light-load play = B - F at zero load: the curve's width at zero torque (the maker's backlash) as a
  rotating test sees it, the wind-up under the no-load running torque included;
* b/a = ``0.97 T_r / (m(T_r) - m(0.03 T_r))`` only when the measured loads bracket both points on
  different linear pieces (with two loads it would only repeat their secant).

The rated torque is the user's (``rated_Nm``); without it lost motion and b/a are said to be missing.
:func:`plot_test_means`: the mean TE per direction and B - F against load (PNG).
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd

from rvcad.atomic import atomic_path
from rvrig.dataset import MeasuredDataset, RunRecord
from rvrig.spectrum import OrderSpectrum, order_spectrum, separate

#: Main orders listed per test.
N_ORDERS = 6
#: Fraction of the rated torque at which lost motion is taken (the maker's +-3 %).
LOST_MOTION_FRACTION = 0.03
#: A load within this fraction of the rated torque of a point counts as measured at it.
AT_LOAD_FRACTION = 0.005
ARCSEC_PER_ARCMIN = 60.0


def _dir_stats(runs: list[RunRecord], specs: dict[str, OrderSpectrum], orders: list[int]) -> dict:
    """Mean, peak-to-peak and the orders' amplitude and phase of the runs of one direction (averaged)."""
    if not runs:
        return {}
    sp = [specs[r.run] for r in runs]
    out = {"mean": float(np.mean([s.mean_arcsec for s in sp])),
           "pp": float(np.mean([np.ptp(r.te_arcsec) for r in runs])), "noise": float(np.mean([r.noise_arcsec for r in runs]))}
    for k in orders:
        z = np.mean([a * np.exp(1j * np.radians(p)) for a, p in (s.at(k) for s in sp)])
        out[f"order{k}"] = (float(abs(z)), float(np.degrees(np.angle(z))))
    return out


def test_table(dataset: MeasuredDataset, n_orders: int = N_ORDERS) -> pd.DataFrame:
    """Per-test table of the measured TE (module docstring).

    Returns
    -------
    DataFrame
        One row per (test, load_Nm, speed_rpm, temperature_C): ``test``, ``load_Nm``, ``speed_rpm``,
        ``temperature_C``, ``runs_fw``, ``runs_bw``, ``mean_fw_arcsec``, ``mean_bw_arcsec``,
        ``bw_minus_fw_arcsec``, ``pp_fw_arcsec``, ``pp_bw_arcsec``, ``noise_arcsec``, and for each main
        order k ``order{k}_amp_{fw,bw}_arcsec``, ``order{k}_phase_{fw,bw}_deg`` (``A cos(k theta + phi)``,
        theta the output angle reading). ``attrs["main_orders"]``: the orders with their labels;
        ``attrs["spectrum"]``: :func:`rvrig.spectrum.separate`'s result. A direction missing from a
        row gives NaN.
    """
    sep = separate(dataset)
    main = [g for g in sep["order_locked"] if abs(g["order"] - round(g["order"])) < 1e-9][:n_orders]
    orders = sorted(int(round(g["order"])) for g in main)
    specs = {r.run: order_spectrum(r) for r in dataset.runs}
    groups: dict[tuple, list[RunRecord]] = {}
    for r in dataset.runs:
        groups.setdefault((r.test, r.load_Nm, r.speed_rpm, r.temperature_C), []).append(r)
    rows = []
    for (test, load, speed, temp), runs in groups.items():
        fw = _dir_stats([r for r in runs if r.direction > 0], specs, orders)
        bw = _dir_stats([r for r in runs if r.direction < 0], specs, orders)
        row = {"test": test, "load_Nm": load, "speed_rpm": speed, "temperature_C": temp,
               "runs_fw": ",".join(r.run for r in runs if r.direction > 0),
               "runs_bw": ",".join(r.run for r in runs if r.direction < 0),
               "mean_fw_arcsec": fw.get("mean", math.nan), "mean_bw_arcsec": bw.get("mean", math.nan)}
        row["bw_minus_fw_arcsec"] = row["mean_bw_arcsec"] - row["mean_fw_arcsec"]
        row.update({"pp_fw_arcsec": fw.get("pp", math.nan), "pp_bw_arcsec": bw.get("pp", math.nan),
                    "noise_arcsec": float(np.nanmean([fw.get("noise", math.nan), bw.get("noise", math.nan)]))})
        for k in orders:
            for tag, st in (("fw", fw), ("bw", bw)):
                a, p = st.get(f"order{k}", (math.nan, math.nan))
                row[f"order{k}_amp_{tag}_arcsec"], row[f"order{k}_phase_{tag}_deg"] = a, p
        rows.append(row)
    df = pd.DataFrame(rows).sort_values(["speed_rpm", "temperature_C", "load_Nm", "test"], na_position="first",
                                        kind="stable").reset_index(drop=True)
    df.attrs["main_orders"] = [{"order": int(round(g["order"])), "label": g["label"]} for g in main]
    df.attrs["spectrum"] = sep
    return df


test_table.__test__ = False  # a function of the package, not a pytest test where a test module imports it


def _conditions(table: pd.DataFrame) -> list[tuple]:
    """(speed, temperature) conditions of a table, NaN kept as a value."""
    keys = table[["speed_rpm", "temperature_C"]].astype(float).fillna(-1e300)
    return [tuple(k) for k in keys.drop_duplicates().to_numpy()]


def _select(table: pd.DataFrame, cond: tuple) -> pd.DataFrame:
    keys = table[["speed_rpm", "temperature_C"]].astype(float).fillna(-1e300).to_numpy()
    return table[(keys == np.array(cond)).all(axis=1)]


def load_changes(table: pd.DataFrame) -> pd.DataFrame:
    """How each quantity of :func:`test_table` changes from the lowest to the highest load, per speed and
    temperature with at least two loads.

    Returns
    -------
    DataFrame
        ``quantity``, ``speed_rpm``, ``temperature_C``, ``load_low_Nm``, ``load_high_Nm``, ``low``, ``high``,
        ``change``, ``change_per_kNm`` (per 1000 N m), ``note`` (the per-direction means carry each
        test's own rig zero: only B - F and the orders compare across tests).
    """
    qty = [c for c in table.columns if c.endswith(("_arcsec", "_deg")) and c != "noise_arcsec"]
    rows = []
    for cond in _conditions(table):
        sub = _select(table, cond)
        by_load = sub.groupby("load_Nm")[qty].mean()
        if len(by_load) < 2:
            continue
        lo, hi = by_load.index.min(), by_load.index.max()
        for q in qty:
            a, b = float(by_load.loc[lo, q]), float(by_load.loc[hi, q])
            d = b - a
            if q.endswith("_deg"):
                d = (d + 180.0) % 360.0 - 180.0
            rows.append({"quantity": q, "speed_rpm": sub["speed_rpm"].iloc[0], "temperature_C": sub["temperature_C"].iloc[0],
                         "load_low_Nm": lo, "load_high_Nm": hi, "low": a, "high": b, "change": d,
                         "change_per_kNm": d / (hi - lo) * 1000.0,
                         "note": "includes the tests' rig zeros" if q in ("mean_fw_arcsec", "mean_bw_arcsec") else ""})
    return pd.DataFrame(rows)


def _interp(loads: np.ndarray, bf: np.ndarray, t: float, rated: float) -> tuple[float | None, str, int | None]:
    """B - F at load ``t``: (value, how, index of the linear piece used); None outside the loads measured."""
    near = np.flatnonzero(np.abs(loads - t) <= AT_LOAD_FRACTION * rated)
    if near.size:
        return float(bf[near[0]]), f"measured at {loads[near[0]]:g} N m", None
    if t < loads[0] or t > loads[-1]:
        return None, f"outside the loads measured ({loads[0]:g} to {loads[-1]:g} N m)", None
    i = int(np.searchsorted(loads, t)) - 1
    v = bf[i] + (bf[i + 1] - bf[i]) * (t - loads[i]) / (loads[i + 1] - loads[i])
    return float(v), f"interpolated linearly between {loads[i]:g} and {loads[i + 1]:g} N m", i


def _secant(t1: float, t2: float, bf1: float, bf2: float) -> float | None:
    """Secant rigidity between two loads, N m/arcmin: the mid-curve angle is half of B - F."""
    d = 0.5 * (bf2 - bf1) / ARCSEC_PER_ARCMIN
    return (t2 - t1) / d if d > 0 else None


def measured_datasheet(dataset: MeasuredDataset, rated_Nm: float | None, speed_rpm: float | None = None,
                       temperature_C: float | None = None, table: pd.DataFrame | None = None) -> dict:
    """The maker's figures from B - F per load, as far as the loads allow (module docstring).

    Parameters
    ----------
    dataset : MeasuredDataset
    rated_Nm : float or None
        The reducer's rated output torque, N m (the user's; None: lost motion and b/a are missing).
    speed_rpm, temperature_C : float or None
        The condition to use; default: the one with the most loads.
    table : DataFrame or None
        :func:`test_table` of the dataset, if already made.

    Returns
    -------
    dict
        ``speed_rpm``, ``temperature_C``, ``rated_torque_Nm``, ``loads_Nm``, ``bw_minus_fw_arcsec`` (per load,
        mean over its tests), ``secant_rigidity_Nm_per_arcmin`` (lowest to highest load), ``secants`` (per
        adjacent pair: ``from_Nm``, ``to_Nm``, ``rigidity_Nm_per_arcmin``), ``light_load_play_arcmin``,
        ``lost_motion_arcmin``, ``lost_motion_from``, ``torsional_rigidity_b_over_a_Nm_per_arcmin``,
        ``statements`` (what each figure is, what was interpolated, what is missing). A figure the loads do
        not allow is None.
    """
    tab = test_table(dataset) if table is None else table
    tab = tab[np.isfinite(tab["bw_minus_fw_arcsec"].astype(float))]
    st = ["B - F at load T is the span of the hysteresis curve between -T and +T (a rotating test at load T in "
          "direction d sits at torque -d T): twice the mid-curve angle (docs/physics.md section 15)"]
    out: dict = {"speed_rpm": None, "temperature_C": None,
                 "rated_torque_Nm": float(rated_Nm) if rated_Nm is not None else None, "loads_Nm": [],
                 "bw_minus_fw_arcsec": [], "secant_rigidity_Nm_per_arcmin": None, "secants": [],
                 "light_load_play_arcmin": None, "lost_motion_arcmin": None, "lost_motion_from": None,
                 "torsional_rigidity_b_over_a_Nm_per_arcmin": None, "statements": st}
    if tab.empty:
        st.append("no test has both directions at one load: B - F, and with it every figure, is missing")
        return out
    conds = _conditions(tab)
    if speed_rpm is not None or temperature_C is not None:
        conds = [c for c in conds if (speed_rpm is None or c[0] == speed_rpm)
                 and (temperature_C is None or c[1] == temperature_C)]
        if not conds:
            raise ValueError(f"no test at speed_rpm {speed_rpm} and temperature_C {temperature_C} with both directions")
    cond = max(conds, key=lambda c: _select(tab, c)["load_Nm"].nunique())
    sub = _select(tab, cond)
    if len(conds) > 1:
        st.append(f"the tests at {len(conds)} speeds/temperatures: the figures are those of the one with the most "
                  "loads")
    per = sub.groupby("load_Nm")["bw_minus_fw_arcsec"].mean()
    loads, bf = per.index.to_numpy(dtype=float), per.to_numpy(dtype=float)
    out.update({"speed_rpm": None if cond[0] == -1e300 else cond[0],
                "temperature_C": None if cond[1] == -1e300 else cond[1],
                "loads_Nm": loads.tolist(), "bw_minus_fw_arcsec": bf.tolist()})
    _rigidity(out, loads, bf, st)
    _light_load(out, loads, bf, rated_Nm, st)
    if rated_Nm is None:
        st.append("rated torque not given (--rated-Nm): lost motion (at +-3 % of it) and b/a (3 % to 100 % of it) "
                  "are missing; the secant between the loads measured does not need it")
        return out
    _lost_motion(out, loads, bf, float(rated_Nm), st)
    _b_over_a(out, loads, bf, float(rated_Nm), st)
    return out


def _rigidity(out: dict, loads: np.ndarray, bf: np.ndarray, st: list[str]) -> None:
    if loads.size < 2:
        st.append(f"one load ({loads[0]:g} N m): no rigidity (it needs two loads)")
        return
    out["secants"] = [{"from_Nm": float(a), "to_Nm": float(b), "rigidity_Nm_per_arcmin": _secant(a, b, x, y)}
                      for a, b, x, y in zip(loads[:-1], loads[1:], bf[:-1], bf[1:])]
    k = _secant(loads[0], loads[-1], bf[0], bf[-1])
    out["secant_rigidity_Nm_per_arcmin"] = k
    if k is None:
        st.append(f"B - F does not grow from {loads[0]:g} to {loads[-1]:g} N m: no rigidity")
    else:
        st.append(f"secant torsional rigidity {k:.4g} N m/arcmin between {loads[0]:g} and {loads[-1]:g} N m")


def _light_load(out: dict, loads: np.ndarray, bf: np.ndarray, rated: float | None, st: list[str]) -> None:
    zero = np.flatnonzero(np.abs(loads) <= (AT_LOAD_FRACTION * rated if rated else 0.0))
    if zero.size == 0:
        st.append(f"light-load play missing: no test at zero load (lowest {loads[0]:g} N m)")
        return
    out["light_load_play_arcmin"] = float(bf[zero[0]]) / ARCSEC_PER_ARCMIN
    st.append(f"light-load play {out['light_load_play_arcmin']:.4g} arcmin = B - F at {loads[zero[0]]:g} N m: the "
              "curve's width at zero torque as a rotating test sees it (with the wind-up under the no-load running "
              "torque), an upper bound of the rigid-limit backlash")


def _lost_motion(out: dict, loads: np.ndarray, bf: np.ndarray, rated: float, st: list[str]) -> None:
    t = LOST_MOTION_FRACTION * rated
    v, how, _ = _interp(loads, bf, t, rated)
    if v is None:
        st.append(f"lost motion missing: B - F at {t:g} N m (3 % of {rated:g} N m) is {how}; it needs loads at or "
                  "around it")
        return
    out["lost_motion_arcmin"] = v / ARCSEC_PER_ARCMIN
    out["lost_motion_from"] = f"B - F at {t:g} N m, {how}"
    st.append(f"lost motion {out['lost_motion_arcmin']:.4g} arcmin: B - F at {t:g} N m (3 % of {rated:g} N m), {how}"
              + ("; a reducer is softer at light load than a secant, so the linear interpolation likely understates it"
                 if how.startswith("interpolated") else ""))


def _b_over_a(out: dict, loads: np.ndarray, bf: np.ndarray, rated: float, st: list[str]) -> None:
    lo, how_lo, i_lo = _interp(loads, bf, LOST_MOTION_FRACTION * rated, rated)
    hi, how_hi, i_hi = _interp(loads, bf, rated, rated)
    if lo is None or hi is None:
        st.append(f"b/a missing: it needs B - F at 3 % and 100 % of {rated:g} N m; "
                  f"{'3 %: ' + how_lo if lo is None else '100 %: ' + how_hi}")
        return
    if loads.size < 3 or (i_lo is not None and i_lo == i_hi):
        st.append(f"b/a missing: with the loads measured, 3 % and 100 % of {rated:g} N m lie on one linear piece, "
                  "so b/a would only repeat the secant there; the rigidity given is a secant, not b/a")
        return
    k = _secant(LOST_MOTION_FRACTION * rated, rated, lo, hi)
    out["torsional_rigidity_b_over_a_Nm_per_arcmin"] = k
    st.append(f"b/a {k:.4g} N m/arcmin from B - F at 3 % ({how_lo}) and 100 % ({how_hi}) of {rated:g} N m"
              if k is not None else "b/a missing: B - F does not grow from 3 % to 100 % of the rated torque")


def plot_test_means(dataset: MeasuredDataset, path: str | Path, table: pd.DataFrame | None = None) -> Path:
    """Figure: mean TE per direction (each test its own rig zero) and B - F against load, PNG written atomically."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    tab = test_table(dataset) if table is None else table
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(10, 4))
    for col, name, mk in (("mean_fw_arcsec", "forward (+1)", "o"), ("mean_bw_arcsec", "backward (-1)", "s")):
        ax.plot(tab["load_Nm"], tab[col], mk, label=name)
    ax.set_xlabel("output load (N m)")
    ax.set_ylabel("mean TE (arcsec)")
    ax.set_title("Mean TE per direction (each test: its own rig zero)", fontsize=9)
    ax.legend(fontsize=8)
    ok = np.isfinite(tab["bw_minus_fw_arcsec"].astype(float))
    bx.plot(tab.loc[ok, "load_Nm"], tab.loc[ok, "bw_minus_fw_arcsec"], "D-", color="C2")
    bx.set_xlabel("output load (N m)")
    bx.set_ylabel("backward - forward (arcsec)")
    bx.set_title("B - F: the hysteresis curve's span between -T and +T", fontsize=9)
    for a in (ax, bx):
        a.grid(True, lw=0.3)
    fig.tight_layout()
    p = Path(path)
    with atomic_path(p, suffix=".png") as tmp:
        fig.savefig(tmp, dpi=110)
    plt.close(fig)
    return p
