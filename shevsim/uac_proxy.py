"""uac_proxy.py - the reproducible *UAC proxy* drive cycle.

No public speed trace of the military Urban Assault Cycle (UAC) exists. What the
seed says of it (App. A.2, Fig. A.1): 8.80 km long, frequent high accelerations
and decelerations, harsher than HD-UDDS in both. This module builds a **proxy**
with those properties from public heavy-duty cycles. It is NOT the UAC; every
file, plot and report calls it "UAC proxy".

Procedure (deterministic; ``python -m shevsim.uac_proxy`` rewrites
``cycles/uac_proxy.csv`` byte for byte):

1. **Split** HD-UDDS and the Orange County Bus cycle (1 Hz) into micro-trips: a
   micro-trip is the idle period before a drive, the drive, and the stop at its
   end. Speeds below 0.1 m/s count as standing (set to 0). The leading idle is
   shortened to at most :data:`IDLE_MAX_S` (frequent short stops).
2. **Re-time** each micro-trip: every source second with acceleration above
   +0.1 m/s^2 is compressed to ``1 / K_ACC`` s, every second with deceleration
   below -0.1 m/s^2 to ``1 / K_DEC`` s; cruise and idle seconds keep their length.
   This multiplies the accelerations and decelerations by ``K_ACC`` / ``K_DEC``
   while keeping the speed levels. The piecewise-linear re-timed trace is sampled
   back at 1 Hz.
3. **Make it drivable** (one forward and one backward pass, speeds only
   lowered): deceleration at most :data:`DECEL_CAP_MPS2`; acceleration at most
   :data:`ACCEL_CAP_MPS2` and within the wheel-power budget
   :data:`WHEEL_POWER_BUDGET_W` of a 15.5 t vehicle against road load
   (``0.5 m_eff (v1^2 - v0^2) + F_road(v_mean) v_mean dt <= P dt``), with the
   road-load and mass constants below (conservative assumptions for the M-ATV,
   not the vehicle component's parameters).
4. **Join**: shuffle the pooled micro-trips with ``numpy.random.default_rng(SEED)``;
   go through them in that order and append each one that keeps the total
   distance <= 8.80 km (skip the others); then append the unused micro-trip that
   overshoots 8.80 km the least.
5. **Scale** all speeds by ``s = 8800 m / distance`` (``s <= 1``, so the
   drivability limits still hold) so the trapezoidal distance is 8.80 km, and
   round to 5 decimals.

Harshness statistic (see ``cycles/README.md`` for the numbers): the 95th
percentiles of acceleration and of deceleration (over intervals with
|a| > 0.1 m/s^2) and the positive kinetic energy per distance (PKE) all exceed
HD-UDDS's.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from shevsim.cycles import IDLE_SPEED_MPS, Cycle, cycle_from_arrays, load_cycle, write_cycle_csv

#: Random seed of the micro-trip order.
SEED = 2014
#: Target total distance (m), seed App. A.2: 8.80 km.
TARGET_DISTANCE_M = 8800.0
#: Acceleration multiplier of the re-timing.
K_ACC = 1.5
#: Deceleration multiplier of the re-timing.
K_DEC = 1.5
#: Accelerations smaller than this are cruise and are not re-timed (m/s^2).
RETIME_THRESHOLD_MPS2 = 0.1
#: Longest idle kept before a micro-trip (s).
IDLE_MAX_S = 10
#: Acceleration cap (m/s^2): about 0.2 g, a hard but sane launch for a 15.5 t MRAP.
ACCEL_CAP_MPS2 = 2.0
#: Deceleration cap (m/s^2): about 0.25 g, firm service braking of a heavy truck.
DECEL_CAP_MPS2 = 2.5
#: Vehicle mass (kg), seed Table 5.1.
MASS_KG = 15554.0
#: Rotating-inertia factor (assumed, typical 1.03-1.08 for a heavy truck).
ROT_INERTIA_FACTOR = 1.05
#: Wheel-power budget (W): 380 kW motors x 0.9 drive efficiency x 0.88 margin.
WHEEL_POWER_BUDGET_W = 300e3
#: Rolling-resistance coefficient (assumed, off-road tyres on pavement).
ROLLING_COEFF = 0.010
#: Drag area Cd*A (m^2): assumed Cd 0.75 x frontal area 5.72 m^2 (Table 5.1).
DRAG_AREA_M2 = 0.75 * 5.72
#: Air density (kg/m^3).
AIR_DENSITY_KG_M3 = 1.2
GRAVITY_MPS2 = 9.81

SOURCE_CYCLES = ("hd_udds.csv", "orange_county_bus.csv")


def road_load_n(v_mps):
    """Road-load force (N) of the proxy's assumed vehicle: rolling + aero."""
    v = np.asarray(v_mps, dtype=float)
    return ROLLING_COEFF * MASS_KG * GRAVITY_MPS2 + 0.5 * AIR_DENSITY_KG_M3 * DRAG_AREA_M2 * v * v


