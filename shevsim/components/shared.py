"""shared.py - the quantities of the vehicle as a whole, declared once (``[shared]`` in a scenario).

Several components need the same vehicle-level number: the vehicle and the driver's feed-forward the
mass, the battery and the BMS the pack and its cell, the supervisors the generator's electrical rating and
the pack capacity, the metrics the fuel's density.  A scenario declares each of them once::

    [shared]
    vehicle = "matv"            # a bundled vehicle (vehicles/matv.toml) or a vehicle file: the base set
    mass_kg = 12000.0           # then any quantity of QUANTITIES, replacing the vehicle's

and every component of the scenario takes it from there (:data:`IDENTITY`: the same parameter under
the component's own name; :func:`_derived`: parameters computed from them by a written rule).  The
rules, for a component of each type:

=================  =====================================================================================
vehicle, driver    ``mass_kg``, ``frontal_area_m2``, ``drag_coefficient``, ``rolling_coefficient``,
                   ``air_density_kg_m3`` (the driver's feed-forward is the vehicle's road-load model);
                   the vehicle also ``wheel_radius_m`` (its wheels' equivalent mass ``J / r^2``)
motor              ``wheel_radius_m``; ``rated_power_w`` = ``motor_power_w`` (maps sized by rating)
engine_generator   ``rated_power_w`` = ``engine_power_w`` (maps sized by rating, generator with the
                   engine); ``fuel_lhv_j_per_g``
battery            ``n_series``, ``n_parallel``; the cell: ``capacity_ah`` = ``cell_capacity_ah``, its
                   tables (``cell_ocv_file`` ...), thermal parameters, calibration factors
                   (``cell_rs_scale`` ...), ``temperature_dependent`` and ``diffusion_time_s``
bms                the same pack and cell (its nominal cell model is the plant's cell, with its solid
                   diffusion ``cell_diffusion_time_s``) plus the cell's
                   voltage limits ``cell_v_min_v``/``cell_v_max_v`` and the SOC window ``soc_min_pct``/
                   ``soc_max_pct``; a cell without second RC branch (``cell_r2_scale = 0``) gives
                   ``v2_model = "none"``
bus, power_limits  ``aux_power_w`` (the bus books it, the limits reserve it: the same load)
mpc_supervisor     the SOC window; ``capacity_ah`` = ``n_parallel x cell_capacity_ah``;
                   ``power_gen_max_w`` = the engine-generator's maximum steady electrical output (end of
                   its optimal operating line, x the sizing factor k = engine_power_w / the maps' rating);
                   for ``k != 1`` the fuel curve (``fuel_vs_power.csv``) with power and fuel x k
rule_supervisor    the SOC window; ``power_gen_max_w`` as above
metrics            ``fuel_density_kg_per_l``
=================  =====================================================================================

Routes of a change, all reaching every user: the scenario's ``[shared]`` table, ``--set shared.NAME=V``
and ``overrides={"shared.NAME": V}`` (``Scenario.set``), an overlay's ``[shared]`` table, and a
component-level value of an identity-bound parameter given by ``--set``, overrides, a scenario's ``set``
table or an overlay (a calibration's ``[battery]`` table): it is *lifted* to the shared quantity, so
``--set battery.n_parallel=6`` changes the BMS and the supervisor too.  Two declarations that disagree
(``[shared] mass_kg`` and ``--set vehicle.mass_kg``; ``battery.n_parallel`` and ``bms.n_parallel``; a
component's parameter file stating another value) are an error naming both.

A component keeps its own value only when it says so: ``[components.bms] own = ["cell"]`` (a BMS
designed for another cell, robustness studies); ``own`` lists parameter names or shared quantity names
(``"cell"`` = every ``cell_*`` quantity).  A scenario without ``[shared]`` runs as before (each component
on its own parameters).
"""
from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from shevsim.core.errors import ScenarioError
from shevsim.core.paths import DATA_ROOT

#: the cell's quantities: ``cell_<battery parameter>`` (the BMS takes the same names)
CELL_PARAMS = ("capacity_ah", "ocv_file", "entropy_file", "discharge_file", "charge_file", "radius_m", "length_m",
               "density_kg_m3", "cp_j_kgk", "kt_w_mk", "rs_scale", "r1_scale", "c1_scale", "r2_scale", "c2_scale",
               "temperature_dependent", "diffusion_time_s")
#: the cell's limits (BMS only: the plant has none)
CELL_LIMITS = ("v_min_v", "v_max_v")

