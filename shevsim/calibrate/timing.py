"""timing.py - a record's sample timing (declared convention, fitted time shift) and its sensor-noise floor.

Sample convention
-----------------
What a logged value at sample time ``t_k`` stands for (``--sample-convention`` of ``shevsim calibrate``):

* ``instantaneous`` (default; a CAN snapshot, a DAQ reading): the value at ``t_k``;
* ``mean-ending``: the mean over the period ending at the sample, ``(t_k - dt, t_k]`` (an energy-integrating
  logger);
* ``mean-starting``: the mean over the period starting at it, ``[t_k, t_k + dt)``.

Each calibration model declares the convention of its own prediction (``native_convention``: the vehicle
model's power is the mean over the grid period ending at the sample; the cell and engine models are
instantaneous).  A value averaged over a period of length ``dt`` is, to second order in ``dt``, the
instantaneous value at the period's centre, so the prediction is moved to the record's convention by
reading it at ``t + (c_record - c_model) dt`` with the centres ``c`` = 0 (instantaneous), -1/2 (ending),
+1/2 (starting).

Every such read - the convention's offset and the fitted time shift alike - is a band-limited fractional
delay (:func:`band_limited_read`), never an interpolating filter.  Linear interpolation at a fraction
``a`` of a sample is a low-pass whose strength depends on ``a`` (white noise keeps 71 % of its rms at
``a`` = 1/2, all of it at ``a`` = 0), so a fitted shift could buy smoothing: on a vehicle record the
prediction carries the differentiated speed noise, the fit moved the shift towards half-sample reads
(0.65 s for a 0.5 s latency, whose true read falls on the samples) and the mass up to make up for the
inertial power the smoothing took away (``docs/calibration_independent.md``).  Read half a sample later
by the band-limited delay, an ending-mean prediction is the mean over the period centred on the sample
(its box filter stays: it is the model's); read by linear interpolation it was the mean over two periods.

Time shift (the ``timing`` effect of every model)
-------------------------------------------------
A logger or CAN latency between the model's input channels and its output channels (a fraction of a
sample or several samples) is an effect of every calibration model: ``time_shift_s`` > 0 means the logged
output lags the logged input by that time (prediction read at ``t - time_shift_s``), bounds
+-``MAX_SHIFT_SAMPLES`` samples.  It is fitted like any effect, so a timing artefact is named as timing.

Sensor-noise floor (the honest baseline)
----------------------------------------
The noise floor of a measured channel is the smallest of (each estimate is inflated, never deflated, by
the signal's own dynamics):

* ``declared``: a sensor noise given by the user (``--sensor-noise CHANNEL=VALUE``), used alone when given;
* ``quiet``: robust std of first differences / sqrt 2 within quiet segments (the model's ``quiet_mask``:
  the vehicle at standstill, the cell at rest), at least ``MIN_QUIET`` differences;
* ``smoother``: robust std of the residual of a local quadratic (Savitzky-Golay, 7 samples) through the
  measured channel, divided by sqrt(1 - h0) (h0 = 1/3, the smoother's own weight on the sample) - the
  part a local quadratic cannot follow;
* ``first-difference``: robust std of the first differences of the model residual / sqrt 2 (the former
  estimate, kept as one candidate).

That is the output's *sensor* floor.  A correct model does not reach it: it is driven by the *measured*
inputs, whose noise it carries into its prediction (the vehicle differentiates the logged speed: 0.02 m/s
at 1 Hz is about 0.8 kW of power on a 1.6 t car, 8x its 100 W power sensor).  The noise floor of a
residual - what a correct model cannot remove - is the sensor floor plus the inputs' noise propagated
through the model, ``sqrt(sensor^2 + propagated^2)`` (:class:`PropagatedInputNoise`, Monte Carlo: the
record re-prepared with white noise at each input's floor added to every measured input, at full and at
half amplitude, ``N_INPUT_SEEDS`` fixed seeds; the rms over the held-out samples it is compared with of the
prediction's change proportional to the noise; the model's own simulation, so any model - vehicle, cell,
engine - with its nonlinearity, time stepping and sample timing).  An input's floor
(:func:`input_noise_floor`) is ``declared`` (``--sensor-noise`` accepts input channels) or the
``differences`` estimate (:func:`difference_noise`: the k-th differences' robust std, orders 1-6, pooled
where they agree, read clear of held values; the 7-sample smoother read a 1 Hz drive's speed at up to 2.4x
its noise, the cycle's own shape), taken as zero (method ``none``, no noise to propagate) below ``MIN_REL_INPUT_NOISE``
= 1e-9 x the channel's scale (the larger of its rms and its range: a constant ambient's 6e-15 degC, a
noise-free command's 1.6e-10 W are floating-point rounding, not a sensor's noise; a 24-bit ADC resolves
6e-8 of its range); the ``quiet`` estimate is not used for an input: its quiet segments are selected on
that input's own values (standstill: speed < 0.05 m/s) and a speed logger clips at zero, so the noise it
sees is truncated (0.008 m/s on the FASTSim records whose speed noise is 0.02 m/s).
"""
from __future__ import annotations

