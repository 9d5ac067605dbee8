"""synthetic.py - "measured" data from a richer truth model with undeclared effects, for tests.

The truth differs from the calibration library in ways a real plant would:

* declared parameters are NOT at the library's defaults (``CELL_TRUTH``, ``VEHICLE_TRUTH``);
* the cell truth is the battery COMPONENT stepped by the master at 0.1 s (finer than the samples); its cooling change is a hard
  step (a fault on its convection input, not the 20 s logistic the calibration fits), sensors add Gaussian noise (current 10 mA,
  voltage 2 mV, temperature 0.05 K) and the model only sees the noisy measured current;
* the vehicle truth is the co-simulation plant itself (cycle -> PI driver -> motor -> vehicle, bus,
  stepped by the master at 0.1 s) with the effect switched on through the components' parameters; the
  calibration follows the noisy measured speed at the logger's rate; the grade is a smooth sinusoid
  (the library has a 6-knot piecewise-linear one); power noise 1 % + 300 W, speed noise 0.01 m/s
  (CAN wheel-speed resolution is ~0.003 m/s); accelerations are jerk-limited (2 s moving average).

Effects are given as ``{"name": {param: value}}`` (``{}`` = the default truth value in
``CELL_EFFECTS`` / ``VEHICLE_EFFECTS``).
"""
from __future__ import annotations

import numpy as np
import pandas as pd

from .data import MeasuredData

# the plant: the battery component (one A123 cell) with parameters away from the nominal's defaults
CELL_TRUTH = {"rs_scale": 1.3, "r1_scale": 0.8, "c1_scale": 1.5, "kt_w_mk": 0.5, "cp_j_kgk": 1000.0,
              "h_conv_factor": 0.75}
# nominal model the calibration starts from (the plant without any effect; scale factors free)
CELL_NOMINAL = {"soc0_frac": 0.95, "entropic_heat": False, "temperature_dependent": False, "r2_scale": 0.0}
# effect -> battery parameters that switch it on in the plant (cooling_change: a fault on the h input)
CELL_EFFECTS = {
    "entropic_heat": {"dudt_soc_frac": (0.1, 0.45, 0.9), "dudt_v_k": (-1.2e-3, 2e-4, 6e-4)},
    "arrhenius_resistance": {"arrhenius_ea_r_k": 4000.0, "arrhenius_t_ref_c": 25.0},
    "cooling_change": {"h_factor": 0.2, "at_frac": 0.4},
    "ocv_hysteresis": {"hyst_max_v": 0.025, "hyst_rate": 40.0},
    "capacity": {"capacity_ah": 1.85},
    "current_offset": {"offset_a": 0.15},
    "low_soc_resistance": {"lowsoc_r_gain": 3.0, "lowsoc_r_scale_frac": 0.08},
    "second_rc_branch": {"r2_scale": 1.0, "c2_scale": 1.0},
    "initial_soc": {"soc_init_pct": 80.0},           # the plant starts there; the nominal says soc0
    "ocv_correction": {"tilt_v": 0.03},      # the plant's OCV: the given curve + tilt (SOC - 0.5) (stays increasing)
    "solid_diffusion": {"diffusion_time_s": 8000.0},
}
VEHICLE_TRUTH = {"efficiency_scale_frac": 0.96}
VEHICLE_EFFECTS = {   # component parameters of the plant (vehicle / motor / bus), see synth_vehicle
    "road_grade": {"amplitude_frac": 0.02, "offset_frac": 0.004},
    "aux_load": {"aux_power_w": 8000.0},
    "mass_error": {"mass_kg": 15554.0 * 1.25},
    "rolling_error": {"rolling_coefficient": 0.012 * 1.8},
    "aero_error": {"drag_coefficient": 0.7 * 1.6},
    "regen_limit": {"regen_power_max_w": 50000.0},
}