#: every shared quantity and what it is
QUANTITIES: dict[str, str] = {
    "vehicle": "bundled vehicle name (shevsim vehicles) or vehicle file: the base set of quantities",
    "mass_kg": "vehicle test mass [kg]",
    "frontal_area_m2": "frontal area [m2]",
    "drag_coefficient": "aerodynamic drag coefficient [1]",
    "rolling_coefficient": "rolling-resistance coefficient [1]",
    "air_density_kg_m3": "air density [kg/m3]",
    "wheel_radius_m": "loaded tyre radius [m]",
    "motor_power_w": "rated (peak) traction power of the drive [W]",
    "engine_power_w": "rated engine power [W] (the generator is sized with the engine)",
    "aux_power_w": "constant auxiliary electrical load on the bus [W] (HVAC, fans, electronics)",
    "fuel": "named fuel (diesel): sets fuel_lhv_j_per_g and fuel_density_kg_per_l",
    "fuel_lhv_j_per_g": "fuel lower heating value [J/g]",
    "fuel_density_kg_per_l": "fuel density [kg/L] (fuel economy in km/L)",
    "cell": "bundled cell set (components/cell/NAME.toml) or cell file: sets every cell_* quantity",
    "n_series": "cells in series [1]",
    "n_parallel": "cells in parallel [1]",
    "soc_min_pct": "lowest SOC of the operating window [%] (BMS limits, supervisors)",
    "soc_max_pct": "highest SOC of the operating window [%]",
    **{f"cell_{p}": f"cell parameter '{p}' (battery plant and BMS nominal model)" for p in CELL_PARAMS},
    **{f"cell_{p}": f"cell limit '{p}' (BMS)" for p in CELL_LIMITS},
}

_BODY = ("mass_kg", "frontal_area_m2", "drag_coefficient", "rolling_coefficient", "air_density_kg_m3")
_CELL_MAP = {p: f"cell_{p}" for p in CELL_PARAMS}

#: component type -> {its parameter: the shared quantity it is}
IDENTITY: dict[str, dict[str, str]] = {
    "vehicle": {**{p: p for p in _BODY}, "wheel_radius_m": "wheel_radius_m"},
    "driver": {p: p for p in _BODY},
    "motor": {"wheel_radius_m": "wheel_radius_m", "rated_power_w": "motor_power_w"},
    "engine_generator": {"rated_power_w": "engine_power_w", "fuel_lhv_j_per_g": "fuel_lhv_j_per_g"},
    "battery": {"n_series": "n_series", "n_parallel": "n_parallel", **_CELL_MAP},
    "bms": {"n_series": "n_series", "n_parallel": "n_parallel", **_CELL_MAP,
            **{p: f"cell_{p}" for p in CELL_LIMITS}, "soc_min_pct": "soc_min_pct", "soc_max_pct": "soc_max_pct"},
    "bus": {"aux_power_w": "aux_power_w"},
    "power_limits": {"aux_power_w": "aux_power_w"},
    "mpc_supervisor": {"soc_min_pct": "soc_min_pct", "soc_max_pct": "soc_max_pct"},
    "rule_supervisor": {"soc_min_pct": "soc_min_pct", "soc_max_pct": "soc_max_pct"},
}
#: component type -> parameters computed from shared quantities (a value given for them is checked)
DERIVED: dict[str, tuple[str, ...]] = {
    "mpc_supervisor": ("capacity_ah", "power_gen_max_w", "fuel_curve_w", "fuel_rate_gps"),
    "rule_supervisor": ("power_gen_max_w",),
    "bms": ("v2_model",),
}

#: derived values that replace the component's default without being a contradiction: the BMS's
#: ``v2_model = "nominal_maps"`` is its design for a two-branch cell; a cell without the branch has none
_FOLLOWS = {"v2_model"}

FUELS = {"diesel": {"fuel_lhv_j_per_g": 42600.0,          # ADVISOR fc_fuel_lhv
                    "fuel_density_kg_per_l": 3.167 / 3.78541}}   # = shevsim.metrics.DIESEL_DENSITY_KG_PER_L (GREET)

_INT = {"n_series", "n_parallel"}
_STR = {"vehicle", "cell", "fuel"}
_BOOL = {"cell_temperature_dependent"}