import copy
import dataclasses
import math

import numpy as np

from ..core.errors import DataError
from .models import Effect, Param

CONVENTIONS = {"instantaneous": 0.0, "mean-ending": -0.5, "mean-starting": 0.5}
DEFAULT_CONVENTION = "instantaneous"
MAX_SHIFT_SAMPLES = 4.0
MIN_QUIET = 30
SG_WINDOW = 7
MAX_DIFF_ORDER = 6           # difference_noise: the highest order of differences
CLIP_SHARE = 0.01            # difference_noise: an extreme value repeated in this share of the samples is a clip
CLIP_MARGIN = 4.0            # ... read only this many noise estimates away from it
POOL_SE = 1.0                # difference_noise: orders within this many standard errors of the smallest are pooled
MIN_ORDERS = 3               # ... and at least this many orders read (fewer: a record too short to tell)
MAD_SE = 1.166               # the standard error of a MAD-based std / the std, times sqrt(n) (normal samples)
N_INPUT_SEEDS = 4
GAP_STEPS = 10.0             # band_limited_read: a step over this x the median step splits the record
MIN_REL_INPUT_NOISE = 1e-9   # an input noise below this x the channel's scale is rounding (a 24-bit ADC: 6e-8)
INPUT_NOISE_SEED = 24


def median_dt(t: np.ndarray) -> float:
    return float(np.median(np.diff(np.asarray(t, float))))


def parse_conventions(spec) -> dict:
    """A record's declared sample convention(s): a convention name (every channel of the record: ``mean-ending``),
    ``CHANNEL=NAME[,CHANNEL=NAME]`` (those channels; every other one ``instantaneous``: a logger that averages the
    power over the period and snapshots the speed is ``power_w=mean-ending``), or a mapping of the same.  Returns
    ``{"*": name}`` or ``{channel: name}``; an unknown convention is a :class:`DataError` naming it."""
    if spec is None:
        return {"*": DEFAULT_CONVENTION}
    if isinstance(spec, dict):
        out = {str(k).strip(): str(v).strip() for k, v in spec.items()}
    elif "=" in str(spec):
        out = {}
        for part in str(spec).split(","):
            if not part.strip():
                continue
            k, sep, v = part.partition("=")
            if not sep or not k.strip():
                raise DataError(f"sample convention '{spec}': expected a convention ({', '.join(CONVENTIONS)}) or "
                                f"CHANNEL=CONVENTION[,CHANNEL=CONVENTION]")
            if k.strip() in out and out[k.strip()] != v.strip():
                raise DataError(f"sample convention '{spec}': channel '{k.strip()}' given twice with different "
                                f"conventions; give it once")
            out[k.strip()] = v.strip()
    else:
        out = {"*": str(spec).strip()}
    for k, v in out.items():
        if v not in CONVENTIONS:
            raise DataError(f"sample convention '{v}'" + ("" if k == "*" else f" of channel '{k}'")
                            + f": expected one of {', '.join(CONVENTIONS)}")
    return out