def _cell_current(duration_s: float, dt: float, rng, quantum_s: float, charge_rests: bool = False):
    """Drive-like current [A, + discharge]: random pulses (up to 12 A = 4C, regen down to -6 A) and rests.

    Segment boundaries fall on multiples of ``quantum_s`` (the logger's sample period).  ``charge_rests``: every
    other rest (at random) is reached after a charge of 60-180 s at 1-3 A (the record then has rests reached after
    charge and after discharge, what a lab uses to see OCV hysteresis: on a drive that only discharges between its
    rests the hysteresis state is the same at every rest, and the rests cannot tell it from an OCV offset).
    Returns the current and the mask of those charges (the caller does not scale them)."""
    n = int(round(duration_s / dt)) + 1
    q = max(1, int(round(quantum_s / dt)))
    i = np.zeros(n)
    held = np.zeros(n, bool)
    k = int(60 / dt)  # initial rest
    while k < n:
        if rng.random() < 0.2:
            if charge_rests and rng.random() < 0.5:
                seg = q * int(rng.uniform(60, 180) / quantum_s)
                i[k:k + seg] = -rng.uniform(1.0, 3.0)
                held[k:k + seg] = True
                k += seg
            k += q * int(rng.uniform(60, 240) / quantum_s)  # rest
            continue
        seg = q * max(1, int(rng.uniform(3, 25) / quantum_s))
        val = rng.choice([rng.uniform(1.0, 12.0), rng.uniform(-6.0, -0.5), rng.uniform(1.0, 4.0)], p=[0.5, 0.25, 0.25])
        i[k:k + seg] = val
        k += seg
    return i, held[:n]


def _bumped_ocv_file(e: dict) -> str:
    """The default OCV table plus ``tilt_v (SOC - 0.5)`` (an increasing correction: the table stays strictly
    increasing) in a temporary file."""
    import tempfile
    from ..battery.cell import CellTables
    tab = CellTables()._ocv
    xs = np.asarray(tab.xs, float)
    ys = np.asarray(tab.ys, float) + e["tilt_v"] * (xs - 0.5)
    fd, path = tempfile.mkstemp(suffix="_ocv.csv", prefix="shevsim_synth_")
    with open(fd, "w") as fh:
        fh.write("soc_frac,ocv_v\n" + "".join(f"{float(a)!r},{float(b)!r}\n" for a, b in zip(xs, ys)))
    return path


