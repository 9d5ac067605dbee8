"""thermal.py - radial heat conduction in a cylindrical cell (seed Ch. II-III).

Physics: 1-D radial conduction with uniform volumetric heat generation and a
convective side surface (seed 2.1-2.2)::

    rho c_p dT/dt = k_t (d2T/dr2 + (1/r) dT/dr) + Q / V_b,
    dT/dr(0) = 0,   -k_t dT/dr(R) = h (T(R) - T_amb).

Three models of it live here:

* :func:`two_state_matrices` / :class:`TwoStateThermal` - the polynomial-profile
  two-state model of the seed (2.15-2.25): states ``x = [T_mean_c, gamma_c_per_m]``
  (volume-averaged temperature, volume-averaged radial gradient), inputs
  ``u = [Q_w, T_amb_c]``, outputs ``y = [T_core_c, T_surface_c]``.  It conserves
  energy exactly: ``rho c_p V dT_mean/dt = Q - h 2 pi R L (T_s - T_amb)``.
* :class:`FDThermal` - an N-node radial discretisation (default 30 nodes) used as
  the higher-fidelity plant and as the verification reference.  The default
  scheme is the conservative control-volume form (``scheme="fv"``); the seed's
  node-based finite differences (2.8-2.12, with the printed typos corrected:
  2.8b's centre coefficient is -2 and the last row of 2.12a carries xi_3, not
  xi_1) are available as ``scheme="fd"``.
* :func:`analytical_tf` - the exact transfer functions from the Laplace-domain
  solution.  With zeta^2 = s/alpha the homogeneous solution is the *modified*
  Bessel function I0(zeta r) (the seed's 2.4-2.7 print J0, which gives a static
  gain of the wrong sign).

Units: SI, temperatures in degC (the equations are linear in T, so any offset works),
heat generation ``q_w`` in W per cell (positive = heat released in the cell),
convection coefficient ``h_w_m2k`` in W/m^2/K on the cylindrical side surface.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
from scipy.linalg import expm

from shevsim.core.errors import ScenarioError, SimulationError

__all__ = [
    "ThermalParams",
    "two_state_matrices",
    "TwoStateThermal",
    "FDThermal",
    "fd_matrices",
    "analytical_tf",
    "state_space_tf",
    "steady_state",
    "profile_from_state",
]


@dataclass(frozen=True)
class ThermalParams:
    """Thermal parameters of one cylindrical cell.

    Defaults are the A123 26650 LFP cell of seed Table 3.1 (identified values);
    :meth:`table_2_1` gives the cell of seed Table 2.1 (from Muratori et al.).
    The cell length is not in Table 3.1; 65.15 mm (Table 2.1) reproduces its
    volume V_b = 3.4219e-5 m^3.

    Parameters
    ----------
    radius_m : float
        Cell radius R [m].
    length_m : float
        Cell length L [m]; only the side surface 2 pi R L convects.
    density_kg_m3 : float
        Volume-averaged density rho [kg/m^3].
    cp_j_kgk : float
        Specific heat capacity c_p [J/kg/K].
    kt_w_mk : float
        Radial thermal conductivity k_t [W/m/K].
    """

    radius_m: float = 12.93e-3
    length_m: float = 65.15e-3
    density_kg_m3: float = 2047.0
    cp_j_kgk: float = 1109.2
    kt_w_mk: float = 0.610

    def __post_init__(self) -> None:
        for f in dataclasses.fields(ThermalParams):      # its own fields (a subclass may add others)
            v = getattr(self, f.name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0.0):
                raise ScenarioError(f"ThermalParams: field '{f.name}' must be a finite positive number, got {v!r}")

    def thermal_params(self) -> "ThermalParams":
        """The cell's thermal parameters as a plain :class:`ThermalParams` (of a subclass's instance too)."""
        return ThermalParams(**{f.name: getattr(self, f.name) for f in dataclasses.fields(ThermalParams)})

    @classmethod
    def table_2_1(cls) -> "ThermalParams":
        """Cell of seed Table 2.1 (rho 1824, c_p 825, k_t 0.488; R 12.93 mm, L 65.15 mm)."""
        return cls(radius_m=12.93e-3, length_m=65.15e-3, density_kg_m3=1824.0, cp_j_kgk=825.0, kt_w_mk=0.488)

    @classmethod
    def table_3_1(cls) -> "ThermalParams":
        """Cell of seed Table 3.1 (the defaults)."""
        return cls()

    @property
    def volume_m3(self) -> float:
        """Cell volume V_b = pi R^2 L [m^3]."""
        return math.pi * self.radius_m ** 2 * self.length_m

    @property
    def surface_m2(self) -> float:
        """Convective (side) surface 2 pi R L [m^2]."""
        return 2.0 * math.pi * self.radius_m * self.length_m

    @property
    def alpha_m2_s(self) -> float:
        """Thermal diffusivity alpha = k_t / (rho c_p) [m^2/s]."""
        return self.kt_w_mk / (self.density_kg_m3 * self.cp_j_kgk)

    @property
    def heat_capacity_j_k(self) -> float:
        """Lumped heat capacity rho c_p V_b [J/K]."""
        return self.density_kg_m3 * self.cp_j_kgk * self.volume_m3


def _check_h(h_w_m2k: float, where: str) -> float:
    h = float(h_w_m2k)
    if not (math.isfinite(h) and h >= 0.0):
        raise SimulationError(f"{where}: convection coefficient h_w_m2k must be finite and >= 0, got {h_w_m2k!r}")
    return h


def _check_dt(dt: float, where: str) -> float:
    d = float(dt)
    if not (math.isfinite(d) and d > 0.0):
        raise SimulationError(f"{where}: time step dt must be finite and > 0 s, got {dt!r}")
    return d


from numba import njit as _njit


# ---------------------------------------------------------------------------------------------
# the two-state model written ONCE (numba-compatible pure functions, compiled; ``f.py_func`` is the
# reference): the plant (battery component), the BMS estimators (shevsim.bms.thermal_estimators) and
# the calibration all call these.
# ---------------------------------------------------------------------------------------------
@_njit(cache=True)
def two_state_a(h, R, k, alpha):
    """``(a00, a01, a10, a11)`` of the continuous two-state A(h) (seed 2.24 / 3.3); the one place the
    matrix is written.  ``B = [[bq, -a00], [0, -a10]]`` with ``bq = alpha / (k V)`` (uniform T = T_amb is an
    equilibrium), so A and B both come from here."""
    den = 24.0 * k + R * h
    return (-48.0 * alpha * h / (R * den), -15.0 * alpha * h / den,
            -320.0 * alpha * h / (R * R * den), -120.0 * alpha * (4.0 * k + R * h) / (R * R * den))


@_njit(cache=True)
def two_state_out(h, R, k):
    """Surface and core output rows ``(cs0, cs1, ds, cc0, cc1, dc)``: ``T_s = cs x + ds T_amb``,
    ``T_c = cc x + dc T_amb`` (seed 2.25)."""
    den = 24.0 * k + R * h
    return (24.0 * k / den, 7.5 * R * k / den, R * h / den,
            (24.0 * k - 3.0 * R * h) / den, -(120.0 * R * k + 15.0 * R * R * h) / (8.0 * den), 4.0 * R * h / den)


@_njit(cache=True)
def two_state_dout(h, R, k, two):
    """Analytic h-derivatives of ``(cs0, cs1, ds)``.  ``two`` = 2.0: ``den ** 2`` through libm ``pow``
    (as CPython's ``**``) with a run-time exponent, so that LLVM cannot turn it into a product."""
    den2 = math.pow(24.0 * k + R * h, two)
    return (-24.0 * k * R / den2, -7.5 * R * R * k / den2, 24.0 * k * R / den2)


@_njit(cache=True)
def two_state_ad_bd(h, R, k, alpha, bq, dt, euler):
    """``(a00, a01, a10, a11, b00, b01, b10, b11)`` of the discretised model at ``h``: the seed's Euler
    (``euler``: ``I + A dt``, ``B dt``) or the exact ZOH (closed-form 2x2 matrix exponential)."""
    a00, a01, a10, a11 = two_state_a(h, R, k, alpha)
    if euler:
        return (1.0 + a00 * dt, a01 * dt, a10 * dt, 1.0 + a11 * dt, bq * dt, -a00 * dt, 0.0, -a10 * dt)
    tr = a00 + a11
    det = a00 * a11 - a01 * a10
    disc = 0.25 * tr * tr - det
    sq = math.sqrt(disc if disc > 0.0 else 0.0)
    l1 = 0.5 * tr + sq
    l2 = 0.5 * tr - sq
    l1dt = l1 * dt
    l2dt = l2 * dt
    e1 = math.exp(l1dt)
    e2 = math.exp(l2dt)
    f1 = (math.expm1(l1dt) / l1) if abs(l1dt) > 1e-12 else dt * (1.0 + 0.5 * l1dt)
    f2 = (math.expm1(l2dt) / l2) if abs(l2dt) > 1e-12 else dt * (1.0 + 0.5 * l2dt)
    dl = l1 - l2
    if dl > 1e-12 * (abs(l1) + abs(l2) + 1e-300):
        c1 = (e1 - e2) / dl
        c0 = (l1 * e2 - l2 * e1) / dl
        d1 = (f1 - f2) / dl
        d0 = (l1 * f2 - l2 * f1) / dl
    else:  # repeated eigenvalue (does not occur for h >= 0; kept for safety)
        c1 = dt * e1
        c0 = e1 - l1 * c1
        d1 = (dt * e1 - f1) / l1 if l1 != 0.0 else 0.5 * dt * dt
        d0 = f1 - l1 * d1
    # Ad = c0 I + c1 A;  G = d0 I + d1 A;  Bd = G B with B = [[bq, -a00], [0, -a10]]
    g00 = d0 + d1 * a00
    g01 = d1 * a01
    g10 = d1 * a10
    g11 = d0 + d1 * a11
    return (c0 + c1 * a00, c1 * a01, c1 * a10, c0 + c1 * a11,
            g00 * bq, -(g00 * a00 + g01 * a10),
            g10 * bq, -(g10 * a00 + g11 * a10))


@_njit(cache=True)
def two_state_d_ad_bd(h, R, k, alpha, bq, dt, euler):
    """Central-difference h-derivative of :func:`two_state_ad_bd` (step ``1e-5 (|h| + 1)``, one-sided at 0)."""
    dh = 1e-5 * (abs(h) + 1.0)
    hp = two_state_ad_bd(h + dh, R, k, alpha, bq, dt, euler)
    hm = two_state_ad_bd(h - dh if h - dh > 0.0 else 0.0, R, k, alpha, bq, dt, euler)
    span = dh + (dh if h - dh > 0.0 else h)
    return ((hp[0] - hm[0]) / span, (hp[1] - hm[1]) / span, (hp[2] - hm[2]) / span, (hp[3] - hm[3]) / span,
            (hp[4] - hm[4]) / span, (hp[5] - hm[5]) / span, (hp[6] - hm[6]) / span, (hp[7] - hm[7]) / span)


def _two_state_abcd(radius_m, length_m, density_kg_m3, cp_j_kgk, kt_w_mk, h_w_m2k):
    """The 16 entries of the two-state model's (A, B, C, D), row-major (seed 2.24-2.25 / 3.3), from
    :func:`two_state_a` and :func:`two_state_out` (``B = [[bq, -a00], [0, -a10]]``, ``bq = alpha / (k V)``)."""
    R = radius_m
    k = kt_w_mk
    alpha = kt_w_mk / (density_kg_m3 * cp_j_kgk)
    bq = alpha / (k * (math.pi * R ** 2 * length_m))
    a00, a01, a10, a11 = two_state_a(h_w_m2k, R, k, alpha)
    cs0, cs1, ds, cc0, cc1, dc = two_state_out(h_w_m2k, R, k)
    return (a00, a01, a10, a11, bq, -a00, 0.0, -a10, cc0, cc1, cs0, cs1, 0.0, dc, 0.0, ds)


def two_state_matrices(p: ThermalParams, h_w_m2k: float):
    """Continuous-time matrices of the two-state model (seed 2.24-2.25 / 3.3).

    Parameters
    ----------
    p : ThermalParams
        Cell parameters.
    h_w_m2k : float
        Convection coefficient [W/m^2/K], >= 0.

    Returns
    -------
    A, B, C, D : numpy.ndarray
        ``dx/dt = A x + B u``, ``y = C x + D u`` with ``x = [T_mean_c, gamma_c_per_m]``,
        ``u = [q_w, t_amb_c]``, ``y = [t_core_c, t_surface_c]``.
    """
    h = _check_h(h_w_m2k, "two_state_matrices")
    e = _two_state_abcd(p.radius_m, p.length_m, p.density_kg_m3, p.cp_j_kgk, p.kt_w_mk, h)
    return (np.array(e[0:4]).reshape(2, 2), np.array(e[4:8]).reshape(2, 2),
            np.array(e[8:12]).reshape(2, 2), np.array(e[12:16]).reshape(2, 2))


def _two_state_coeffs(radius_m, length_m, density_kg_m3, cp_j_kgk, kt_w_mk, h_w_m2k, dt):
    """Exact ZOH and output coefficients of the two-state model, 14 floats:
    ``(a00, a01, a10, a11, b00, b01, b10, b11, c00, c01, d0, c10, c11, d1)`` with
    ``x+ = Ad x + Bd [q, T_amb]``, ``[T_core, T_surface] = C x + D [q, T_amb]`` (:func:`two_state_ad_bd`,
    the closed-form 2x2 matrix exponential, and :func:`two_state_out`)."""
    R = radius_m
    k = kt_w_mk
    alpha = kt_w_mk / (density_kg_m3 * cp_j_kgk)
    bq = alpha / (k * (math.pi * R ** 2 * length_m))
    ad = two_state_ad_bd(h_w_m2k, R, k, alpha, bq, dt, False)
    cs0, cs1, ds, cc0, cc1, dc = two_state_out(h_w_m2k, R, k)
    return (ad[0], ad[1], ad[2], ad[3], ad[4], ad[5], ad[6], ad[7], cc0, cc1, dc, cs0, cs1, ds)


_two_state_abcd = _njit(cache=True, error_model="numpy")(_two_state_abcd)
two_state_coeffs = _njit(cache=True, error_model="numpy")(_two_state_coeffs)


def zoh(A: np.ndarray, B: np.ndarray, dt: float):
    """Exact zero-order-hold discretisation (works for singular A)."""
    n, m = B.shape
    M = np.zeros((n + m, n + m))
    M[:n, :n] = A
    M[:n, n:] = B
    E = expm(M * dt)
    return E[:n, :n].copy(), E[:n, n:].copy()


def steady_state(p: ThermalParams, q_w: float, t_amb_c: float, h_w_m2k: float):
    """Exact steady state of the PDE for constant inputs (parabolic profile).

    ``T(r) = T_s + Q (R^2 - r^2) / (4 k_t V_b)``, ``T_s = T_amb + Q R / (2 h V_b)``.

    Returns
    -------
    dict with ``t_core_c``, ``t_surface_c``, ``t_mean_c``, ``gamma_c_per_m``.
    """
    h = _check_h(h_w_m2k, "steady_state")
    if h == 0.0:
        raise SimulationError("steady_state: no steady state with h_w_m2k = 0 and heat input")
    R, k, V = p.radius_m, p.kt_w_mk, p.volume_m3
    ts = t_amb_c + q_w * R / (2.0 * h * V)
    c = q_w / (4.0 * k * V)  # T = ts + c (R^2 - r^2)
    return {
        "t_core_c": ts + c * R * R,
        "t_surface_c": ts,
        "t_mean_c": ts + c * R * R / 2.0,  # (2/R^2) int r c (R^2 - r^2) dr = c R^2 / 2
        "gamma_c_per_m": -4.0 * c * R / 3.0,  # (2/R^2) int r (-2 c r) dr = -4 c R / 3
    }


def profile_from_state(p: ThermalParams, x, t_surface_c: float, r_m):
    """Radial temperature profile of the two-state model (seed 2.20) at radii ``r_m`` [m]."""
    R = p.radius_m
    tm, g = float(x[0]), float(x[1])
    a = 4.0 * t_surface_c - 3.0 * tm - 15.0 * R / 8.0 * g
    b = -18.0 * t_surface_c + 18.0 * tm + 15.0 * R / 2.0 * g
    d = 15.0 * t_surface_c - 15.0 * tm - 45.0 * R / 8.0 * g
    z = (np.asarray(r_m, dtype=float) / R) ** 2
    return a + b * z + d * z * z


class TwoStateThermal:
    """Two-state (T_mean, gamma) thermal model of one cell with exact ZOH stepping.

    The state is a tuple ``(t_mean_c, gamma_c_per_m)``.  Discretisations are cached
    per ``(h_w_m2k, dt)`` (bounded cache), so the hot path is a handful of float
    multiplications.

    Parameters
    ----------
    params : ThermalParams
        Cell parameters (default: seed Table 3.1).

    Notes
    -----
    Inputs: ``q_w`` heat generated in the cell [W] (+ = heating), ``t_amb_c`` coolant/ambient
    temperature [degC], ``h_w_m2k`` convection coefficient [W/m^2/K].  Outputs: core and
    surface temperature [degC].
    """

    _CACHE_MAX = 256

    def __init__(self, params: ThermalParams | None = None):
        self.params = params if params is not None else ThermalParams()
        self._disc: dict = {}
        self._out: dict = {}

    # -- state helpers -------------------------------------------------------------
    @staticmethod
    def initial_state(t_uniform_c: float):
        """State of a cell at a uniform temperature [degC]."""
        return (float(t_uniform_c), 0.0)

    @staticmethod
    def mean_temperature(x) -> float:
        """Volume-averaged temperature [degC] of state ``x``."""
        return float(x[0])

    def matrices(self, h_w_m2k: float):
        """Continuous-time (A, B, C, D); see :func:`two_state_matrices`."""
        return two_state_matrices(self.params, h_w_m2k)

    def discretise(self, h_w_m2k: float, dt: float):
        """Exact ZOH (Ad, Bd) as 2x2 numpy arrays."""
        A, B, _, _ = two_state_matrices(self.params, h_w_m2k)
        return zoh(A, B, _check_dt(dt, "TwoStateThermal.discretise"))

    def _all_coeffs(self, h: float, dt: float):
        key = (h, dt)
        c = self._disc.get(key)
        if c is None:
            _check_h(h, "TwoStateThermal.step")
            _check_dt(dt, "TwoStateThermal.step")
            p = self.params
            c = two_state_coeffs(p.radius_m, p.length_m, p.density_kg_m3, p.cp_j_kgk, p.kt_w_mk, float(h), float(dt))
            if len(self._disc) >= self._CACHE_MAX:
                self._disc.clear()
            self._disc[key] = c
        return c

    def _coeffs(self, h: float, dt: float):
        """ZOH coefficients ``(a00, a01, a10, a11, b00, b01, b10, b11)`` (:func:`two_state_coeffs`)."""
        return self._all_coeffs(h, dt)[:8]

    def _ocoeffs(self, h: float):
        """Output coefficients ``(c00, c01, d0, c10, c11, d1)`` (:func:`two_state_coeffs`)."""
        return self._all_coeffs(h, 1.0)[8:]

    # -- hot path ------------------------------------------------------------------
    def step(self, x, q_w: float, t_amb_c: float, h_w_m2k: float, dt: float):
        """Advance the state by ``dt`` [s] with inputs held (exact for piecewise-constant inputs).

        Returns the new state tuple ``(t_mean_c, gamma_c_per_m)``.
        """
        a00, a01, a10, a11, b00, b01, b10, b11 = self._coeffs(h_w_m2k, dt)
        x0 = x[0]
        x1 = x[1]
        return (a00 * x0 + a01 * x1 + b00 * q_w + b01 * t_amb_c,
                a10 * x0 + a11 * x1 + b10 * q_w + b11 * t_amb_c)

    def outputs(self, x, q_w: float, t_amb_c: float, h_w_m2k: float):
        """``(t_core_c, t_surface_c)`` of state ``x`` (q_w has no direct feedthrough)."""
        c00, c01, d0, c10, c11, d1 = self._ocoeffs(h_w_m2k)
        x0 = x[0]
        x1 = x[1]
        return (c00 * x0 + c01 * x1 + d0 * t_amb_c, c10 * x0 + c11 * x1 + d1 * t_amb_c)

    def profile(self, x, t_amb_c: float, h_w_m2k: float, r_m):
        """Radial profile [degC] at radii ``r_m`` (seed 2.20)."""
        ts = self.outputs(x, 0.0, t_amb_c, h_w_m2k)[1]
        return profile_from_state(self.params, x, ts, r_m)


# ---------------------------------------------------------------------------------
# N-node radial discretisation
# ---------------------------------------------------------------------------------
def fd_matrices(p: ThermalParams, h_w_m2k: float, n_nodes: int = 30, scheme: str = "fv"):
    """State-space matrices of an ``n_nodes`` radial discretisation.

    Parameters
    ----------
    p : ThermalParams
    h_w_m2k : float
        Convection coefficient [W/m^2/K].
    n_nodes : int
        ``"fv"``: number of control volumes (states = cell-centre temperatures).
        ``"fd"``: number of intervals N of the seed's scheme (states T_1..T_{N-1}).
    scheme : {"fv", "fd"}
        ``"fv"`` conservative control-volume scheme (energy-exact, steady state exact
        for the parabolic profile); core temperature by quadratic extrapolation
        ``(9 T_0 - T_1)/8``, surface temperature through the half-cell resistance.
        ``"fd"`` the seed's 2.9-2.12 (corrected), ``T_0 = T_1`` and
        ``T_N = (k T_{N-1} + h dr T_amb)/(k + h dr)``.

    Returns
    -------
    A, B, C, D, w : numpy.ndarray
        Matrices with inputs ``[q_w, t_amb_c]``, outputs ``[t_core_c, t_surface_c]``;
        ``w`` are volume weights (``T_mean = w @ x``).
    """
    h = _check_h(h_w_m2k, "fd_matrices")
    N = int(n_nodes)
    if N < 3:
        raise SimulationError(f"fd_matrices: n_nodes must be >= 3, got {n_nodes!r}")
    R, k, a, V = p.radius_m, p.kt_w_mk, p.alpha_m2_s, p.volume_m3
    rc = p.density_kg_m3 * p.cp_j_kgk
    dr = R / N
    if scheme == "fv":
        faces = dr * np.arange(N + 1)              # r_{j-1/2}, j = 0..N
        area = faces[1:] ** 2 - faces[:-1] ** 2    # annulus area / pi
        cap = rc * area                            # per pi per unit length
        A = np.zeros((N, N))
        B = np.zeros((N, 2))
        for j in range(N - 1):
            g = k * 2.0 * faces[j + 1] / dr        # conductance / pi per unit length
            A[j, j] -= g / cap[j]
            A[j, j + 1] += g / cap[j]
            A[j + 1, j + 1] -= g / cap[j + 1]
            A[j + 1, j] += g / cap[j + 1]
        # outer face: half-cell conduction in series with convection
        gs = 2.0 * R / (dr / (2.0 * k) + (1.0 / h if h > 0 else math.inf))
        A[N - 1, N - 1] -= gs / cap[N - 1]
        B[N - 1, 1] = gs / cap[N - 1]
        B[:, 0] = 1.0 / (rc * V)                   # uniform heat generation
        C = np.zeros((2, N))
        D = np.zeros((2, 2))
        C[0, 0], C[0, 1] = 9.0 / 8.0, -1.0 / 8.0
        kk = 2.0 * k / dr
        C[1, N - 1] = kk / (kk + h)
        D[1, 1] = h / (kk + h)
        w = area / R ** 2
        return A, B, C, D, w
    if scheme == "fd":
        n = N - 1                                   # states T_1..T_{N-1}
        x1 = a / dr ** 2
        x2 = a / (k * V)
        x3 = k / (k + h * dr)
        x4 = h * dr / (k + h * dr)
        A = np.zeros((n, n))
        B = np.zeros((n, 2))
        for idx in range(n):
            i = idx + 1
            lo, mid, hi = (2 * i - 1) / (2 * i), -2.0, (2 * i + 1) / (2 * i)
            A[idx, idx] += mid * x1
            if i == 1:
                A[idx, idx] += lo * x1              # T_0 = T_1
            else:
                A[idx, idx - 1] += lo * x1
            if i == N - 1:
                A[idx, idx] += hi * x1 * x3         # T_N = x3 T_{N-1} + x4 T_amb
                B[idx, 1] = hi * x1 * x4
            else:
                A[idx, idx + 1] += hi * x1
        B[:, 0] = x2
        C = np.zeros((2, n))
        D = np.zeros((2, 2))
        C[0, 0] = 1.0
        C[1, n - 1] = x3
        D[1, 1] = x4
        # trapezoidal volume weights on nodes 0..N with T_0 = T_1, T_N from the BC (approximate)
        r = dr * np.arange(N + 1)
        wn = np.zeros(N + 1)
        wn[1:] += r[1:] * dr
        wn[:-1] += r[:-1] * dr
        wn *= 1.0 / R ** 2                          # (2/R^2) * (dr/2) * (r_i + r_{i+1})
        w = wn[1:N].copy()
        w[0] += wn[0]
        w[-1] += wn[N] * x3
        return A, B, C, D, w
    raise SimulationError(f"fd_matrices: unknown scheme {scheme!r} (use 'fv' or 'fd')")


class FDThermal:
    """Higher-fidelity radial thermal model (N nodes) with the :class:`TwoStateThermal` API.

    The state is a numpy array of node temperatures [degC].  Stepping is exact ZOH
    (matrix exponential cached per ``(h, dt)``).

    Parameters
    ----------
    params : ThermalParams
    n_nodes : int
        Number of radial nodes (default 30).
    scheme : {"fv", "fd"}
        See :func:`fd_matrices`.
    """

    _CACHE_MAX = 64

    def __init__(self, params: ThermalParams | None = None, n_nodes: int = 30, scheme: str = "fv"):
        self.params = params if params is not None else ThermalParams()
        self.n_nodes = int(n_nodes)
        self.scheme = scheme
        self._w = fd_matrices(self.params, 1.0, self.n_nodes, scheme)[4]  # validates early; volume weights
        self._disc: dict = {}
        self._out: dict = {}

    @property
    def n_states(self) -> int:
        return self.n_nodes if self.scheme == "fv" else self.n_nodes - 1

    def initial_state(self, t_uniform_c: float) -> np.ndarray:
        """Uniform-temperature state [degC]."""
        return np.full(self.n_states, float(t_uniform_c))

    def matrices(self, h_w_m2k: float):
        """Continuous-time (A, B, C, D) of the discretisation."""
        return fd_matrices(self.params, h_w_m2k, self.n_nodes, self.scheme)[:4]

    def mean_temperature(self, x) -> float:
        """Volume-averaged temperature [degC] (weights from the discretisation)."""
        if self.scheme != "fv":
            raise SimulationError("FDThermal.mean_temperature: only defined exactly for scheme='fv'")
        return float(self._w @ np.asarray(x))

    def _coeffs(self, h: float, dt: float):
        key = (h, dt)
        c = self._disc.get(key)
        if c is None:
            _check_h(h, "FDThermal.step")
            _check_dt(dt, "FDThermal.step")
            A, B = fd_matrices(self.params, h, self.n_nodes, self.scheme)[:2]
            Ad, Bd = zoh(A, B, dt)
            c = (Ad, np.ascontiguousarray(Bd[:, 0]), np.ascontiguousarray(Bd[:, 1]))
            if len(self._disc) >= self._CACHE_MAX:
                self._disc.clear()
            self._disc[key] = c
        return c

    def _ocoeffs(self, h: float):
        c = self._out.get(h)
        if c is None:
            _, _, C, D, _ = fd_matrices(self.params, h, self.n_nodes, self.scheme)
            c = (C[0].copy(), C[1].copy(), float(D[0, 1]), float(D[1, 1]))
            self._out[h] = c
        return c

    def step(self, x, q_w: float, t_amb_c: float, h_w_m2k: float, dt: float) -> np.ndarray:
        """Advance the node temperatures by ``dt`` [s]; returns a new array."""
        Ad, b0, b1 = self._coeffs(h_w_m2k, dt)
        return Ad @ x + b0 * q_w + b1 * t_amb_c

    def outputs(self, x, q_w: float, t_amb_c: float, h_w_m2k: float):
        """``(t_core_c, t_surface_c)``."""
        c0, c1, d0, d1 = self._ocoeffs(h_w_m2k)
        return (float(c0 @ x) + d0 * t_amb_c, float(c1 @ x) + d1 * t_amb_c)


# ---------------------------------------------------------------------------------
# Frequency responses
# ---------------------------------------------------------------------------------
def state_space_tf(A, B, C, D, s) -> np.ndarray:
    """``H(s) = C (sI - A)^-1 B + D`` for each complex ``s``; shape (len(s), ny, nu)."""
    s = np.atleast_1d(np.asarray(s, dtype=complex))
    n = A.shape[0]
    I = np.eye(n)
    out = np.empty((s.size, C.shape[0], B.shape[1]), dtype=complex)
    for i, si in enumerate(s):
        out[i] = C @ np.linalg.solve(si * I - A, B) + D
    return out


def analytical_tf(p: ThermalParams, h_w_m2k: float, s) -> np.ndarray:
    """Exact transfer functions of the PDE (Laplace domain, zero initial state).

    Derivation: with ``zeta = sqrt(s/alpha)``, (2.3a) reads
    ``Theta'' + Theta'/r - zeta^2 Theta = -Q/(k V)``, so
    ``Theta = C I0(zeta r) + Theta_p`` with ``Theta_p = alpha Q / (k V s)``;
    (2.3c) gives ``C = -(h/k)(Theta_p - Theta_inf) / (zeta I1(zeta R) + (h/k) I0(zeta R))``.
    Hence, with ``den = zeta I1 + (h/k) I0`` (arguments ``zeta R``)::

        H11 = T_c/Q     = alpha/(k V s) * (zeta I1 + (h/k)(I0 - 1)) / den
        H12 = T_c/T_inf = (h/k) / den
        H21 = T_s/Q     = alpha/(k V s) * zeta I1 / den
        H22 = T_s/T_inf = (h/k) I0 / den

    Static gains (s -> 0): H21 -> R/(2 h V), H11 -> R/(2 h V) + R^2/(4 k V), H12 = H22 -> 1,
    equal to the parabolic steady state.  Exponentially scaled Bessel functions are
    used so that high frequencies do not overflow.

    Returns
    -------
    numpy.ndarray, complex, shape (len(s), 2, 2): ``[[H11, H12], [H21, H22]]``.
    """
    from scipy.special import ive

    h = _check_h(h_w_m2k, "analytical_tf")
    s = np.atleast_1d(np.asarray(s, dtype=complex))
    R, k, a, V = p.radius_m, p.kt_w_mk, p.alpha_m2_s, p.volume_m3
    zeta = np.sqrt(s / a)
    z = zeta * R
    i0 = ive(0, z)             # I0(z) exp(-|Re z|)
    i1 = ive(1, z)
    sc = np.exp(-np.abs(z.real))
    hk = h / k
    den = zeta * i1 + hk * i0  # scaled by exp(-|Re z|)
    with np.errstate(divide="ignore", invalid="ignore"):
        g = a / (k * V * s)
    out = np.empty((s.size, 2, 2), dtype=complex)
    with np.errstate(divide="ignore", invalid="ignore"):
        out[:, 0, 0] = g * (zeta * i1 + hk * (i0 - sc)) / den
        out[:, 0, 1] = hk * sc / den
        out[:, 1, 0] = g * zeta * i1 / den
        out[:, 1, 1] = hk * i0 / den
    # small |z| (including s = 0): series with the 1/s cancelled analytically
    small = np.abs(z) < 1e-3
    if np.any(small):
        z2 = s[small] * R * R / a                  # (zeta R)^2
        i0m1 = z2 / 4.0 + z2 * z2 / 64.0          # I0 - 1
        zi1 = (z2 / 2.0 + z2 * z2 / 16.0) / R     # zeta I1(zeta R)
        dens = zi1 + hk * (1.0 + i0m1)
        g_zi1 = R / (k * V) * (0.5 + z2 / 16.0)           # alpha/(k V s) * zeta I1
        g_i0m1 = R * R / (k * V) * (0.25 + z2 / 64.0)     # alpha/(k V s) * (I0 - 1)
        out[small, 0, 0] = (g_zi1 + hk * g_i0m1) / dens
        out[small, 0, 1] = hk / dens
        out[small, 1, 0] = g_zi1 / dens
        out[small, 1, 1] = hk * (1.0 + i0m1) / dens
    return out