def check_value(name: str, value: Any, where: str) -> Any:
    """Check one shared quantity's name and type; returns the value (ints as int, numbers as float)."""
    if name not in QUANTITIES:
        import difflib
        best = difflib.get_close_matches(name, sorted(QUANTITIES), n=1)
        hint = f" (did you mean '{best[0]}'?)" if best else f" (known: {', '.join(sorted(QUANTITIES))})"
        raise ScenarioError(f"{where}: unknown shared quantity '{name}'{hint}")
    if name in _STR or name.endswith("_file"):
        if not isinstance(value, str) or not value:
            raise ScenarioError(f"{where}: shared quantity '{name}' must be a non-empty string, got {value!r}")
        return value
    if name in _BOOL:
        if not isinstance(value, bool):
            raise ScenarioError(f"{where}: shared quantity '{name}' must be true or false, got {value!r}")
        return value
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ScenarioError(f"{where}: shared quantity '{name}' must be a finite number, got {value!r}")
    if name in _INT:
        if not float(value).is_integer() or value < 1:
            raise ScenarioError(f"{where}: shared quantity '{name}' must be an integer >= 1, got {value!r}")
        return int(value)
    if name.endswith("_pct"):
        if not 0.0 <= value <= 100.0:
            raise ScenarioError(f"{where}: shared quantity '{name}' must be in [0, 100], got {value!r}")
    elif name in ("cell_r2_scale", "aux_power_w", "cell_diffusion_time_s"):
        if value < 0.0:
            raise ScenarioError(f"{where}: shared quantity '{name}' must be >= 0, got {value!r}")
    elif not value > 0.0:
        raise ScenarioError(f"{where}: shared quantity '{name}' must be > 0, got {value!r}")
    return float(value)


# ------------------------------------------------------------------------------------ named sets
def vehicles_dir() -> Path:
    """The folder of the bundled vehicles."""
    return DATA_ROOT / "vehicles"


def bundled_vehicles() -> list[str]:
    """Names of the bundled vehicles."""
    return sorted(p.stem for p in vehicles_dir().glob("*.toml"))


def _plain(name: str) -> bool:
    return bool(name) and "/" not in name and "\\" not in name and not name.startswith(".") and ":" not in name


def vehicle_file(name: str, base: Path | None = None) -> Path:
    """The file of vehicle ``name``: a bundled vehicle's name, else a path (relative to ``base``)."""
    stem = name[:-5] if name.endswith(".toml") else name
    if _plain(stem) and (vehicles_dir() / f"{stem}.toml").is_file():
        return vehicles_dir() / f"{stem}.toml"
    for p in ([base / name] if base is not None else []) + [Path(name)]:
        if p.is_file():
            return p.resolve()
    raise ScenarioError(f"vehicle '{name}' not found: neither a bundled vehicle ({', '.join(bundled_vehicles())}) "
                        f"nor a file")


def cell_file(name: str, base: Path | None = None) -> Path:
    """The file of cell set ``name``: ``components/cell/NAME.toml``, else a path (relative to ``base``)."""
    stem = name[:-5] if name.endswith(".toml") else name
    d = DATA_ROOT / "components" / "cell"
    if _plain(stem) and (d / f"{stem}.toml").is_file():
        return d / f"{stem}.toml"
    for p in ([base / name] if base is not None else []) + [Path(name)]:
        if p.is_file():
            return p.resolve()
    known = sorted(p.stem for p in d.glob("*.toml"))
    raise ScenarioError(f"cell '{name}' not found: neither a bundled cell set ({', '.join(known)}) nor a file")