def wheel_power_needed_w(v0, v1, dt=1.0):
    """Mean wheel power (W) to go from ``v0`` to ``v1`` in ``dt``: kinetic-energy gain + road load."""
    v0 = np.asarray(v0, dtype=float)
    v1 = np.asarray(v1, dtype=float)
    vm = 0.5 * (v0 + v1)
    return (0.5 * MASS_KG * ROT_INERTIA_FACTOR * (v1 * v1 - v0 * v0) + road_load_n(vm) * vm * dt) / dt


def split_micro_trips(speed_mps: np.ndarray) -> list[np.ndarray]:
    """Split a 1 Hz trace into micro-trips ``[idle..., drive..., 0]`` (idle capped at IDLE_MAX_S)."""
    v = np.where(np.asarray(speed_mps, float) < IDLE_SPEED_MPS, 0.0, np.asarray(speed_mps, float))
    moving = v > 0.0
    trips = []
    i, n = 0, v.size
    while i < n:
        j = i
        while j < n and not moving[j]:
            j += 1
        if j >= n:
            break
        k = j
        while k < n and moving[k]:
            k += 1
        idle = min(j - i, IDLE_MAX_S)
        idle = max(idle, 1)  # start from standstill
        trip = np.concatenate([np.zeros(idle), v[j:k], [0.0]])
        trips.append(trip)
        i = k
    return trips


def retime(trip: np.ndarray) -> np.ndarray:
    """Re-time a 1 Hz micro-trip (step 2) and resample at 1 Hz; ends at 0 speed."""
    a = np.diff(trip)
    dt = np.ones_like(a)
    dt[a > RETIME_THRESHOLD_MPS2] = 1.0 / K_ACC
    dt[a < -RETIME_THRESHOLD_MPS2] = 1.0 / K_DEC
    t = np.concatenate([[0.0], np.cumsum(dt)])
    tn = np.arange(0.0, np.floor(t[-1] + 1e-9) + 1.0)
    vn = np.interp(tn, t, trip)
    vn[-1] = 0.0
    return vn


def make_drivable(v: np.ndarray) -> np.ndarray:
    """Step 3: lower speeds so that deceleration, acceleration and wheel power stay within the caps."""
    v = v.copy()
    for i in range(v.size - 2, -1, -1):  # backward pass: braking limit
        v[i] = min(v[i], v[i + 1] + DECEL_CAP_MPS2)
    for i in range(v.size - 1):  # forward pass: acceleration and power limits
        v0 = v[i]
        hi = min(v[i + 1], v0 + ACCEL_CAP_MPS2)
        if hi > v0 and wheel_power_needed_w(v0, hi) > WHEEL_POWER_BUDGET_W:
            lo = v0
            for _ in range(60):
                mid = 0.5 * (lo + hi)
                if wheel_power_needed_w(v0, mid) > WHEEL_POWER_BUDGET_W:
                    hi = mid
                else:
                    lo = mid
            hi = lo
        v[i + 1] = hi
    return v


def _distance(v: np.ndarray) -> float:
    return float(np.sum(0.5 * (v[1:] + v[:-1])))


def build_uac_proxy(cycle_folder: str | Path, seed: int = SEED) -> tuple[Cycle, dict]:
    """Build the UAC proxy from the source cycles in ``cycle_folder``.

    Returns
    -------
    cycle : Cycle
        The proxy (1 Hz, 8.80 km).
    info : dict
        Procedure record: trips used (source, index), speed scale factor.
    """
    folder = Path(cycle_folder)
    pool = []
    for fname in SOURCE_CYCLES:
        src = load_cycle(folder / fname)
        for k, trip in enumerate(split_micro_trips(src.speed_mps)):
            vt = make_drivable(retime(trip))
            d = _distance(vt)
            if d > 1.0:
                pool.append((f"{src.name}#{k}", vt, d))
    rng = np.random.default_rng(seed)
    order = list(rng.permutation(len(pool)))
    chosen, total, unused = [], 0.0, []
    for j in order:
        if total + pool[j][2] <= TARGET_DISTANCE_M:
            chosen.append(j)
            total += pool[j][2]
        else:
            unused.append(j)
    over = [j for j in unused if total + pool[j][2] >= TARGET_DISTANCE_M]
    if not over:
        raise RuntimeError("UAC proxy: source micro-trips too short to reach 8.80 km")
    last = min(over, key=lambda j: total + pool[j][2])
    chosen.append(last)
    v = np.concatenate([pool[j][1] for j in chosen])
    scale = TARGET_DISTANCE_M / _distance(v)
    v = np.round(v * scale, 5)
    cyc = cycle_from_arrays("uac_proxy", np.arange(v.size, dtype=float), v, source="shevsim.uac_proxy")
    info = {"trips": [pool[j][0] for j in chosen], "speed_scale": scale, "seed": seed}
    return cyc, info