def synth_cell(effects: dict | None = None, duration_s: float = 2400.0, dt_s: float = 1.0,
               ambient: str = "constant", seed: int = 0, truth: dict | None = None, soc0: float = 0.95,
               discharge_frac: float = 0.6, charge_rests: bool = False):
    """Synthetic cell record from the co-simulation plant, and the truth used.

    The ``battery`` component (one cell, current input) is stepped by the master at 0.1 s with
    ``CELL_TRUTH`` plus the effects' parameters (``{"name": {param: value}}``, ``{}`` = the defaults in
    :data:`CELL_EFFECTS`); a cooling change is a fault on its convection input (the master's fault
    mechanism, a hard step), a current-sensor offset is added to the logged current.  A logger samples
    every ``dt_s``: current of the interval starting at the sample, voltage and temperatures 0.1 s later
    (after the step change), with Gaussian noise (10 mA, 2 mV, 0.05 K, ambient 0.1 K).
    ``ambient``: ``"constant"`` (25 degC) or ``"warmup"`` (chamber from -10 to +25 degC).  The cell starts at
    ``soc0`` and the discharge pulses are scaled so the record's net discharge is ``discharge_frac`` of 2.3 Ah.
    ``charge_rests``: half the rests are reached after a charge (:func:`_cell_current`).
    """
    from ..components.battery import BatteryPack, BatteryPackParams
    from ..components.profile import ProfileParams, ProfileSource
    from ..core.master import Connection, Fault, Master, MasterSettings
    rng = np.random.default_rng(seed)
    fine = 0.1
    i_true, held = _cell_current(duration_s, fine, rng, dt_s, charge_rests)
    # discharge pulses scaled (x0.3 .. x2) towards a net discharge of discharge_frac of 2.3 Ah, then down
    # until the SOC stays within [0.03, 0.98] along the whole record (the charges before rests are not scaled)
    dis = float(np.sum(np.maximum(i_true, 0.0)) * fine / 3600.0)
    chg = float(np.sum(np.maximum(-i_true[~held], 0.0)) * fine / 3600.0)
    target = discharge_frac * 2.3 + float(np.sum(-i_true[held]) * fine / 3600.0)
    scale = min(max((target + chg) / dis, 0.3), 2.0) if dis > 0 else 1.0
    # then the charge pulses (x0.2 .. x1) make up what the capped discharge scale could not
    scale_c = min(max((scale * dis - target) / chg, 0.2), 1.0) if chg > 0 else 1.0
    for _ in range(100):
        i_try = np.where(held, i_true, np.where(i_true > 0, i_true * scale, i_true * scale_c))
        soc = soc0 - np.cumsum(i_try) * fine / (3600.0 * 2.3)
        if soc.min() >= 0.03 and soc.max() <= 0.98:
            break
        if soc.min() < 0.03:
            scale *= 0.9
        else:
            scale_c *= 0.8
    i_true = i_try
    n = i_true.size
    t = np.arange(n) * fine
    if ambient == "constant":
        ta = np.full(n, 25.0)
    elif ambient == "warmup":
        ta = -10.0 + 35.0 * np.clip(t / (0.8 * t[-1]), 0, 1)
    else:
        raise ValueError(ambient)
    vals = dict(CELL_TRUTH, **(truth or {}))
    faults, offset = [], 0.0
    for name, over in (effects or {}).items():
        e = dict(CELL_EFFECTS[name], **(over or {}))
        if name == "cooling_change":
            faults.append(Fault(round(e["at_frac"] * t[-1]), "battery", "h_conv_w_m2k", 20.0 * e["h_factor"]))
            vals["_cooling_change"] = e
        elif name == "current_offset":
            offset = e["offset_a"]
            vals["_current_offset_a"] = offset
        elif name == "ocv_correction":
            vals["ocv_file"] = _bumped_ocv_file(e)
            vals["_ocv_correction"] = e
        else:
            vals.update(e)
    plant = {k: v for k, v in vals.items() if not k.startswith("_")}
    base = dict(n_series=1, n_parallel=1, input_mode="current", soc_init_pct=100.0 * soc0, t_init_c=float(ta[0]),
                entropic_heat=False, temperature_dependent=False, r2_scale=0.0, seed=seed,
                sigma_current_a=0.0, sigma_voltage_v=0.0, sigma_temperature_c=0.0)
    base.update({k: (tuple(v) if isinstance(v, (list, tuple)) else v) for k, v in plant.items()})
    prm = BatteryPackParams(**base)
    src = ProfileSource("profile", ProfileParams(time_s=tuple(t), current_a=tuple(i_true), t_ambient_c=tuple(ta)))
    conns = [Connection("profile", "current_a", "battery", "current_cmd_a"),
             Connection("profile", "t_ambient_c", "battery", "t_ambient_c")]
    res = Master([src, BatteryPack("battery", prm)], conns, MasterSettings(step_s=fine), faults=faults,
                 order=["profile", "battery"]).run(float(t[-1]) + fine)
    if "_ocv_correction" in vals:                # our own temporary table (read when the battery was built)
        import os
        os.unlink(vals["ocv_file"])
    step = int(round(dt_s / fine))
    ks = np.arange(0, n, step)
    m = ks.size
    # the plant's outputs at t_k + 0.1 are the state just after the interval's current was applied
    v = np.asarray(res["battery.voltage_v"])[ks + 1]
    ts = np.asarray(res["battery.t_surface_c"])[ks + 1]
    df = pd.DataFrame({
        "time_s": t[ks],
        "current_a": i_true[ks] + offset + rng.normal(0, 0.01, m),
        "voltage_v": v + rng.normal(0, 0.002, m),
        "t_surface_c": ts + rng.normal(0, 0.05, m),
        "t_ambient_c": ta[ks] + rng.normal(0, 0.1, m),
    })
    return df, vals


def _speed_profile(duration_s: float, dt: float, rng):
    """Stop-and-go plus faster stretches: exact speed [m/s] and acceleration [m/s^2]."""
    n = int(round(duration_s / dt)) + 1
    a = np.zeros(n)
    v = np.zeros(n)
    k = int(10 / dt)
    cur = 0.0
    while k < n - 1:
        target = rng.choice([0.0, rng.uniform(5, 12), rng.uniform(12, 25)], p=[0.3, 0.4, 0.3])
        acc = rng.uniform(0.4, 1.2) if target > cur else -rng.uniform(0.5, 1.5)
        steps = int(abs(target - cur) / abs(acc) / dt) if target != cur else 0
        a[k:k + steps] = acc
        k += steps
        cur = target if steps else cur
        hold = int(rng.uniform(5, 60 if target > 0 else 25) / dt)
        k += hold
    # jerk-limited: smooth the acceleration steps over 2 s (a moving average keeps the speed targets)
    w = max(1, int(round(2.0 / dt)))
    a = np.convolve(a[:n], np.ones(w) / w, mode="full")[:n]
    v = np.concatenate([[0.0], np.cumsum(a[:-1] * dt)])
    v = np.maximum(v, 0.0)
    return v, a


