"""build_maps.py - regenerate every derived powertrain map from the copied ADVISOR sources.

Run from the repository root::

    python -m shevsim.powertrain.build_maps            # writes components/*/ maps + plot
    python -m shevsim.powertrain.build_maps --check    # rebuild in memory, compare with files

Sources (NREL ADVISOR 2003 data files converted to CSV, copied into ``components/maps_source/``
with ``ADVISOR_license.txt``; all had ``*_proprietary = 0``):

* ``FC_CI330`` Detroit Diesel Series 60 12.7 L, 330 kW: fuel map and max-torque curve.
* ``FC_CI67_emis`` (VW 1.9 L TDI) and ``FC_CI60_emis`` (Mercedes 1.7 L), ORNL-measured: PM maps.
* ``GC_PM63`` Mannesmann Sachs 63 kW PM generator/controller: efficiency map, max torque.
* ``MC_AC75`` Westinghouse 75 kW AC induction motor/inverter: efficiency map, max torque.

Scaling (all explicit below, all recorded in each output's header)

Engine (seed Table 5.1: 261 kW)
    Power-linear in torque at unchanged speed (ADVISOR's ``fc_trq_scale``):
    ``tau = k_e * tau_src``, ``fuel = k_e * fuel_src`` at the same speed, so BSFC at corresponding
    points is unchanged; ``k_e = 261 kW / P_src,max``. The fuel map's lowest measured torque is
    200 Nm (source); the zero-torque column is added by extending each speed's first segment
    linearly (Willans line: fuel is affine in brake torque for a diesel at fixed speed).
Engine torque map (B.1 form, torque as a function of speed and fuel rate)
    Inverse of the fuel map at each speed for torque <= the max-torque curve. Below the zero-torque
    fuel the Willans line is continued down to zero fuel (the negative torque is engine friction
    when fuel is cut); fuel above the full-load fuel gives no more than full-load torque.
Soot map
    Only the two light-duty ORNL maps carry PM. Their shape is transferred as *PM per unit fuel*
    ``r(n_s, n_t)`` [mg soot / g fuel] on normalised speed ``n_s = (N - N_min)/(N_max - N_min)``
    (range of each engine's max-torque curve) and normalised load ``n_t = tau / tau_max(N)``,
    averaged over the two engines, then applied to the heavy engine:
    ``soot_mgps(w, tau) = r(n_s(w), min(n_t, 1)) * fuel_gps(w, tau)``.
    This is a quasi-static map; transient soot is modelled separately in the component.
Generator (seed Table 5.1: 236 kW)
    GC_PM63 is a 5500 rpm machine; the heavy engine's range is 1200-2100 rpm. A lossless step-up
    gear ``g = 5500/2100`` maps the engine's rated speed onto the generator's top speed, and torque
    is scaled power-linearly so the max-torque curve's peak *shaft* power is 236 kW (ADVISOR's
    convention: machine ratings are shaft power). The derived map is stored in engine-shaft
    coordinates: ``w_e = w_gen / g``, ``tau_e = g * k_g * tau_gen`` with ``k_g = 236 kW / P_src``.
Motor (seed Table 5.1: 380 kW)
    Four in-hub motors (M-ATV is 4x4), each MC_AC75 scaled power-linearly in torque to 95 kW
    peak; they share torque equally, so the stored map is the equivalent single machine with
    ``tau_total = 4 * (95/P_src) * tau_src`` at unchanged speed (hub reduction in the vehicle
    parameters). The ADVISOR max-torque curve is taken as the *peak* curve; the continuous curve
    is an assumed fraction ``CONT_FRACTION`` of it (traction machines: continuous ~ 0.5 peak).
Optimal operating line (seed Fig. 5.2)
    For each electrical output P, search engine speed on a 10 rpm grid over the map's range: solve
    the generator torque for P (``tau w eta_g(w, tau) = P``), require it within both max-torque
    curves, take the engine fuel rate at that torque; keep the speed of least fuel. The raw argmin
    is then made non-decreasing in P (running maximum; the fuel penalty of that is reported in the
    header) so the speed set point never steps down when power rises.
"""
from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from shevsim.powertrain.maps import RPM, Curve, Grid2D, grid_to_long, read_columns, write_long_csv
from shevsim.core.paths import DATA_ROOT