def convention_text(conv: dict) -> str:
    """:func:`parse_conventions`' result as the option's text (``mean-ending``, ``power_w=mean-ending``)."""
    return conv["*"] if set(conv) == {"*"} else ",".join(f"{k}={v}" for k, v in conv.items())


def convention_offsets(conv: dict, outputs, inputs, native: str, dt: float) -> tuple[dict, dict]:
    """Per output channel, the offset [s] at which the model's prediction (convention ``native``, computed from
    inputs it takes as values at their sample times) is read to give the record's convention of that channel:
    ``(c_output - c_native - c_input) dt``, ``c_input`` the convention of the model's driving input (its first of
    ``inputs`` in the record: the vehicle's speed, the cell's current, the engine's power).  An input logged as a
    period's mean stands for the value at the period's centre, so the whole model runs that much early or late:
    a record whose every channel is averaged over the period ending at the sample is read as the model's
    prediction half a sample later - the same as a record of snapshots, since a common delay of every channel
    is no delay between them (a new user's FASTSim trial: declared ``mean-ending`` for such a record, the
    convention applied to the power alone cost 1713 W held out against 829 W, and a -0.45 s timing was named).
    Returns ``(offsets, conventions)``: ``{output: s}`` and every named channel's convention.  A channel named in
    ``conv`` that the record does not have is a :class:`DataError` listing those it has."""
    if native not in CONVENTIONS:       # the model's own declaration (``native_convention``)
        raise DataError(f"sample convention '{native}' of the model: expected one of {', '.join(CONVENTIONS)}")
    known = list(outputs) + [c for c in inputs if c not in outputs]
    bad = [k for k in conv if k != "*" and k not in known]
    if bad:
        raise DataError(f"sample convention: {', '.join(repr(b) for b in bad)} is not a channel of this record "
                        f"(its channels: {', '.join(known)})")
    every = conv.get("*", DEFAULT_CONVENTION)
    conventions = {c: conv.get(c, every) for c in known}
    c_in = CONVENTIONS[conventions[inputs[0]]] if inputs else 0.0
    return ({c: (CONVENTIONS[conventions[c]] - CONVENTIONS[native] - c_in) * dt for c in outputs}, conventions)


def timing_effect(channels, dt: float) -> Effect:
    """The ``timing`` effect: a time shift between the model's inputs and its output channels."""
    def starts(ctx, base):
        return [{"time_shift_s": k * dt} for k in (-2.0, -1.0, -0.5, 0.5, 1.0, 2.0)]
    lim = MAX_SHIFT_SAMPLES * dt
    return Effect("timing", "time shift between the logged inputs and outputs (logger or CAN latency, "
                  "a sample convention other than the declared one); > 0: the output lags",
                  (Param("time_shift_s", "s", -lim, lim, 0.0, "output lag behind the inputs"),),
                  {"time_shift_s": 0.0}, tuple(channels), starts)


def shift_prediction(pred: dict, t: np.ndarray, offset_s) -> dict:
    """Every array channel of ``pred`` read at ``t + offset_s`` (:func:`band_limited_read`); ``offset_s`` a number
    (every channel) or ``{channel: s}`` (a channel not in it is not moved)."""
    per = offset_s if isinstance(offset_s, dict) else None
    if per is None and offset_s == 0.0:
        return pred
    out = {}
    for c, y in pred.items():
        off = float(per.get(c, 0.0)) if per is not None else float(offset_s)
        out[c] = (band_limited_read(y, t, off) if off != 0.0 and isinstance(y, np.ndarray) and y.shape == t.shape
                  else y)
    return out