def synth_vehicle(effects: dict | None = None, duration_s: float = 1800.0, dt_s: float = 1.0,
                  seed: int = 0, truth: dict | None = None):
    """Synthetic vehicle record (``time_s``, ``speed_mps``, ``power_w``) from the co-simulation plant.

    The plant is the simulator's own forward chain stepped by :class:`~shevsim.core.master.Master` at
    0.1 s: ``cycle`` (a jerk-limited stop-and-go profile) -> ``driver`` (PI + feed-forward with the
    nominal vehicle) -> ``motor`` -> ``vehicle`` (force mode) and ``bus``; effects are switched on through
    the components' parameters (``VEHICLE_EFFECTS``: e.g. ``mass_kg``, ``aux_power_w``; ``road_grade`` is a
    smooth sinusoid ``offset + amplitude sin(2 pi d / D + 0.7)`` over the distance ``D`` sampled as
    ``grade_frac`` knots every 50 m - richer than the calibration's 6 knots).  Logged every ``dt_s``:
    the vehicle speed at the sample time + N(0, 0.01 m/s), and the bus demand power averaged over the
    sample period ending at it (an energy-integrating logger) x (1 + N(0, 1 %)) + N(0, 300 W).

    Returns the DataFrame and the truth: ``{component parameter: value}`` (grade: the two shape values).
    """
    import tempfile
    from pathlib import Path

    from ..components import get_component_class
    from ..core.master import Connection, Master, MasterSettings
    from ..core.params import load_params
    from .vehicle import PARAM_FILES, OWNERS

    rng = np.random.default_rng(seed)
    dt = 0.1
    v, _ = _speed_profile(duration_s, dt, rng)
    vals = dict(VEHICLE_TRUTH)
    vals.update(truth or {})
    for name, over in (effects or {}).items():
        vals.update(dict(VEHICLE_EFFECTS[name], **(over or {})))
    over = {"vehicle": {}, "motor": {}, "bus": {}}
    for k, x in vals.items():
        for comp in OWNERS.get(k, ()):
            over[comp][k] = x
    if vals.get("amplitude_frac", 0.0) or vals.get("offset_frac", 0.0):
        d_end = float(np.sum(v) * dt)
        kd = np.arange(0.0, d_end + 50.0, 50.0)
        kg = vals.get("offset_frac", 0.0) + vals.get("amplitude_frac", 0.0) * np.sin(2 * np.pi * kd / max(d_end, 1.0) + 0.7)
        over["vehicle"]["grade_distance_m"] = [float(x) for x in kd]
        over["vehicle"]["grade_frac"] = [float(x) for x in kg]
    cyc_cls, drv_cls = get_component_class("cycle"), get_component_class("driver")
    with tempfile.TemporaryDirectory() as tmp:
        f = Path(tmp) / "profile.csv"
        f.write_text("time_s,speed_mps\n" + "\n".join(f"{k * dt!r},{float(x)!r}" for k, x in enumerate(v)) + "\n")
        comps = [cyc_cls("cycle", load_params(cyc_cls.Params, None, {"cycle_file": str(f)})),
                 drv_cls("driver", load_params(drv_cls.Params, PARAM_FILES["vehicle"].parents[1] / "driver" / "default.toml"))]
    for n in ("vehicle", "motor", "bus"):
        cls = get_component_class(n)
        comps.append(cls(n, load_params(cls.Params, PARAM_FILES[n], over[n])))
    conns = [Connection.parse(a, b) for a, b in (
        ("driver.speed_ref_mps", "cycle.speed_ref_mps"), ("driver.accel_ref_mps2", "cycle.accel_ref_mps2"),
        ("driver.speed_mps", "vehicle.speed_mps"), ("motor.force_req_n", "driver.force_req_n"),
        ("motor.speed_mps", "vehicle.speed_mps"), ("vehicle.traction_force_n", "motor.traction_force_n"),
        ("vehicle.brake_force_n", "motor.brake_force_n"), ("bus.motor_power_w", "motor.elec_power_w"))]
    master = Master(comps, conns, MasterSettings(step_s=dt), order=["cycle", "vehicle", "driver", "motor", "bus"])
    res = master.run((v.size - 1) * dt)
    vs = np.asarray(res["vehicle.speed_mps"], float)
    pw = np.asarray(res["bus.demand_power_w"], float)
    step = int(round(dt_s / dt))
    n = (vs.size - 1) // step + 1
    t = np.arange(n) * step * dt
    p_s = np.empty(n)
    p_s[0] = pw[0]
    p_s[1:] = pw[:(n - 1) * step].reshape(n - 1, step).mean(axis=1)
    df = pd.DataFrame({"time_s": t,
                       "speed_mps": np.maximum(vs[::step][:n] + rng.normal(0, 0.01, n), 0.0),
                       "power_w": p_s * (1 + rng.normal(0, 0.01, n)) + rng.normal(0, 300.0, n)})
    return df, vals