ROOT = DATA_ROOT
SRC = ROOT / "components" / "maps_source"
EG = ROOT / "components" / "engine_generator"
MOT = ROOT / "components" / "motor"

ENGINE_POWER_W = 261e3      # seed Table 5.1
GENERATOR_POWER_W = 236e3   # seed Table 5.1 (shaft rating, ADVISOR convention)
MOTOR_POWER_W = 380e3       # seed Table 5.1 (total of all motors)
N_MOTORS = 4                # assumed: one in-hub motor per wheel of the 4x4 M-ATV
CONT_FRACTION = 0.5         # assumed continuous/peak torque ratio of the traction motors
GEN_TOP_RPM_SRC = 5500.0    # GC_PM63 top speed
LICENCE = "ADVISOR data, (C) Alliance for Sustainable Energy; MIT-style licence in components/maps_source/ADVISOR_license.txt"


def _grid(path: Path, x: str, y: str, z: str):
    d = read_columns(path, (x, y, z))
    xs, ys = np.unique(d[x]), np.unique(d[y])
    Z = np.full((xs.size, ys.size), np.nan)
    Z[np.searchsorted(xs, d[x]), np.searchsorted(ys, d[y])] = d[z]
    assert not np.isnan(Z).any(), path
    return xs, ys, Z


def _curve(path: Path, x: str, y: str):
    d = read_columns(path, (x, y))
    return d[x], d[y]


def peak_power(speed_radps, torque_nm) -> float:
    """Peak of ``tau * w`` along a (piecewise-linear) max-torque curve, sampled densely."""
    w = np.linspace(speed_radps[0], speed_radps[-1], 2001)
    return float(np.max(w * np.interp(w, speed_radps, torque_nm)))


# ----------------------------------------------------------------------------- engine
def build_engine():
    rpm, trq, fuel = _grid(SRC / "FC_CI330_map.csv", "speed_rpm", "torque_Nm", "fuel_g_per_s")
    mrpm, mtrq = _curve(SRC / "FC_CI330_maxtorque.csv", "speed_rpm", "max_torque_Nm")
    assert np.allclose(mrpm, rpm)
    w = rpm * RPM
    p_src = peak_power(w, mtrq)
    k_e = ENGINE_POWER_W / p_src
    # Willans extension to zero torque
    slope = (fuel[:, 1] - fuel[:, 0]) / (trq[1] - trq[0])
    f0 = fuel[:, 0] - slope * trq[0]
    trq_ax = np.concatenate([[0.0], trq]) * k_e
    fuel_tab = np.column_stack([f0, fuel]) * k_e
    tmax = mtrq * k_e
    fuel_map = Grid2D(w, trq_ax, fuel_tab, ("clamp", "linear"), "engine fuel map")
    fmax = np.array([fuel_map(wi, ti) for wi, ti in zip(w, tmax)])
    # inverse (B.1): torque(speed, fuel)
    fuel_ax = np.linspace(0.0, math.ceil(fmax.max() * 1.05), 31)
    tq_of_f = np.empty((w.size, fuel_ax.size))
    for i, wi in enumerate(w):
        tt = np.linspace(0.0, tmax[i], 200)
        ff = np.array([fuel_map(wi, t) for t in tt])
        s0 = (ff[1] - ff[0]) / (tt[1] - tt[0])
        for j, fj in enumerate(fuel_ax):
            if fj <= ff[0]:
                tq_of_f[i, j] = (fj - ff[0]) / s0         # Willans line continued: friction
            else:
                tq_of_f[i, j] = np.interp(fj, ff, tt)     # clamps at tmax above full-load fuel
    return dict(w=w, trq_ax=trq_ax, fuel_tab=fuel_tab, tmax=tmax, fmax=fmax, fuel_map=fuel_map,
                fuel_ax=fuel_ax, tq_of_f=tq_of_f, k_e=k_e, p_src=p_src)