HEADER = """UAC proxy -- NOT the Urban Assault Cycle (no public trace exists).
Built by shevsim.uac_proxy (python -m shevsim.uac_proxy) from HD-UDDS and Orange County Bus
micro-trips, re-timed to harsher acceleration/deceleration, joined and scaled to 8.80 km.
See cycles/README.md for the procedure and statistics."""


def write_uac_proxy(cycle_folder: str | Path, out_path: str | Path | None = None) -> Path:
    """Build the proxy and write it as CSV (default ``<cycle_folder>/uac_proxy.csv``)."""
    cyc, _ = build_uac_proxy(cycle_folder)
    out = Path(out_path) if out_path else Path(cycle_folder) / "uac_proxy.csv"
    write_cycle_csv(cyc, out, HEADER)
    return out


def plot_accel_comparison(cycle_folder: str | Path, out_png: str | Path) -> Path:
    """Fig. A.1-style comparison: acceleration and deceleration distributions, UAC proxy vs HD-UDDS.

    Left: share of time per acceleration bin (|a| > 0.1 m/s^2); right: acceleration versus
    speed (each 1 s interval), with the proxy's drivability limit.
    """
    from shevsim.plotting import headless_pyplot
    plt = headless_pyplot()

    folder = Path(cycle_folder)
    cyc = {"HD-UDDS": load_cycle(folder / "hd_udds.csv"), "UAC proxy": load_cycle(folder / "uac_proxy.csv")}
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4.2))
    bins = np.arange(-3.0, 3.01, 0.25)
    for (name, c), col in zip(cyc.items(), ("tab:blue", "tab:red")):
        a = c.accel_mps2
        a = a[np.abs(a) > RETIME_THRESHOLD_MPS2]
        w = np.full(a.size, 100.0 / c.accel_mps2.size)
        ax1.hist(a, bins=bins, weights=w, histtype="step", lw=2, color=col, label=name)
        vm = 0.5 * (c.speed_mps[1:] + c.speed_mps[:-1]) * 3.6
        ax2.plot(vm, c.accel_mps2, ".", ms=3, alpha=0.5, color=col, label=name)
        s = c.stats()
        for q, ls in ((s["accel_p95_mps2"], "--"), (-s["decel_p95_mps2"], "--")):
            ax1.axvline(q, color=col, ls=ls, lw=1)
    v = np.linspace(0.5, 70 / 3.6, 200)
    a_lim = np.minimum(ACCEL_CAP_MPS2, (WHEEL_POWER_BUDGET_W / v - road_load_n(v)) / (MASS_KG * ROT_INERTIA_FACTOR))
    ax2.plot(v * 3.6, a_lim, "k-", lw=1, label="proxy limit (300 kW wheel, 2 m/s2)")
    ax2.axhline(-DECEL_CAP_MPS2, color="k", lw=1)
    ax1.set_xlabel("acceleration [m/s2] (dashed: 95th percentiles)")
    ax1.set_ylabel("share of cycle time [%]")
    ax1.legend()
    ax2.set_xlabel("speed [km/h]")
    ax2.set_ylabel("acceleration [m/s2]")
    ax2.legend(fontsize=8)
    fig.suptitle("Acceleration/deceleration: UAC proxy (not the UAC) vs HD-UDDS (cf. seed Fig. A.1)")
    fig.tight_layout()
    out = Path(out_png)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description="Regenerate the UAC proxy cycle CSV.")
    ap.add_argument("--cycles", default=str(Path(__file__).resolve().parents[1] / "cycles"))
    ap.add_argument("--out", default=None)
    ap.add_argument("--plot", default=None, help="also save the Fig. A.1-style comparison PNG here")
    a = ap.parse_args(argv)
    out = write_uac_proxy(a.cycles, a.out)
    cyc, info = build_uac_proxy(a.cycles)
    print(f"wrote {out}: {cyc.duration_s:.0f} s, {cyc.distance_m / 1000:.4f} km, "
          f"{len(info['trips'])} micro-trips, speed scale {info['speed_scale']:.4f}")
    if a.plot:
        print(f"wrote {plot_accel_comparison(a.cycles, a.plot)}")


if __name__ == "__main__":
    main()