#: the sample convention of this module's records: the vehicle plant's power is the mean over the period
#: ending at the sample, its speed the value at the sample time; cell and engine records are the plant's values at
#: the sample time
SYNTH_CONVENTION = {"vehicle": "power_w=mean-ending", "cell": "instantaneous", "engine": "instantaneous"}


def as_measured(df: pd.DataFrame, model: str, convention: str | None = None, path: str = "<synthetic>") -> MeasuredData:
    """Wrap a synthetic DataFrame as loaded data (skips the file checks); ``sample_convention`` is the
    generator's (default: this module's, :data:`SYNTH_CONVENTION`)."""
    data = MeasuredData(df=df.reset_index(drop=True), path=path, model=model)
    data.sample_convention = convention or SYNTH_CONVENTION.get(model, "instantaneous")
    return data


# the engine-generator plant: the component's default parameters, soot scale away from 1, no effect
ENGINE_TRUTH = {"soot_scale_frac": 1.3, "transient_soot_mg_per_g": 0.0}
ENGINE_EFFECTS = {  # effect -> the plant's component parameters switching it on
    "transient_soot": {"transient_soot_mg_per_g": 10.0},
    "analyzer_lag": {"soot_analyzer_tau_s": 4.0},
    "analyzer_offset": {"soot_analyzer_offset_mgps": 1.5},
}


def _engine_command(duration_s: float, dt: float, rng):
    """Supervisor-like power command [W]: random levels (off, part load, high load) held 5-40 s."""
    n = int(round(duration_s / dt)) + 1
    p = np.zeros(n)
    k = 0
    while k < n:
        seg = max(1, int(rng.uniform(5, 40) / dt))
        p[k:k + seg] = rng.choice([0.0, rng.uniform(20e3, 100e3), rng.uniform(100e3, 230e3)], p=[0.15, 0.45, 0.4])
        k += seg
    return np.arange(n) * dt, p


def synth_engine(effects: dict | None = None, duration_s: float = 900.0, dt_s: float = 1.0,
                 seed: int = 0, truth: dict | None = None, rate_wps: float = 1e12):
    """Synthetic engine-generator record (``time_s``, ``power_w`` = power command, ``soot_rate_mgps``) from
    the ``engine_generator`` component stepped by the master behind a sample-and-hold command source,
    with ``ENGINE_TRUTH`` (+ ``truth``) and the effects' component parameters; analyser noise 2 % +
    0.05 mg/s on the component's measured soot output.  Returns the DataFrame and the parameters used."""
    from ..components import get_component_class
    from ..core.master import Connection, Master, MasterSettings
    from ..core.params import load_params
    from .engine import DEFAULT_PARAMS_FILE, power_source
    rng = np.random.default_rng(seed)
    t, p = _engine_command(duration_s, dt_s, rng)
    vals = dict(ENGINE_TRUTH, **(truth or {}))
    for name, over in (effects or {}).items():
        vals.update(dict(ENGINE_EFFECTS[name], **(over or {})))
    cls = get_component_class("engine_generator")
    eg = cls("engine_generator", load_params(cls.Params, DEFAULT_PARAMS_FILE, vals))
    eg.u["power_rate_max_wps"] = rate_wps
    src = power_source(t, p)
    m = Master([src, eg], [Connection(src.name, "power_w", "engine_generator", "power_cmd_w")],
               MasterSettings(step_s=dt_s), order=[src.name, "engine_generator"])
    res = m.run(float(t[-1]))
    s = np.asarray(res["engine_generator.soot_rate_meas_mgps"], float)
    s = s * (1.0 + rng.normal(0.0, 0.02, s.size)) + rng.normal(0.0, 0.05, s.size)
    return pd.DataFrame({"time_s": t, "power_w": p, "soot_rate_mgps": s}), vals