def _pm_ratio(stem: str):
    """PM per unit fuel [mg/g] of one ORNL engine on normalised (speed, load)."""
    d = read_columns(SRC / f"{stem}_map.csv", ("speed_rpm", "torque_Nm", "fuel_g_per_s", "pm_g_per_s"))
    rpm, trq = np.unique(d["speed_rpm"]), np.unique(d["torque_Nm"])
    R = np.full((rpm.size, trq.size), np.nan)
    R[np.searchsorted(rpm, d["speed_rpm"]), np.searchsorted(trq, d["torque_Nm"])] = (
        1e3 * d["pm_g_per_s"] / d["fuel_g_per_s"])
    ratio = Grid2D(rpm, trq, R, "clamp", f"{stem} PM/fuel")
    mr, mt = _curve(SRC / f"{stem}_maxtorque.csv", "speed_rpm", "max_torque_Nm")
    tmax = Curve(mr, mt, "clamp")
    return ratio, tmax, float(mr[0]), float(mr[-1])


def build_soot(eng):
    ns = np.linspace(0.0, 1.0, 11)
    nt = np.linspace(0.0, 1.0, 11)
    acc = np.zeros((ns.size, nt.size))
    stems = ("FC_CI67_emis", "FC_CI60_emis")
    for stem in stems:
        ratio, tmax, n0, n1 = _pm_ratio(stem)
        for i, s in enumerate(ns):
            n = n0 + s * (n1 - n0)
            for j, t in enumerate(nt):
                acc[i, j] += ratio(n, t * tmax(n))
    r = Grid2D(ns, nt, acc / len(stems), "clamp", "soot per fuel")
    rpm = np.arange(1200.0, 2100.0 + 1, 100.0)
    w = rpm * RPM
    tq = eng["trq_ax"]
    tmax = Curve(eng["w"], eng["tmax"], "clamp")
    w0, w1 = eng["w"][0], eng["w"][-1]
    soot = np.empty((w.size, tq.size))
    for i, wi in enumerate(w):
        for j, t in enumerate(tq):
            soot[i, j] = r((wi - w0) / (w1 - w0), min(t / tmax(wi), 1.0)) * eng["fuel_map"](wi, t)
    return dict(w=w, tq=tq, soot=soot, ratio=r)


# ----------------------------------------------------------------------------- generator
def build_generator():
    rpm, trq, eff = _grid(SRC / "GC_PM63_effmap.csv", "speed_rpm", "torque_Nm", "efficiency")
    mrpm, mtrq = _curve(SRC / "GC_PM63_maxtorque.csv", "speed_rpm", "max_torque_Nm")
    gear = GEN_TOP_RPM_SRC / 2100.0
    p_src = peak_power(mrpm * RPM, mtrq)
    k_g = GENERATOR_POWER_W / p_src
    w_e = rpm * RPM / gear
    t_e = trq * gear * k_g
    return dict(w=w_e, tq=t_e, eff=eff, mw=mrpm * RPM / gear, mt=mtrq * gear * k_g,
                gear=gear, k_g=k_g, p_src=p_src)


# ----------------------------------------------------------------------------- motor
def build_motor():
    rpm, trq, eff = _grid(SRC / "MC_AC75_effmap.csv", "speed_rpm", "torque_Nm", "efficiency")
    mrpm, mtrq = _curve(SRC / "MC_AC75_maxtorque.csv", "speed_rpm", "max_torque_Nm")
    p_src = peak_power(mrpm * RPM, mtrq)
    k_m = MOTOR_POWER_W / p_src      # = N_MOTORS * (MOTOR_POWER_W / N_MOTORS) / p_src
    return dict(w=rpm * RPM, tq=trq * k_m, eff=eff, mw=mrpm * RPM, peak=mtrq * k_m,
                cont=CONT_FRACTION * mtrq * k_m, k_m=k_m, p_src=p_src)