def _read(path: Path) -> dict:
    try:
        return tomllib.loads(path.read_text(encoding="utf-8-sig"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError, OSError) as exc:
        raise ScenarioError(f"{path}: cannot read as TOML: {exc}") from None


@dataclass
class VehicleSet:
    """A vehicle of the library: its shared quantities and its per-type component values."""
    name: str
    path: Path
    description: str
    source: str
    shared: dict[str, Any]
    components: dict[str, dict[str, Any]] = field(default_factory=dict)


def load_vehicle(name: str, base: Path | None = None) -> VehicleSet:
    """Read a vehicle file: ``[meta]``, ``[shared]`` (quantities) and optional ``[TYPE]`` tables (values of
    components of that type beyond the shared quantities, e.g. ``[driver] kp_n_per_mps``)."""
    path = vehicle_file(name, base)
    doc = _read(path)
    meta = doc.get("meta", {})
    shared = doc.get("shared")
    if not isinstance(shared, dict):
        raise ScenarioError(f"{path}: a vehicle file needs a [shared] table of quantities")
    vals = {}
    for k, v in shared.items():
        if k == "vehicle":
            raise ScenarioError(f"{path}: [shared] 'vehicle': a vehicle file cannot name another vehicle")
        vals[k] = check_value(k, v, f"{path}: [shared]")
    comps = {}
    from . import is_registered
    for k, v in doc.items():
        if k in ("meta", "shared"):
            continue
        if not isinstance(v, dict) or not is_registered(k):
            raise ScenarioError(f"{path}: table [{k}] is not a component type (types: {', '.join(sorted(IDENTITY))})")
        comps[k] = {kk: _abs_file(kk, vv, path.parent) for kk, vv in v.items()}
    vals = {k: _abs_file(k, v, path.parent) for k, v in vals.items()}
    return VehicleSet(path.stem, path, str(meta.get("description", "")), str(meta.get("source", "")), vals, comps)


def _abs_file(key: str, value: Any, base: Path) -> Any:
    if key.endswith("_file") and isinstance(value, str) and value and not Path(value).is_absolute():
        return str((base / value).resolve())
    return value


def expand_cell(name: str, base: Path | None, where: str) -> dict[str, Any]:
    """The ``cell_*`` quantities of a cell set (its ``[params]``, file paths made absolute)."""
    try:
        path = cell_file(name, base)
    except ScenarioError as exc:
        raise ScenarioError(f"{where}: {exc}") from None
    doc = _read(path)
    prm = doc.get("params")
    if not isinstance(prm, dict):
        raise ScenarioError(f"{path}: a cell file needs a [params] table")
    out = {}
    for k, v in prm.items():
        q = f"cell_{k}"
        out[q] = check_value(q, _abs_file(k, v, path.parent), f"{path}: [params]")
    return out


def expand_fuel(name: str, where: str) -> dict[str, float]:
    if name not in FUELS:
        raise ScenarioError(f"{where}: unknown fuel '{name}' (known: {', '.join(FUELS)}; or give "
                            f"fuel_lhv_j_per_g and fuel_density_kg_per_l)")
    return dict(FUELS[name])


# ------------------------------------------------------------------------------------ resolution
def _same(a: Any, b: Any) -> bool:
    if isinstance(a, str) and isinstance(b, str):
        if a == b:
            return True
        try:
            return Path(a).resolve() == Path(b).resolve()
        except OSError:
            return False
    if isinstance(a, bool) or isinstance(b, bool):
        return a is b or a == b
    if isinstance(a, (int, float)) and isinstance(b, (int, float)):
        return float(a) == float(b)
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    return a == b


same = _same        # the registry's name (shevsim.core.registry.shared_quantities)


def _owned(own: set[str], param: str, quantity: str | None) -> bool:
    return param in own or (quantity is not None and (quantity in own or
                                                      (quantity.startswith("cell_") and "cell" in own)))


@dataclass
class Resolution:
    """What the shared quantities give each component: ``params[name] = {param: value}``;
    ``values[q] = (value, origin)``; ``k_engine``; ``metrics`` options."""
    values: dict[str, tuple[Any, str]]
    params: dict[str, dict[str, Any]]
    metrics: dict[str, Any]
    vehicle: VehicleSet | None = None
    sources: dict[str, dict[str, str]] = field(default_factory=dict)   # name -> param -> where from
    explicit: set = field(default_factory=set)     # quantities the scenario declared (not the vehicle's)
    lifted: set = field(default_factory=set)       # quantities a component's value gave


def resolve(scenario, file_params) -> Resolution | None:
    """Resolve the scenario's shared quantities; ``file_params(spec)`` returns the ``[params]`` a
    component's parameter file states (``{}`` without file), ``*_file`` values absolute.  None when the
    scenario declares no shared quantities."""
    shared = getattr(scenario, "shared", None)
    if not shared and not getattr(scenario, "shared_base", None):
        return None
    where = f"{scenario.path or '<scenario>'}"
    values, explicit, veh = _collect_shared(scenario, dict(shared or {}), where)
    lifted = _lift_component_values(scenario, values, explicit, where)
    k_engine, p_max_w = _engine_scale(scenario, values, file_params)
    # per component
    params: dict[str, dict[str, Any]] = {}
    sources: dict[str, dict[str, str]] = {}
    for spec in scenario.components:
        own = set(getattr(spec, "own", ()) or ())
        inj: dict[str, Any] = {}
        src: dict[str, str] = {}
        if veh is not None:
            for k, v in veh.components.get(spec.type, {}).items():
                inj[k] = v
                src[k] = f"vehicle '{veh.name}' [{spec.type}] {k}"
        for param, q in IDENTITY.get(spec.type, {}).items():
            if q in values and not _owned(own, param, q):
                inj[param] = values[q][0]
                src[param] = f"shared {q} ({values[q][1]})"
        for param, (v, why) in _derived(spec, values, k_engine, p_max_w, file_params).items():
            if not _owned(own, param, None):
                inj[param] = v
                src[param] = why
        if not inj:
            continue
        _check_injected(spec, inj, src, file_params(spec), where)
        params[spec.name] = bms_params_for(inj) if spec.type == "bms" else inj
        sources[spec.name] = src
    metrics = {}
    if "fuel_density_kg_per_l" in values:
        metrics["fuel_density_kg_per_l"] = values["fuel_density_kg_per_l"]   # (value, origin)
    return Resolution(values, params, metrics, veh, sources, set(explicit), set(lifted))


def _collect_shared(scenario, shared: dict, where: str):
    """The shared quantities in order of precedence (a study's captured vehicle, the named vehicle, the
    scenario's ``[shared]`` table, cell and fuel expansions first): ``(values, explicit, vehicle)``."""
    origins = getattr(scenario, "shared_origins", {})
    base_dir = scenario.path.parent if scenario.path is not None else None
    values: dict[str, tuple[Any, str]] = {}
    explicit: set[str] = set()

    def put(d: dict, origin: str, is_explicit: bool, ctx: str) -> None:
        # expansions first, then the plain quantities of the same table
        for key in ("cell", "fuel"):
            if key in d:
                exp = expand_cell(d[key], base_dir, ctx) if key == "cell" else expand_fuel(d[key], ctx)
                for q, v in exp.items():
                    values[q] = (v, f"{origin} ({key} '{d[key]}')")
                    if is_explicit:
                        explicit.add(q)
        for q, v in d.items():
            if q in ("cell", "fuel", "vehicle"):
                continue
            values[q] = (v, origin)
            if is_explicit:
                explicit.add(q)

    veh = None
    base = getattr(scenario, "shared_base", None)
    if base and "vehicle" not in shared:     # captured by a study's bundle: the vehicle's values, resolved
        put(base, "the captured vehicle", False, where)
    if "vehicle" in shared:
        try:
            veh = load_vehicle(shared["vehicle"], base_dir)
        except ScenarioError as exc:
            raise ScenarioError(f"{origins.get('vehicle', where + ': [shared]')}: {exc}") from None
        put(veh.shared, f"vehicle '{shared['vehicle']}' ({veh.path.name})", False, str(veh.path))
    for key in [k for k in ("cell", "fuel") if k in shared] + [k for k in shared if k not in ("cell", "fuel", "vehicle")]:
        put({key: shared[key]}, origins.get(key, f"{where}: [shared] {key}"), True, origins.get(key, where))
    return values, explicit, veh


def _lift_component_values(scenario, values: dict, explicit: set, where: str) -> dict[str, str]:
    """Lift component-level values of identity-bound parameters (--set, overrides, set tables, overlays)
    into ``values``; a contradiction of a declared or already lifted quantity is an error."""
    lifted: dict[str, str] = {}
    for spec in scenario.components:
        ident = IDENTITY.get(spec.type, {})
        own = set(getattr(spec, "own", ()) or ())
        for param, q in ident.items():
            if param not in spec.overrides or _owned(own, param, q):
                continue
            v = spec.overrides[param]
            origin = spec.origins.get(param) or getattr(spec, "sources", {}).get(param) or \
                f"{where}: [components.{spec.name}] {param}"
            desc = f"{spec.name}.{param} = {v!r} ({origin})"
            if q in values and not _same(values[q][0], v) and (q in explicit or q in lifted):
                raise ScenarioError(f"{desc} contradicts the shared quantity {q} = {values[q][0]!r} "
                                    f"({values[q][1]}); declare it once, as shared.{q}")
            if q in values and _same(values[q][0], v):
                continue
            try:
                v = check_value(q, v, origin)
            except ScenarioError:
                pass      # the component's own check names it better (when it is built)
            values[q] = (v, desc)
            lifted[q] = desc
    return lifted


def _engine_scale(scenario, values: dict, file_params) -> tuple[float, float | None]:
    """The engine-generator's map scale ``k_engine`` (rated / map-rated power) and its scaled maximum
    electric power [W] (None without engine or with an unreadable optimal-operating-line file)."""
    eg = next((s for s in scenario.components if s.type == "engine_generator"), None)
    k_engine, p_max_w = 1.0, None
    if eg is not None:
        eg_vals = {**file_params(eg), **eg.overrides}
        from .engine_generator import EngineGeneratorParams
        d = EngineGeneratorParams()
        eg_rated = float(eg_vals.get("maps_rated_power_w", d.maps_rated_power_w))
        rated = values["engine_power_w"][0] if "engine_power_w" in values and \
            not _owned(set(eg.own), "rated_power_w", "engine_power_w") else eg_vals.get("rated_power_w", d.rated_power_w)
        k_engine = float(rated) / eg_rated
        from shevsim.powertrain.maps import load_curve_csv
        ool = eg_vals.get("ool_file", d.ool_file)
        try:
            p_max_w = float(load_curve_csv(ool, "elec_power_w", "speed_radps").x[-1]) * k_engine
        except Exception:       # the engine component's own check names a bad file when it is built
            p_max_w = None
    return k_engine, p_max_w


def _check_injected(spec, inj: dict, src: dict, fvals: dict, where: str) -> None:
    """A component-level value that contradicts an injected one (its parameter file, or an override of a
    derived parameter) is an error telling how to keep it (``own = [...]``)."""
    for param, v in inj.items():
        if param not in src or src[param].startswith("vehicle '") or param in _FOLLOWS:
            continue          # a vehicle's own value for this component type: above the file
        if param in spec.overrides and not _same(spec.overrides[param], v) and \
                param not in IDENTITY.get(spec.type, {}):
            origin = spec.origins.get(param) or getattr(spec, "sources", {}).get(param) or \
                f"{where}: [components.{spec.name}] {param}"
            raise ScenarioError(f"{spec.name}.{param} = {spec.overrides[param]!r} ({origin}) contradicts "
                                f"{src[param]} = {v!r}; to keep the component's own value list it in "
                                f"[components.{spec.name}] own = [\"{param}\"]")
        if param in fvals and param not in spec.overrides and not _same(fvals[param], v):
            raise ScenarioError(f"{spec.name}.{param} = {fvals[param]!r} ({spec.params_file}: [params] {param}) "
                                f"contradicts {src[param]} = {v!r}; remove it from the parameter file, or "
                                f"list it in [components.{spec.name}] own = [\"{param}\"]")


def _derived(spec, values, k_engine: float, p_max_w: float | None, file_params) -> dict[str, tuple[Any, str]]:
    """Parameters of ``spec`` computed from shared quantities: ``{param: (value, why)}``."""
    out: dict[str, tuple[Any, str]] = {}
    t = spec.type
    if t in ("mpc_supervisor", "rule_supervisor") and p_max_w is not None:
        out["power_gen_max_w"] = (p_max_w, f"the engine-generator's rated electrical output (end of its optimal "
                                           f"operating line x k = {k_engine:.6g})")
    if t == "mpc_supervisor" and "n_parallel" in values and "cell_capacity_ah" in values:
        cap = values["n_parallel"][0] * values["cell_capacity_ah"][0]
        out["capacity_ah"] = (float(cap), f"shared n_parallel x cell_capacity_ah "
                                          f"({values['n_parallel'][0]} x {values['cell_capacity_ah'][0]})")
    if t == "mpc_supervisor" and k_engine != 1.0:
        vals = {**file_params(spec), **spec.overrides}
        if not vals.get("fuel_curve_w"):
            from shevsim.supervisor.fuel_curve import SqrtFuelCurve
            from shevsim.components.supervisors import DEFAULT_FUEL_CURVE
            fc = SqrtFuelCurve.from_csv(vals.get("fuel_curve_file") or DEFAULT_FUEL_CURVE)
            why = f"fuel curve x k = {k_engine:.6g} (engine-generator sized by rating)"
            out["fuel_curve_w"] = ([float(x) * k_engine for x in fc.power_w], why)
            out["fuel_rate_gps"] = ([float(x) * k_engine for x in fc.fuel_rate_gps], why)
    if t == "bms" and "cell_r2_scale" in values and values["cell_r2_scale"][0] == 0.0:
        out["v2_model"] = ("none", "shared cell_r2_scale = 0 (a cell without second RC branch)")
    return out


def bms_params_for(inj: dict[str, Any]) -> dict[str, Any]:
    """A BMS cannot scale a branch to 0: with ``r2_scale = 0`` the branch is off (``v2_model``), factor 1."""
    if inj.get("r2_scale") == 0.0:
        inj = {**inj, "r2_scale": 1.0}
    return inj
