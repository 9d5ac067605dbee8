"""thermal_estimators.py - core-temperature and convection-coefficient estimators (seed Ch. III).

All three filters use the two-state cell model (seed 3.1-3.3: states T_mean, gamma; inputs
Q [W/cell], T_amb [degC]; measured output T_surface [degC]) discretised with the sample time
``dt_s``:

* :class:`ThermalKF` - linear Kalman filter with a given convection coefficient h.
* :class:`ThermalDKF` - dual Kalman filter (3.10-3.15): a KF for (T_mean, gamma) with the current
  h estimate and a scalar EKF for h (random walk).  The parameter filter's output Jacobian
  ``C^theta = dy/dh`` is the *total* derivative, including the recursively propagated
  sensitivity of the state prediction to h (Wan & Nelson / Plett), as 3.15c's ``d/d theta`` implies;
  ``total_derivative=False`` uses the partial derivative only.
* :class:`ThermalJEKF` - joint EKF (3.16-3.20) on the augmented state (T_mean, gamma, h).  The
  output Jacobian is evaluated at the predicted state and the current ambient temperature
  (the seed's 3.20b writes x_{k-1}^+ and u_{k-1}, which is the same point up to one step).

Default tunings are seed Table 3.2 (beta_1 = 5e-4, beta_2 = 7e-3 (DKF) / 6e-3 (JEKF),
sigma = 0.05 degC, P(0) = diag(1, 1[, 0.05]), S(0) = 0.05).  The seed's units are ours
(degC, K/m, W/m^2/K, s); its sample time is not printed, 1 s is assumed, so the tunings are
per 1-s step.  h estimates are clipped to [h_min, h_max] (default 0.5-1000 W/m^2/K).

Per-step API: ``update(t_surface_meas_c, t_amb_c, q_w) -> ThermalEstimate``: the call for sample k
first predicts from sample k-1 with the inputs of sample k-1 (3.12a), then corrects with the
measurement of sample k.  The first call only corrects the initial state.

Discretisation: ``"zoh"`` (exact, closed-form 2x2 matrix exponential, default) or ``"euler"``
(the seed's A_bar = I + A dt, B_bar = B dt).

One source: the model (:func:`two_state_a` - the one place A(h), hence B, is written -,
:func:`two_state_ad_bd`, :func:`two_state_out`, ...) and the three filter steps (:func:`kf_step`,
:func:`dkf_step`, :func:`jekf_step`) are pure numba-compatible functions; each is compiled from its
source, and ``f.py_func`` is the same source run by Python (``compiled=False``).  The filter classes
only hold the state array and the constants and call the step.

The seed Table 3.3 study that runs these filters on simulated data is :mod:`shevsim.studies.thermal_estimators`.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from shevsim.battery.thermal import (ThermalParams, two_state_a, two_state_ad_bd, two_state_d_ad_bd,  # noqa: F401
                                     two_state_dout, two_state_out)  # the one two-state model
from shevsim.core.errors import SimulationError
from shevsim.core.lookup import HAVE_NUMBA, njit, py_func

__all__ = ["ThermalEstimate", "ThermalKF", "ThermalDKF", "ThermalJEKF", "TwoStateDiscretiser", "tuning",
           "two_state_a", "two_state_ad_bd",
           "two_state_d_ad_bd", "two_state_out", "two_state_dout", "kf_step", "dkf_step", "jekf_step"]


def tuning(table: str = "3.2", kind: str = "dkf", dt_s: float = 1.0, dt_ref_s: float = 1.0) -> dict:
    """Seed tunings as keyword arguments for the filter constructors.

    ``table="3.2"`` (Ch. III experiments: sigma 0.05 degC, beta_1 5e-4, beta_2 7e-3 (DKF) / 6e-3 (JEKF),
    P(0) diag(1, 1[, 0.05]), S(0) 0.05) or ``"5.4"`` (Ch. V SHEV simulation, thermal DKF:
    Sigma_w diag(2.5e-7, 2.5e-7), Sigma_v 2.5e-4, Sigma_r 9e-4, P(0) diag(1, 1), S(0) 1e-2; Table 5.4
    has no JEKF column, the JEKF gets the DKF's values).  ``kind`` in {"kf", "dkf", "jekf"}.
    The seed's values are per sample; the random-walk variances (Sigma_w, Sigma_r) are scaled
    by ``dt_s / dt_ref_s`` (the seed's sample time is not printed; 1 s is assumed).
    """
    if table not in ("3.2", "5.4") or kind not in ("kf", "dkf", "jekf"):
        raise SimulationError(f"tuning: unknown table {table!r} or kind {kind!r} (tables '3.2', '5.4'; "
                              "kinds 'kf', 'dkf', 'jekf')")
    sc = math.sqrt(dt_s / dt_ref_s)
    if table == "3.2":
        sigma, b1, s0 = 0.05, 5e-4, 0.05
        b2 = 6e-3 if kind == "jekf" else 7e-3
    else:
        sigma, b1, b2, s0 = math.sqrt(2.5e-4), 5e-4, 0.03, 1e-2
    kw = {"sigma_c": sigma, "beta1": b1 * sc}
    if kind == "kf":
        kw["p0"] = (1.0, 1.0)
    elif kind == "dkf":
        kw.update(beta2=b2 * sc, p0=(1.0, 1.0), s0=s0)
    else:
        kw.update(beta2=b2 * sc, p0=(1.0, 1.0, s0 if table == "5.4" else 0.05))
    return kw


class ThermalEstimate(NamedTuple):
    """Estimator output (a posteriori): temperatures in degC, gradient in K/m, h in W/m^2/K."""

    t_mean_c: float
    gamma_c_per_m: float
    t_core_c: float
    t_surface_c: float
    h_w_m2k: float


# ---------------------------------------------------------------------------------
# the two-state model and the three filters, each written ONCE as a numba-compatible pure function
# (floats and float arrays in, tuples out, filter state updated in place).  ``f`` is the compiled
# function, ``f.py_func`` the same source run by Python (the reference; :func:`shevsim.core.lookup.py_func`).
# ---------------------------------------------------------------------------------
# constants vector ``c`` shared by the three filters (built by :meth:`_Base._constants`)
_R, _K, _ALPHA, _BQ, _DT, _EULER, _TWO, _Q, _RV, _QH, _HMIN, _HMAX, _TOTAL = range(13)
# filter state ``st`` (one float array; :class:`ThermalDKF` / :class:`ThermalJEKF` name slots 6-8)
_X0, _X1, _P00, _P01, _P11, _H, _S6, _S7, _S8, _HAS_U, _UQ, _UT = range(12)


class TwoStateDiscretiser:
    """The two-state model at sample time ``dt_s`` as functions of h (wraps the pure functions above).

    ``ad_bd(h)`` returns ``(a00, a01, a10, a11, b00, b01, b10, b11)``; ``out(h)`` returns the
    surface/core output rows ``(cs0, cs1, ds, cc0, cc1, dc)`` and ``dout(h)`` their h-derivatives
    (analytic).  ``d_ad_bd(h)`` returns the h-derivative of ``ad_bd`` by central differences.
    """

    def __init__(self, params: ThermalParams, dt_s: float, method: str = "zoh"):
        if not (math.isfinite(dt_s) and dt_s > 0):
            raise SimulationError(f"thermal estimator: dt_s must be > 0 s, got {dt_s!r}")
        if method not in ("zoh", "euler"):
            raise SimulationError(f"thermal estimator: discretisation must be 'zoh' or 'euler', got {method!r}")
        self.p = params
        self.dt = float(dt_s)
        self.method = method
        self._R = params.radius_m
        self._k = params.kt_w_mk
        self._a = params.alpha_m2_s
        self._bq = self._a / (self._k * params.volume_m3)   # 1/(rho c_p V)
        self._args = (self._R, self._k, self._a, self._bq, self.dt, method == "euler")
        self._last_h = None
        self._last = None

    def a_mat(self, h: float):
        return two_state_a(h, self._R, self._k, self._a)

    def ad_bd(self, h: float):
        if h != self._last_h:
            self._last = two_state_ad_bd(h, *self._args)
            self._last_h = h
        return self._last

    def d_ad_bd(self, h: float):
        """Central-difference h-derivative of :meth:`ad_bd` (step ``1e-5 (|h| + 1)``, one-sided at 0)."""
        return two_state_d_ad_bd(h, *self._args)

    def out(self, h: float):
        return two_state_out(h, self._R, self._k)

    def dout(self, h: float):
        """Derivatives of (cs0, cs1, ds) w.r.t. h."""
        return two_state_dout(h, self._R, self._k, 2.0)


@njit(cache=True)
def _predict_state(st, c, h):
    """``x <- Ad x + Bd u_prev`` (3.12a); returns ``Ad, Bd`` (8) and the prior ``x`` (2)."""
    a00, a01, a10, a11, b00, b01, b10, b11 = two_state_ad_bd(h, c[_R], c[_K], c[_ALPHA], c[_BQ], c[_DT],
                                                             c[_EULER] > 0.5)
    x0 = st[_X0]
    x1 = st[_X1]
    uq = st[_UQ]
    ut = st[_UT]
    st[_X0] = a00 * x0 + a01 * x1 + b00 * uq + b01 * ut
    st[_X1] = a10 * x0 + a11 * x1 + b10 * uq + b11 * ut
    return a00, a01, a10, a11, x0, x1


@njit(cache=True)
def _ad_p(st, a00, a01, a10, a11):
    """``M = Ad P`` of the 2x2 state covariance ``P`` in ``st``: ``(m00, m01, m10, m11)``."""
    p00 = st[_P00]
    p01 = st[_P01]
    p11 = st[_P11]
    return (a00 * p00 + a01 * p01, a00 * p01 + a01 * p11, a10 * p00 + a11 * p01, a10 * p01 + a11 * p11)


@njit(cache=True)
def _g_dh(da, x0, x1, uq, ut):
    """``g = dAd/dh x + dBd/dh u`` (``da`` = :func:`two_state_d_ad_bd`): the h-sensitivity of the prediction."""
    return (da[0] * x0 + da[1] * x1 + da[4] * uq + da[5] * ut,
            da[2] * x0 + da[3] * x1 + da[6] * uq + da[7] * ut)


@njit(cache=True)
def _predict_cov(st, a00, a01, a10, a11, q):
    """``P <- Ad P Ad' + q I`` of the 2x2 state covariance (3.12b)."""
    m00, m01, m10, m11 = _ad_p(st, a00, a01, a10, a11)
    st[_P00] = m00 * a00 + m01 * a01 + q
    st[_P01] = m00 * a10 + m01 * a11
    st[_P11] = m10 * a10 + m11 * a11 + q


@njit(cache=True)
def _correct_state(st, e, cs0, cs1, r):
    """Measurement update of (x, P) with the surface row ``[cs0, cs1]`` (3.13); returns the gain."""
    p00 = st[_P00]
    p01 = st[_P01]
    p11 = st[_P11]
    v0 = p00 * cs0 + p01 * cs1
    v1 = p01 * cs0 + p11 * cs1
    s = cs0 * v0 + cs1 * v1 + r
    k0 = v0 / s
    k1 = v1 / s
    st[_X0] += k0 * e
    st[_X1] += k1 * e
    st[_P00] = p00 - k0 * v0
    st[_P01] = p01 - k0 * v1
    st[_P11] = p11 - k1 * v1
    return k0, k1


@njit(cache=True)
def _finish(st, c, h, ta, q_w):
    """Store ``h`` (clipped to [h_min, h_max]) and the inputs for the next prediction; return the
    a-posteriori ``(T_mean, gamma, T_core, T_surface, h)``."""
    h = c[_HMIN] if h < c[_HMIN] else (c[_HMAX] if h > c[_HMAX] else h)
    st[_H] = h
    st[_HAS_U] = 1.0
    st[_UQ] = q_w
    st[_UT] = ta
    cs0, cs1, ds, cc0, cc1, dc = two_state_out(h, c[_R], c[_K])
    x0 = st[_X0]
    x1 = st[_X1]
    return x0, x1, cc0 * x0 + cc1 * x1 + dc * ta, cs0 * x0 + cs1 * x1 + ds * ta, h


@njit(cache=True)
def kf_step(st, c, y, ta, q_w):
    """One :class:`ThermalKF` update (h = ``st[5]`` given, not clipped) on the state ``st`` (in place)."""
    h = st[_H]
    if st[_HAS_U] > 0.5:
        a00, a01, a10, a11, _, _ = _predict_state(st, c, h)
        _predict_cov(st, a00, a01, a10, a11, c[_Q])
    cs0, cs1, ds, _, _, _ = two_state_out(h, c[_R], c[_K])
    _correct_state(st, y - (cs0 * st[_X0] + cs1 * st[_X1] + ds * ta), cs0, cs1, c[_RV])
    return _finish(st, c, h, ta, q_w)


@njit(cache=True)
def dkf_step(st, c, y, ta, q_w):
    """One :class:`ThermalDKF` update (3.10-3.15) on ``st = [x0, x1, p00, p01, p11, h, ph, dx0, dx1, has_u,
    uq, ut]`` (in place); ``dx = d x^+ / d h`` is the recursive sensitivity of the total derivative."""
    total = c[_TOTAL] > 0.5
    h = st[_H]
    ph = st[_S6] + c[_QH]                        # parameter time update (3.11)
    dx0 = st[_S7]
    dx1 = st[_S8]
    if st[_HAS_U] > 0.5:
        a00, a01, a10, a11, xp0, xp1 = _predict_state(st, c, h)     # (3.12) with A(h^-)
        _predict_cov(st, a00, a01, a10, a11, c[_Q])
        if total:
            da = two_state_d_ad_bd(h, c[_R], c[_K], c[_ALPHA], c[_BQ], c[_DT], c[_EULER] > 0.5)
            g0, g1 = _g_dh(da, xp0, xp1, st[_UQ], st[_UT])
            d0 = dx0
            d1 = dx1
            dx0 = g0 + a00 * d0 + a01 * d1
            dx1 = g1 + a10 * d0 + a11 * d1
    cs0, cs1, ds, _, _, _ = two_state_out(h, c[_R], c[_K])
    dcs0, dcs1, dds = two_state_dout(h, c[_R], c[_K], c[_TWO])
    x0 = st[_X0]
    x1 = st[_X1]
    e = y - (cs0 * x0 + cs1 * x1 + ds * ta)
    ch = dcs0 * x0 + dcs1 * x1 + dds * ta                     # partial dy/dh (3.15c)
    if total:
        ch += cs0 * dx0 + cs1 * dx1
    k0, k1 = _correct_state(st, e, cs0, cs1, c[_RV])           # state measurement update (3.13)
    if total:
        dx0 -= k0 * ch
        dx1 -= k1 * ch
    s = ch * ch * ph + c[_RV]                                  # parameter measurement update (3.14)
    lg = ph * ch / s
    st[_S6] = (1.0 - lg * ch) * ph
    st[_S7] = dx0
    st[_S8] = dx1
    return _finish(st, c, h + lg * e, ta, q_w)


@njit(cache=True)
def jekf_step(st, c, y, ta, q_w):
    """One :class:`ThermalJEKF` update (3.16-3.20) on ``st = [x0, x1, p00, p01, p11, h, p22, p02, p12, has_u,
    uq, ut]`` (in place): the EKF of the augmented state (T_mean, gamma, h)."""
    h = st[_H]
    p22 = st[_S6]
    p02 = st[_S7]
    p12 = st[_S8]
    if st[_HAS_U] > 0.5:
        # F = [[Ad, g], [0, 1]],  g = dAd/dh x + dBd/dh u  (3.20a)
        da = two_state_d_ad_bd(h, c[_R], c[_K], c[_ALPHA], c[_BQ], c[_DT], c[_EULER] > 0.5)
        a00, a01, a10, a11, x0, x1 = _predict_state(st, c, h)
        g0, g1 = _g_dh(da, x0, x1, st[_UQ], st[_UT])
        # M = Ad Pxx ; w = Ad pxh
        m00, m01, m10, m11 = _ad_p(st, a00, a01, a10, a11)
        w0 = a00 * p02 + a01 * p12
        w1 = a10 * p02 + a11 * p12
        n00 = m00 * a00 + m01 * a01 + w0 * g0 + g0 * w0 + p22 * g0 * g0
        n01 = m00 * a10 + m01 * a11 + w0 * g1 + g0 * w1 + p22 * g0 * g1
        n11 = m10 * a10 + m11 * a11 + w1 * g1 + g1 * w1 + p22 * g1 * g1
        st[_P00] = n00 + c[_Q]
        st[_P01] = n01
        st[_P11] = n11 + c[_Q]
        p02 = w0 + g0 * p22
        p12 = w1 + g1 * p22
        p22 = p22 + c[_QH]
    cs0, cs1, ds, _, _, _ = two_state_out(h, c[_R], c[_K])
    dcs0, dcs1, dds = two_state_dout(h, c[_R], c[_K], c[_TWO])
    x0 = st[_X0]
    x1 = st[_X1]
    c2 = dcs0 * x0 + dcs1 * x1 + dds * ta              # (3.20b)
    e = y - (cs0 * x0 + cs1 * x1 + ds * ta)
    p00 = st[_P00]
    p01 = st[_P01]
    p11 = st[_P11]
    v0 = p00 * cs0 + p01 * cs1 + p02 * c2
    v1 = p01 * cs0 + p11 * cs1 + p12 * c2
    v2 = p02 * cs0 + p12 * cs1 + p22 * c2
    s = cs0 * v0 + cs1 * v1 + c2 * v2 + c[_RV]
    k0 = v0 / s
    k1 = v1 / s
    k2 = v2 / s
    st[_X0] = x0 + k0 * e
    st[_X1] = x1 + k1 * e
    st[_P00] = p00 - k0 * v0
    st[_P01] = p01 - k0 * v1
    st[_P11] = p11 - k1 * v1
    st[_S7] = p02 - k0 * v2
    st[_S8] = p12 - k1 * v2
    st[_S6] = p22 - k2 * v2
    return _finish(st, c, h + k2 * e, ta, q_w)


def _st_property(i: int, doc: str):
    def get(self):
        return float(self._st[i])

    def set_(self, v):
        self._st[i] = v
    return property(get, set_, doc=doc)


class _Base:
    """Wrapper shared by the three filters: the state is one float array ``_st`` (read and written by
    the attributes below), the constants one array ``_c``; :meth:`update` runs the filter's pure step
    (``_STEP``, compiled, or its ``py_func`` with ``compiled=False``)."""

    _STEP = None
    x0 = _st_property(_X0, "a-posteriori T_mean [degC]")
    x1 = _st_property(_X1, "a-posteriori gamma [K/m]")
    p00 = _st_property(_P00, "state covariance")
    p01 = _st_property(_P01, "state covariance")
    p11 = _st_property(_P11, "state covariance")
    h = _st_property(_H, "h estimate (ThermalKF: the assumed h) [W/m^2/K]")

    @property
    def _u(self):
        """(q_w, t_amb_c) of the previous sample, None before the first update."""
        st = self._st
        return (float(st[_UQ]), float(st[_UT])) if st[_HAS_U] > 0.5 else None

    @_u.setter
    def _u(self, v):
        st = self._st
        if v is None:
            st[_HAS_U] = 0.0
        else:
            st[_HAS_U], st[_UQ], st[_UT] = 1.0, v[0], v[1]

    def __init__(self, params, dt_s, h0, x0_c, discretisation, *, sigma_c, beta1, p0, h_min, h_max, compiled,
                 beta2=0.0, total=False):
        self._st = np.zeros(12)
        self.params = params if params is not None else ThermalParams()
        self.disc = TwoStateDiscretiser(self.params, dt_s, discretisation)
        self.dt_s = float(dt_s)
        h0 = float(h0)
        if not (math.isfinite(h0) and h0 > 0):
            raise SimulationError(f"{type(self).__name__}: initial/known h_w_m2k must be > 0, got {h0!r}")
        self.h = h0
        self.x0 = float(x0_c[0])
        self.x1 = float(x0_c[1])
        self.r = float(sigma_c) ** 2
        self.q = float(beta1) ** 2
        self.qh = float(beta2) ** 2
        self.p00, self.p01, self.p11 = float(p0[0]), 0.0, float(p0[1])
        self.h_min = float(h_min)
        self.h_max = float(h_max)
        self.total = bool(total)
        self._u = None   # (q_w, t_amb_c) of the previous sample
        self.compiled = bool(compiled and HAVE_NUMBA)
        self._step = self._STEP if self.compiled else py_func(self._STEP)
        d = self.disc
        c = [0.0] * 13
        c[_R], c[_K], c[_ALPHA], c[_BQ], c[_DT], c[_EULER], c[_TWO] = \
            d._R, d._k, d._a, d._bq, d.dt, 1.0 if d.method == "euler" else 0.0, 2.0
        c[_Q], c[_RV], c[_QH], c[_HMIN], c[_HMAX], c[_TOTAL] = \
            self.q, self.r, self.qh, self.h_min, self.h_max, 1.0 if self.total else 0.0
        self._c = np.array(c)

    def update(self, t_surface_meas_c: float, t_amb_c: float, q_w: float) -> ThermalEstimate:
        """Predict with the previous sample's inputs, correct with this sample's measurement.

        ``t_surface_meas_c``, ``t_amb_c`` [degC], ``q_w`` [W per cell, + heat generated].
        """
        if not (math.isfinite(t_surface_meas_c) and math.isfinite(t_amb_c) and math.isfinite(q_w)):
            raise SimulationError(f"{type(self).__name__}.update: non-finite input "
                                  f"t_surface_meas_c={t_surface_meas_c!r}, t_amb_c={t_amb_c!r}, q_w={q_w!r}")
        return ThermalEstimate(*self._step(self._st, self._c, float(t_surface_meas_c), float(t_amb_c),
                                           float(q_w)))


class ThermalKF(_Base):
    """Kalman filter for (T_mean, gamma) with a known convection coefficient (seed Sec. 3.4.1, h given).

    Parameters
    ----------
    params : ThermalParams
        Cell thermal parameters (default seed Table 3.1).
    h_w_m2k : float
        Assumed convection coefficient [W/m^2/K]; can be changed between updates via ``h``.
    dt_s : float
        Sample time [s].
    x0_c : (float, float)
        Initial (T_mean [degC], gamma [K/m]); seed: (30, 0).
    sigma_c : float
        Surface-temperature measurement noise std [degC] (seed 0.05).
    beta1 : float
        State process-noise std per step (seed 5e-4).
    p0 : (float, float)
        Initial state variances (seed (1, 1)).
    compiled : bool
        Run the step :func:`kf_step` compiled (default) or its ``py_func`` (the same source in Python).

    Notes
    -----
    ``update(t_surface_meas_c [degC], t_amb_c [degC], q_w [W, + = heat generated])`` returns a
    :class:`ThermalEstimate`.
    """

    _STEP = staticmethod(kf_step)

    def __init__(self, params: ThermalParams | None = None, h_w_m2k: float = 56.2, dt_s: float = 1.0, *,
                 x0_c=(30.0, 0.0), sigma_c: float = 0.05, beta1: float = 5e-4, p0=(1.0, 1.0),
                 discretisation: str = "zoh", compiled: bool = True):
        super().__init__(params, dt_s, h_w_m2k, x0_c, discretisation, sigma_c=sigma_c, beta1=beta1, p0=p0,
                         h_min=0.0, h_max=math.inf, compiled=compiled)


class ThermalDKF(_Base):
    """Dual Kalman filter: KF for (T_mean, gamma), EKF for h (seed 3.10-3.15, Table 3.2).

    Parameters as :class:`ThermalKF`, plus ``beta2`` (h random-walk std per step, seed 7e-3),
    ``s0`` (initial h variance, seed 0.05), ``h_min``/``h_max`` (clip of the h estimate) and
    ``total_derivative`` (see module docstring); the step is :func:`dkf_step`.
    """

    _STEP = staticmethod(dkf_step)
    ph = _st_property(_S6, "h variance")
    dx0 = _st_property(_S7, "d x0^+ / d h")
    dx1 = _st_property(_S8, "d x1^+ / d h")

    def __init__(self, params: ThermalParams | None = None, h0_w_m2k: float = 56.2, dt_s: float = 1.0, *,
                 x0_c=(30.0, 0.0), sigma_c: float = 0.05, beta1: float = 5e-4, beta2: float = 7e-3,
                 p0=(1.0, 1.0), s0: float = 0.05, discretisation: str = "zoh", h_min: float = 0.5,
                 h_max: float = 1000.0, total_derivative: bool = True, compiled: bool = True):
        super().__init__(params, dt_s, h0_w_m2k, x0_c, discretisation, sigma_c=sigma_c, beta1=beta1, p0=p0,
                         h_min=h_min, h_max=h_max, compiled=compiled, beta2=beta2, total=total_derivative)
        self.ph = float(s0)


class ThermalJEKF(_Base):
    """Joint EKF on the augmented state (T_mean, gamma, h) (seed 3.16-3.20, Table 3.2).

    Parameters as :class:`ThermalDKF`; seed defaults ``beta2 = 6e-3``, ``P(0) = diag(1, 1, 0.05)``.
    The initial h variance is ``s0`` when given, else ``p0[2]`` (``p0`` may then have 2 entries).
    The step is :func:`jekf_step`.
    """

    _STEP = staticmethod(jekf_step)
    p22 = _st_property(_S6, "h variance")
    p02 = _st_property(_S7, "T_mean-h covariance")
    p12 = _st_property(_S8, "gamma-h covariance")

    def __init__(self, params: ThermalParams | None = None, h0_w_m2k: float = 56.2, dt_s: float = 1.0, *,
                 x0_c=(30.0, 0.0), sigma_c: float = 0.05, beta1: float = 5e-4, beta2: float = 6e-3,
                 p0=(1.0, 1.0, 0.05), discretisation: str = "zoh", h_min: float = 0.5, h_max: float = 1000.0,
                 s0: float | None = None, compiled: bool = True):
        super().__init__(params, dt_s, h0_w_m2k, x0_c, discretisation, sigma_c=sigma_c, beta1=beta1, p0=p0[:2],
                         h_min=h_min, h_max=h_max, compiled=compiled, beta2=beta2)
        # initial h variance: s0 if given (same keyword as the DKF), else the third entry of p0
        self.p22 = float(s0) if s0 is not None else (float(p0[2]) if len(p0) > 2 else 0.05)