# ----------------------------------------------------------------------------- optimal line
def build_ool(eng, gen, speed_step_rpm: float = 10.0, power_step_w: float = 2e3):
    fuel_map = eng["fuel_map"]
    geff = Grid2D(gen["w"], gen["tq"], gen["eff"], "clamp", "generator efficiency")
    te_max = Curve(eng["w"], eng["tmax"], "clamp")
    tg_max = Curve(gen["mw"], gen["mt"], "clamp")
    w_ax = np.arange(eng["w"][0] / RPM, eng["w"][-1] / RPM + 1e-9, speed_step_rpm) * RPM
    # electrical output vs torque at each speed (monotone envelope)
    tables = []
    pmax = 0.0
    for w in w_ax:
        tl = min(te_max(w), tg_max(w))
        tt = np.linspace(0.0, tl, 600)
        pe = np.maximum.accumulate(np.array([t * w * geff(w, t) for t in tt]))
        tables.append((tt, pe))
        pmax = max(pmax, pe[-1])
    p_ax = np.append(np.arange(0.0, pmax, power_step_w), pmax)
    best_w = np.empty(p_ax.size)
    for k, p in enumerate(p_ax):
        bf, bw = math.inf, math.nan
        for w, (tt, pe) in zip(w_ax, tables):
            if p > pe[-1] + 1e-9:
                continue
            t = float(np.interp(p, pe, tt))
            f = fuel_map(w, t)
            if f < bf - 1e-12:
                bf, bw = f, w
        best_w[k] = bw
    raw_w = best_w.copy()
    mono_w = np.maximum.accumulate(best_w)
    out = {k: np.empty(p_ax.size) for k in ("torque", "fuel", "raw_fuel")}
    idx = {w: i for i, w in enumerate(w_ax)}
    for k, p in enumerate(p_ax):
        for key, w in (("fuel", mono_w[k]), ("raw_fuel", raw_w[k])):
            tt, pe = tables[idx[w]]
            if p > pe[-1] + 1e-9:   # monotone speed infeasible here: keep the raw optimum
                mono_w[k] = raw_w[k]
                w = raw_w[k]
                tt, pe = tables[idx[w]]
            t = float(np.interp(p, pe, tt))
            out[key][k] = fuel_map(w, t)
            if key == "fuel":
                out["torque"][k] = t
    return dict(p=p_ax, w=mono_w, raw_w=raw_w, torque=out["torque"], fuel=out["fuel"],
                raw_fuel=out["raw_fuel"], pmax=pmax, geff=geff)


# ----------------------------------------------------------------------------- write
def build_all():
    eng = build_engine()
    soot = build_soot(eng)
    gen = build_generator()
    mot = build_motor()
    ool = build_ool(eng, gen)
    return eng, soot, gen, mot, ool


def _hdr(*lines):
    return [*lines, LICENCE, "regenerate: python -m shevsim.powertrain.build_maps"]