def band_limited_read(y: np.ndarray, t: np.ndarray, offset_s: float) -> np.ndarray:
    """``y`` (sampled at ``t``) read at ``t + offset_s`` by a band-limited fractional delay (module docstring).

    The delay multiplies the spectrum of the even extension ``[y, y reversed]`` (whose periodic
    continuation is continuous, so the record's ends do not ring) by ``exp(2 pi i f offset_s)``: an
    all-pass, every frequency keeps its amplitude whatever the offset (the Nyquist bin of the even length
    keeps its real part).  Beyond the record's ends the read is the mirror image.  An irregular ``t`` is
    delayed on its median-step grid and read back linearly; a channel with non-finite values is read by
    linear interpolation (the FFT would spread them over the whole channel).  A record with gaps (a step
    over ``GAP_STEPS`` x the median step: a logger stopped overnight) is split there and each segment read
    on its own (mirrored at its ends), so the grid is at most ``GAP_STEPS`` x the samples, whatever the
    gaps' length (on the whole span's grid a one-day gap made each read of 1 800 samples 0.5 s).
    """
    y = np.asarray(y, float)
    t = np.asarray(t, float)
    n = y.size
    if n < 4 or not np.all(np.isfinite(y)):
        return np.interp(t + offset_s, t, y)
    dt = median_dt(t)
    cuts = np.flatnonzero(np.diff(t) > GAP_STEPS * dt) + 1
    if cuts.size:
        return np.concatenate([band_limited_read(ys, ts, offset_s) if ts.size >= 4 else
                               np.interp(ts + offset_s, ts, ys)
                               for ys, ts in zip(np.split(y, cuts), np.split(t, cuts))])
    return _read_segment(y, t, offset_s, dt)