def outputs(eng, soot, gen, mot, ool) -> dict[Path, tuple[list[str], dict]]:
    k_e, k_g, k_m = eng["k_e"], gen["k_g"], mot["k_m"]
    files: dict[Path, tuple[list[str], dict]] = {}
    x, y, z = grid_to_long(eng["w"], eng["trq_ax"], eng["fuel_tab"])
    files[EG / "engine_fuel_map.csv"] = (_hdr(
        "Engine fuel rate map: fuel_gps(speed_radps, torque_nm), brake torque at the crankshaft.",
        f"source: ADVISOR FC_CI330 (Detroit Diesel Series 60 12.7 L, 330 kW), peak {eng['p_src']/1e3:.1f} kW on its max-torque curve",
        f"scaling: power-linear in torque to {ENGINE_POWER_W/1e3:.0f} kW (seed Table 5.1): torque and fuel x k_e = {k_e:.5f}, speed unchanged",
        "torque_nm = 0 column: Willans-line extension of each speed's first measured segment (source starts at 200 Nm)",
        "extrapolation in use: speed clamp, torque linear (Willans)"),
        dict(speed_radps=x, torque_nm=y, fuel_gps=z))
    x, y, z = grid_to_long(eng["w"], eng["fuel_ax"], eng["tq_of_f"])
    files[EG / "engine_torque_map.csv"] = (_hdr(
        "Engine torque map (seed B.1/Fig. B.1 form): torque_nm(speed_radps, fuel_gps); inverse of engine_fuel_map.csv",
        "below the zero-torque fuel: Willans line continued (negative torque = friction at fuel cut); above full-load fuel: full-load torque",
        f"source/scaling: as engine_fuel_map.csv (FC_CI330 x k_e = {k_e:.5f})"),
        dict(speed_radps=x, fuel_gps=y, torque_nm=z))
    files[EG / "engine_max_torque.csv"] = (_hdr(
        "Engine full-load curve: torque_max_nm and the fuel rate at full load fuel_max_gps (rack = 1)",
        f"source: ADVISOR FC_CI330_maxtorque x k_e = {k_e:.5f}"),
        dict(speed_radps=eng["w"], torque_max_nm=eng["tmax"], fuel_max_gps=eng["fmax"]))
    x, y, z = grid_to_long(soot["w"], soot["tq"], soot["soot"])
    files[EG / "soot_map.csv"] = (_hdr(
        "Quasi-static engine-out soot map soot_mgps(speed_radps, torque_nm) (seed Fig. B.2 role)",
        "shape: PM per unit fuel of the ORNL-measured ADVISOR maps FC_CI67_emis (VW 1.9 L TDI) and FC_CI60_emis (Mercedes 1.7 L), averaged",
        "on normalised speed (N-Nmin)/(Nmax-Nmin) of each engine's max-torque curve and normalised load tau/tau_max(N)",
        "applied to the heavy engine: soot = ratio(n_s, min(n_t,1)) [mg/g] * fuel_gps (engine_fuel_map.csv); assumption: the light-duty ratio shape transfers"),
        dict(speed_radps=x, torque_nm=y, soot_mgps=z))
    x, y, z = grid_to_long(gen["w"], gen["tq"], gen["eff"])
    files[EG / "generator_eff_map.csv"] = (_hdr(
        "Generator+controller efficiency efficiency_frac(speed_radps, torque_nm) in ENGINE-SHAFT coordinates",
        f"source: ADVISOR GC_PM63 (Mannesmann Sachs 63 kW PM), peak shaft power {gen['p_src']/1e3:.1f} kW",
        f"scaling: step-up gear g = {gen['gear']:.5f} (5500 rpm generator top speed at 2100 rpm engine), torque power-linear x k_g = {k_g:.5f}",
        f"to {GENERATOR_POWER_W/1e3:.0f} kW peak shaft power (seed Table 5.1); speed_radps = w_gen/g, torque_nm = g*k_g*tau_gen"),
        dict(speed_radps=x, torque_nm=y, efficiency_frac=z))
    files[EG / "generator_max_torque.csv"] = (_hdr(
        "Generator max shaft torque (engine-shaft coordinates)",
        f"source: ADVISOR GC_PM63_maxtorque; speed / g, torque x g x k_g (g = {gen['gear']:.5f}, k_g = {k_g:.5f})"),
        dict(speed_radps=gen["mw"], torque_max_nm=gen["mt"]))
    p = ool["p"]
    bsfc = np.where(p > 0, ool["fuel"] / np.maximum(p, 1e-9) * 3.6e6, np.nan)
    penalty = float(np.nanmax((ool["fuel"] - ool["raw_fuel"]) / np.maximum(ool["raw_fuel"], 1e-12)))
    files[EG / "optimal_operating_line.csv"] = (_hdr(
        "Optimal operating line of the engine-generator: least fuel for each electrical output (seed Fig. 5.2b)",
        "built from engine_fuel_map.csv, engine_max_torque.csv, generator_eff_map.csv, generator_max_torque.csv (10 rpm speed search)",
        f"speed made non-decreasing in power (running max of the raw argmin); max fuel penalty of that {100*penalty:.3f} %",
        "bsfc_elec_g_per_kwh = fuel per electrical kWh (NaN at zero power)"),
        dict(elec_power_w=p, speed_radps=ool["w"], engine_torque_nm=ool["torque"],
             shaft_power_w=ool["torque"] * ool["w"], fuel_gps=ool["fuel"], raw_speed_radps=ool["raw_w"],
             bsfc_elec_g_per_kwh=bsfc))
    files[EG / "fuel_vs_power.csv"] = (_hdr(
        "Quasi-static engine-generator fuel rate vs electrical output power along the optimal operating line (seed Fig. 5.2a)",
        "from optimal_operating_line.csv; for the supervisor's fuel model"),
        dict(elec_power_w=p, fuel_gps=ool["fuel"]))
    x, y, z = grid_to_long(mot["w"], mot["tq"], mot["eff"])
    files[MOT / "motor_eff_map.csv"] = (_hdr(
        "Traction motor+inverter efficiency efficiency_frac(speed_radps, torque_nm); torque < 0 = generating (regen)",
        f"EQUIVALENT machine of {N_MOTORS} in-hub motors sharing torque equally (total torque at motor-shaft speed)",
        f"source: ADVISOR MC_AC75 (Westinghouse 75 kW AC induction), peak {mot['p_src']/1e3:.1f} kW on its max-torque curve",
        f"scaling: power-linear in torque to {MOTOR_POWER_W/1e3:.0f} kW total (seed Table 5.1) = {N_MOTORS} x {MOTOR_POWER_W/N_MOTORS/1e3:.0f} kW: torque x k_m = {k_m:.5f}, speed unchanged"),
        dict(speed_radps=x, torque_nm=y, efficiency_frac=z))
    files[MOT / "motor_torque_curves.csv"] = (_hdr(
        f"Peak and continuous torque of the equivalent motor ({N_MOTORS} in-hub motors), motoring and generating symmetric",
        f"peak: ADVISOR MC_AC75_maxtorque x k_m = {k_m:.5f}; continuous: assumed {CONT_FRACTION} x peak (no continuous curve in the source)"),
        dict(speed_radps=mot["mw"], peak_torque_nm=mot["peak"], cont_torque_nm=mot["cont"]))
    return files