def _read_segment(y: np.ndarray, t: np.ndarray, offset_s: float, dt: float) -> np.ndarray:
    """:func:`band_limited_read` of one gap-free segment on the grid of step ``dt``."""
    n = y.size
    tg = t[0] + dt * np.arange(n)
    regular = bool(np.allclose(tg, t, rtol=0.0, atol=1e-6 * dt))
    if not regular:
        tg = t[0] + dt * np.arange(int(round((t[-1] - t[0]) / dt)) + 1)
    yg = y if regular else np.interp(tg, t, y)
    from scipy import fft as sfft
    ext = np.concatenate([yg, yg[::-1]])
    m = ext.size
    ph = np.exp(2j * np.pi * np.arange(m // 2 + 1) * (offset_s / dt) / m)
    ph[-1] = math.cos(math.pi * offset_s / dt)
    out = sfft.irfft(sfft.rfft(ext) * ph, m)[:yg.size]
    return out if regular else np.interp(t, tg, out)


def _robust_std(x: np.ndarray) -> float:
    if x.size < 3:
        return float("nan")
    return float(1.4826 * np.median(np.abs(x - np.median(x))))


def smoother_noise(y: np.ndarray) -> float:
    """Robust std of the residual of a local quadratic (Savitzky-Golay) through ``y`` / sqrt(1 - h0)."""
    if y.size < 3 * SG_WINDOW:
        return float("nan")
    from scipy.signal import savgol_filter
    r = y - savgol_filter(y, SG_WINDOW, 2, mode="interp")
    h0 = savgol_filter(np.eye(SG_WINDOW)[SG_WINDOW // 2], SG_WINDOW, 2, mode="constant")[SG_WINDOW // 2]
    return _robust_std(r[SG_WINDOW:-SG_WINDOW]) / math.sqrt(max(1.0 - h0, 1e-6))


def _difference_orders(y: np.ndarray, keep: np.ndarray) -> float:
    """:func:`difference_noise` over the samples ``keep``: the pooled estimate, ``0.0`` when an order's differences
    are mostly exactly zero (no noise there to read), nan when fewer than ``MIN_ORDERS`` orders have enough
    stencils."""
    est = []
    for k in range(1, MAX_DIFF_ORDER + 1):
        c = math.comb(2 * k, k)
        # the k-th differences of white noise are an MA(k) series: autocorrelation (-1)^j C(2k, k + j) / C(2k, k)
        # at lag j; the variance of a scale estimate from them is (1 + 2 sum rho_j^2) times an independent one's
        infl = 1.0 + 2.0 * sum((math.comb(2 * k, k + j) / c) ** 2 for j in range(1, k + 1))
        d = np.diff(y, k)
        ok = np.ones(d.size, bool)
        for j in range(k + 1):
            ok &= keep[j:j + d.size]
        m = int(ok.sum())
        if m < MIN_QUIET * infl:
            continue
        e = _robust_std(d[ok]) / math.sqrt(c)
        if e == 0.0:
            return 0.0
        est.append((e, MAD_SE * e * math.sqrt(infl / m)))
    if len(est) < MIN_ORDERS:      # a short record: its low orders alone would read the signal's shape as noise
        return float("nan")
    e0, s0 = min(est)
    return float(np.mean([e for e, se in est if e - e0 <= POOL_SE * math.hypot(se, s0)]))


def difference_noise(y: np.ndarray) -> float:
    """White noise's std in ``y`` (a measured input) from its differences: for each order ``k`` = 1 ..
    ``MAX_DIFF_ORDER`` the robust std of the ``k``-th differences / sqrt(C(2k, k)) - unbiased for white noise,
    inflated by the signal's own ``k``-th differences (a step-like signal - a drive's current - least at a low
    order, a smooth one - a vehicle's speed at 1 Hz - at a high order) - and, of the orders within ``POOL_SE``
    standard error of the smallest, their mean (the smallest alone is low by chance on noise: 0.95x at 300
    samples; pooled 1.00x).  Nan (the caller falls back on the smoother) with fewer than ``MIN_ORDERS`` orders
    of enough stencils (at least ``MIN_QUIET`` x the order's variance inflation): a short record.  Samples at a
    held value are left out: an exact value taken by at least 3 and ``CLIP_SHARE`` of the samples (a clip, a dead
    band, a hold, a speed logger's standstill read as 0: no noise there); at a held value
    with fewer than ``CLIP_SHARE`` of the samples beyond it (a clip at the bottom or the top of the range: the noise
    of the samples near it is cut off on one side) the samples within ``CLIP_MARGIN`` x the first pass's estimate
    of it are left out too.  An order whose differences are mostly exactly zero reads no noise: 0 (a noise-free
    piecewise-polynomial command).  A value below the channel's resolution (the smallest step between its distinct
    values, a quantiser's) is raised to the resolution's own error, step / sqrt 12.  Measured on the FASTSim speed
    records shipped (true noise 0.014-0.028 m/s): 0.89-1.19x the truth, where the 7-sample quadratic smoother read
    up to 2.4x (the shape of a drive cycle between its samples); the PyBaMM records' current 1.01-1.25x (the
    smoother up to 2.35x)."""
    y = np.asarray(y, float)
    y = y[np.isfinite(y)]
    n = y.size
    if n < 3 * SG_WINDOW:
        return float("nan")
    vals, counts = np.unique(y, return_counts=True)
    held = vals[counts >= max(3.0, CLIP_SHARE * n)]
    keep = ~np.isin(y, held)
    est = _difference_orders(y, keep)
    if not math.isfinite(est) or est == 0.0:
        return est
    for h in held:
        if min(int((y < h).sum()), int((y > h).sum())) < CLIP_SHARE * n:     # a clip: at an end of the range
            keep &= np.abs(y - h) > CLIP_MARGIN * est
    est2 = _difference_orders(y, keep)
    est = est2 if math.isfinite(est2) else est
    step = float(np.min(np.diff(vals))) if vals.size > 1 else 0.0
    return max(est, step / math.sqrt(12.0)) if est > 0.0 else est


def quiet_noise(y: np.ndarray, quiet: np.ndarray | None) -> float:
    """Robust std of first differences / sqrt 2 between consecutive quiet samples."""
    if quiet is None:
        return float("nan")
    q = np.asarray(quiet, bool)
    both = q[1:] & q[:-1]
    if int(both.sum()) < MIN_QUIET:
        return float("nan")
    return _robust_std(np.diff(y)[both]) / math.sqrt(2.0)


def sensor_noise_floor(meas: np.ndarray, residual: np.ndarray, quiet, declared: float | None = None) -> dict:
    """``{"value", "method", "estimates"}``: the channel's noise floor (module docstring)."""
    if declared is not None:
        return {"value": float(declared), "method": "declared", "estimates": {"declared": float(declared)}}
    est = {"quiet": quiet_noise(meas, quiet), "smoother": smoother_noise(meas),
           "first-difference": _robust_std(np.diff(residual)) / math.sqrt(2.0) if residual.size > 3 else float("nan")}
    ok = {k: v for k, v in est.items() if math.isfinite(v) and v > 0}
    if not ok:
        return {"value": float("nan"), "method": "none", "estimates": est}
    k = min(ok, key=ok.get)
    return {"value": ok[k], "method": k, "estimates": est}



def input_noise_floor(y: np.ndarray, declared: float | None = None) -> dict:
    """``{"value", "method", "estimates"}``: the noise floor of a measured *input* (module docstring): declared,
    or the differences' estimate (:func:`difference_noise`; the local smoother's where it has none: a short
    record); value 0 (method ``none``, saying why) when the channel has none: a noise-free command, a constant,
    or an estimate below ``MIN_REL_INPUT_NOISE`` x the channel's scale (max of its rms and its range) -
    floating-point rounding, not noise."""
    if declared is not None:
        return {"value": float(declared), "method": "declared", "estimates": {"declared": float(declared)}}
    y = np.asarray(y, float)
    ests = {"differences": difference_noise(y), "smoother": smoother_noise(y)}
    # the differences' estimate, read clear of held values; the smoother only where it has none (too few stencils
    # for three orders: a short record): the smoother reads a clipped channel's standstill too, where the noise
    # is cut (0.78-0.86 x the truth on drives stopped 30 % of the time, tests/unit/test_calibrate_input_noise.py)
    k = "differences" if math.isfinite(ests["differences"]) else "smoother"
    est = ests[k]
    fin = y[np.isfinite(y)]
    scale = max(float(np.sqrt(np.mean(fin * fin))), float(np.ptp(fin))) if fin.size else 0.0
    if math.isfinite(est) and est > MIN_REL_INPUT_NOISE * scale:
        return {"value": est, "method": k, "estimates": ests}
    why = ("none: no estimate (too few samples)" if not math.isfinite(est) else
           f"none: the {k} estimate {est:.3g} is below {MIN_REL_INPUT_NOISE:g} x the channel's scale "
           f"{scale:.3g} (numerically zero: no noise to propagate)")
    return {"value": 0.0, "method": why, "estimates": {**ests, "scale": scale}}


class PropagatedInputNoise:
    """The measured inputs' noise carried through the model into its prediction (module docstring).

    ``floors``: ``{input column: 1-sigma noise}``.  For each of ``seeds`` fixed seeds (deterministic) one
    white-noise draw ``n`` is added to the input columns twice, at full and at half amplitude, and each
    copy of the record is prepared by a throw-away shallow copy of the model: ``prepare`` may set
    record-derived state on the model (the cell's initial SOC, knots, rests), which stays the original
    record's - only the prepared input arrays differ.  :meth:`floor` simulates the copies with ``model``.

    The floor is the part of the prediction's change that is proportional to the input noise, first-order
    error propagation: ``2 (p(n) - p(n / 2))`` (exact for a response linear in the noise, the quadratic
    term's error is 1.5x its own size).  A response that does not scale with the noise - a switch in the
    model that any perturbation toggles, e.g. a table chosen by the sign of a current that sits at zero -
    says nothing about the inputs' noise level: it is ``p(n) - p - 2 (p(n) - p(n / 2))``, reported as
    ``non_proportional`` and not counted (measured: the battery model on the Panasonic -20 degC record's
    rests, 6.1 mV rms for 2 mA of current noise and still 2.8 mV for 20 uA; 0.09 mV away from zero
    current).
    """

    def __init__(self, model, data, floors: dict, seeds: int = N_INPUT_SEEDS):
        self.floors = {k: float(v) for k, v in floors.items() if math.isfinite(v) and v > 0}
        self.seeds = seeds if self.floors else 0
        self.model = model
        self.copies = []
        self.failed = None
        self.non_proportional: dict = {}
        for k in range(self.seeds):
            rng = np.random.default_rng([INPUT_NOISE_SEED, k])
            noise = {c: rng.normal(0.0, sd, len(data.df)) for c, sd in self.floors.items()}
            pair = []
            for amp in (1.0, 0.5):
                df = data.df.copy()
                for c, n in noise.items():
                    df[c] = df[c].to_numpy(float) + amp * n
                try:
                    pair.append(copy.copy(model).prepare(dataclasses.replace(data, df=df)))
                except (DataError, ArithmeticError, ValueError) as exc:   # said in the method, never hidden
                    self.failed = f"{type(exc).__name__}: {exc}"
                    break
            if self.failed:
                self.copies = []
                break
            self.copies.append(tuple(pair))

    @property
    def method(self) -> str:
        if not self.floors:
            return "none (no measured input with a noise floor)"
        if self.failed:
            return f"none: the record with its inputs re-noised could not be prepared ({self.failed})"
        return (f"Monte Carlo: the inputs ({', '.join(f'{c} +- {v:.3g}' for c, v in self.floors.items())}) "
                f"re-noised with {self.seeds} fixed seeds at full and half amplitude, rms over the held-out "
                f"samples of the prediction's change proportional to the noise, 2 (p(n) - p(n/2))")

    def floor(self, simulate, values: dict, pred: dict, channels, where=None) -> dict:
        """``{channel: rms of the proportional change}`` over the samples ``where`` (boolean mask; all when None:
        the change is not stationary - the vehicle's scales with the speed - so it is taken over the samples it
        is compared with); ``simulate(model, ctx, values)`` -> prediction (the caller's read of it: sample
        convention, time shift), ``pred`` the unperturbed prediction at ``values``.  The rms of the response
        that does not scale with the noise is left in :attr:`non_proportional`."""
        if not self.copies:
            self.non_proportional = {c: 0.0 for c in channels}
            return {c: 0.0 for c in channels}
        lin = {c: [] for c in channels}
        rest = {c: [] for c in channels}
        for ctx_full, ctx_half in self.copies:
            p1, p2 = simulate(self.model, ctx_full, values), simulate(self.model, ctx_half, values)
            for c in channels:
                a, b, p0 = (np.asarray(x[c], float) for x in (p1, p2, pred))
                if where is not None:
                    a, b, p0 = a[where], b[where], p0[where]
                d = 2.0 * (a - b)
                r = (a - p0) - d
                ok = np.isfinite(d) & np.isfinite(r)
                lin[c].append(d[ok])
                rest[c].append(r[ok])

        def rms(parts):
            x = np.concatenate(parts) if parts else np.zeros(0)
            return float(np.sqrt(np.mean(x * x))) if x.size else 0.0
        self.non_proportional = {c: rms(rest[c]) for c in channels}
        return {c: rms(lin[c]) for c in channels}


def combined_floor(sensor: dict, propagated: float, how: str, inputs: dict, non_proportional: float = 0.0) -> dict:
    """A channel's noise floor: its sensor floor and the inputs' propagated noise added in quadrature."""
    s = sensor["value"] if math.isfinite(sensor["value"]) else 0.0
    v = math.hypot(s, propagated)
    return {"value": v if v > 0 else float("nan"),
            "method": f"{sensor['method']} sensor floor (+) measured inputs' noise propagated through the model",
            "sensor": sensor, "propagated_inputs": {"value": propagated, "method": how, "inputs": inputs,
                                                    "non_proportional_not_counted": non_proportional},
            "estimates": sensor.get("estimates", {})}