def plot(eng, gen, ool, path: Path) -> None:
    from shevsim.plotting import headless_pyplot
    plt = headless_pyplot()

    fig, ax = plt.subplots(1, 2, figsize=(11, 4.2))
    ax[0].plot(ool["p"] / 1e3, ool["fuel"], "k-")
    ax[0].set_xlabel("engine-generator electrical power [kW]")
    ax[0].set_ylabel("fuel rate [g/s]")
    ax[0].set_title("(a) quasi-static fuel rate along the optimal line")
    ax[0].grid(True, alpha=0.3)
    w = np.linspace(eng["w"][0], eng["w"][-1], 60)
    t = np.linspace(20.0, eng["tmax"].max(), 60)
    W, T = np.meshgrid(w, t, indexing="ij")
    F = eng["fuel_map"].eval_array(W, T)
    E = ool["geff"].eval_array(W, T)
    tmax = np.interp(W, eng["w"], eng["tmax"])
    gmax = np.interp(W, gen["mw"], gen["mt"])
    bsfc = np.where((T <= tmax) & (T <= gmax), F / (W * T * E) * 3.6e6, np.nan)
    cs = ax[1].contour(W / RPM, T, bsfc, levels=[215, 220, 230, 240, 260, 300, 350, 450])
    ax[1].clabel(cs, fmt="%d")
    ax[1].plot(eng["w"] / RPM, eng["tmax"], "k--", label="engine max torque")
    ax[1].plot(gen["mw"] / RPM, gen["mt"], "k:", label="generator max torque")
    ax[1].plot(ool["w"] / RPM, ool["torque"], "r-", lw=2, label="optimal operating line")
    ax[1].set_xlim(eng["w"][0] / RPM - 20, eng["w"][-1] / RPM + 20)
    ax[1].set_xlabel("engine speed [rpm]")
    ax[1].set_ylabel("engine torque [N m]")
    ax[1].set_title("(b) unit bsfc [g per electrical kWh] + optimal line")
    ax[1].legend(fontsize=8, loc="lower right")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true", help="compare rebuilt maps with the files on disk")
    args = ap.parse_args(argv)
    parts = build_all()
    files = outputs(*parts)
    if args.check:
        bad = 0
        for path, (_, cols) in files.items():
            disk = read_columns(path, tuple(cols))
            for c, v in cols.items():
                if not np.allclose(disk[c], v, rtol=1e-6, atol=1e-9, equal_nan=True):
                    print(f"DIFFERS: {path.relative_to(ROOT)} column {c}")
                    bad += 1
        print("maps up to date" if not bad else f"{bad} column(s) differ")
        return 1 if bad else 0
    EG.mkdir(parents=True, exist_ok=True)
    MOT.mkdir(parents=True, exist_ok=True)
    for path, (hdr, cols) in files.items():
        write_long_csv(path, hdr, cols)
        print("wrote", path.relative_to(ROOT))
    eng, _, gen, _, ool = parts
    plot(eng, gen, ool, EG / "optimal_operating_line.png")
    print("wrote", (EG / "optimal_operating_line.png").relative_to(ROOT))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
