"""workflow.py - fit, diagnose the residual, test candidate effects, select, refit, report.

Steps (:func:`run_workflow`):

1. **Split** the record into a training and a held-out part. Default ``blocks``: the time span is cut into
   10 equal blocks and ``round(10 * holdout)`` of them, evenly spread, are held out (so slowly varying
   effects are seen in both parts); ``tail`` holds out the last fraction.  The model is always simulated
   over the whole record (its inputs are measured everywhere); only training samples enter the fit.
2. **Fit** the declared parameters with ``scipy.optimize.least_squares`` (trust-region reflective,
   bounded; parameters mapped to [0, 1] between their bounds, log-scaled where declared).  Channels are
   weighted by 1 / (baseline training RMSE of the channel): the baseline is fitted once with weights
   1 / std(measured), reweighted and refitted; all later fits use those fixed weights.  The model is
   simulated at every sample, but the loss uses at most ``MAX_FIT_SAMPLES`` = 4000 training samples per
   channel (uniform stride); RMSE, BIC and diagnostics use all samples.  Effects with several starting
   points are screened by short fits (``PRE_NFEV`` = 8 evaluations each, from the current fit and from
   the declared defaults) and finished from the best ``N_STARTS_KEPT`` = 2.  Every fit carries a weak prior
   (:meth:`Fitter._prior`): each fitted parameter's nominal value with ``PRIOR_SIGMA`` = 1 bound range
   (normalised) as its standard deviation - it decides the directions the record leaves flat (a slow RC
   branch's capacitance on rests shorter than the branch), which the rounding of the linear algebra decided
   before (the same record gave ``c2_scale`` 63.6 or 3.21 with two sets of BLAS kernels); the reported costs,
   RMSEs and BICs are the data's alone.
3. **Diagnose** residuals per channel on both parts: bias, RMSE, drift slope, autocorrelation at lags
   1..10 and a Ljung-Box statistic, a high-frequency noise-floor estimate (robust std of first
   differences / sqrt 2), correlation with the model's candidate regressors and with measured columns the
   model does not use.
4. **Test** every candidate effect: fit model + effect (declared + effect parameters, multi-start where
   the effect declares starts; at most ``CAND_NFEV`` = 60 function evaluations per candidate fit, the
   final refit runs to convergence) on the training part; evaluate held-out RMSE per channel, the combined
   held-out score ``sqrt(mean_c (rmse_c / rmse_c,baseline)^2)`` (baseline = 1.0) and an
   autocorrelation-corrected BIC on the training residuals:
   ``BIC = sum_c n_eff,c ln(SSE_c / n_c) + k ln(n_eff)``, ``n_eff,c = n_c (1 - rho1_c) / (1 + rho1_c)``
   with rho1_c the lag-1 autocorrelation of the current model's training residual (correlated residuals
   carry less information than their sample count; the plain BIC would accept any parameter).
5. **Select** greedily: a candidate passes when, relative to the current model,
   (a) its combined held-out score falls by at least ``MIN_GAIN`` = 10 %,
   (b) no channel's held-out RMSE rises by more than ``MAX_WORSEN`` = 10 %, and
   (c) its BIC falls by at least ``MIN_DBIC`` = 10 ("very strong" on the Kass-Raftery scale);
   or, whatever the BIC says, when it halves (``HALVING``) some channel's held-out RMSE and (b) holds: the
   more systematic a residual (a missing effect), the more autocorrelated it is and the fewer effective
   samples the corrected BIC counts, so the BIC alone vetoes exactly the effects that matter most.
   In both cases (d) the gain must also be at least ``MIN_GAIN`` on the channels the effect acts on
   (``Effect.evidence``, default ``Effect.channels``; for a pair, each effect over the current model and
   over the other one alone): a gain that shows only on other channels comes from the refit of the declared
   parameters (the nominal's compromise between channels coupled through them: an equivalent circuit's heat
   follows resistances bent to a voltage model-form error), not from the effect.  What an effect claims is
   also checked on the record itself where the model can (:meth:`CalibrationModel.effect_evidence`: the
   cell's cooling change and reversible heat against the record's own energy balance, its OCV hysteresis, OCV
   correction and capacity against the relaxed voltages of its rests after current); a candidate whose
   claim the record does not show does not pass, and the report says why.  An effect with a claim about one
   channel (``Effect.channel_claim``: the cell's Arrhenius law, about the voltage) is tested there instead of
   by (d): its parameter refitted on that channel alone must be significant and of the joint fit's size
   (``_Run.channel_claim``; the standard error by the sandwich with a HAC - Newey-West, Andrews bandwidth -
   variance of the parameter's influence series, :meth:`Fitter.channel_only`).  Such an effect, new to the model,
   that does not pass with every parameter free is fitted and judged once more with the parameters it does not
   act on (the claim's held ones: the thermal parameters under an electrical law) held at the current model's
   values (:meth:`_Run.assess`, :meth:`_Run.hold_for`); when that version passes it is the candidate, and those
   parameters stay held while the effect is selected.  Why: free, they let the law trade the other channel's
   model-form error (measured on the PyBaMM Arrhenius record: Ea/R 2662 K with the held-out voltage +12.7 % and
   temperature -35 %; held, 1598 K; truth 1413 K; with the slow-branch limit of e9e17e9, since reverted,
   free: voltage +16.6 %; held: 1389 K); held always, they keep the compensation a model without the
   law made (the Panasonic -20 degC warm-up, whose free candidate passes: held, its final temperature error was
   1.07 K instead of 0.27 K).  A claim verified on its channel is a measurement there, as a directly measured
   parameter is (below): (a) is then any held-out gain (> 0), (b)-(c) stay.  Why not ``MIN_GAIN``: a law the
   channel shows can be small against the model's form error on the held-out blocks - the Arrhenius record's law
   acts where the cell is far from its mean temperature (the cold first minutes, a training block); the held-out
   blocks sit within 3 K of it, where the true law (Ea/R fixed at 1413 K) changes the held-out voltage by -0.4 %
   against a 12.4 mV form error.  A held-out significance test instead (Diebold-Mariano with a HAC variance) was
   measured and does not separate: t = -0.4 on the Arrhenius record, -2.0 to -4.6 (significant) on no-effect
   records (none_2, none_swing_2, capacity_swing), where the law with its thermal parameters held still fits the
   temperature's form error; the claim on the voltage does separate (Arrhenius record 1431 +- 223 K, t = 6.4;
   no-effect records 0 to 572 +- 390 K, t <= 1.5).  The claim is refitted beside its confounders
   (``Effect.claim_nuisance``): over a drive the cell warms while its SOC falls, so a resistance that changes
   with the SOC reads on the voltage as a temperature law; the Arrhenius claim must show beside the library's
   SOC law of the resistances, of either sign (PyBaMM no-effect drive with the heat of mixing, 25 -> 44 degC,
   resistance -6 % from 80 to 60 % SOC: 507 +- 300 K alone and selected, 181 +- 270 K beside the SOC law;
   the Arrhenius record 1483 +- 260 K beside it).
   An effect that cannot act on the channels a model's model-form terms are computed from
   (:meth:`CalibrationModel.model_form_terms`, ``model_form_sources``: the cell's temperature term is the heat of
   its own voltage error) is judged after those terms are fitted out of the residual on the training part: a
   thermal-only effect must explain what the heat of the circuit's voltage error does not (an effect on the
   voltage is judged on the plain residuals: fixing the voltage fixes its heat).  The
   ranking score and the reported RMSE are the plain ones.
   Among passing candidates the lowest held-out score wins, except that a candidate within ``TIE`` = 2 %
   of it with a lower BIC is preferred (parsimony), and a passing candidate with fewer parameters that the
   winner does not beat by ``MIN_GAIN`` replaces it (:meth:`_Run.parsimonious`: extra parameters must earn
   the same gain over a simpler explanation as an effect over the model).  The winner is added, the remaining candidates are
   re-tested on top of it; this repeats until none passes ("nothing found" when none passes at first).
   When no single effect passes in the first round, the pairs among the ``PAIR_TOP`` = 3 candidates with the
   best held-out gain are fitted together and judged by the same rule (two effects can each fix one part of
   the record and spoil another).  Backward elimination then drops a selected effect whose removal costs
   less than ``DROP_TOL`` = 3 % of held-out score (an early choice made redundant by later ones).  Before it,
   one exchange pass (:meth:`_Run.exchange`): a round-1 candidate that gained ``MIN_GAIN`` but did not pass
   replaces a selected effect when the exchanged model passes the rule against the selection (greedy forward
   selection can let an early choice keep the right effect out).
   Measured: on 20 noise/profile realisations of a cell record with no missing effect, 1 false selection.
   An effect that acts only on channels whose nominal held-out residual is within ``AT_NOISE`` = 1.5x their
   noise floor is not a candidate (there is nothing there for it to explain; listed in the report).
6. **Refit and report**: ``report.json``, ``report.md`` and PNG plots in the output directory, all
   written atomically (temp file + ``os.replace``).  The noise floor of each channel is its sensor noise
   (:func:`shevsim.calibrate.timing.sensor_noise_floor`: declared, or the smallest of a quiet-segment, a
   local-smoother and a first-difference estimate; the method is reported), so it holds on dynamic signals,
   plus, in quadrature, the measured inputs' noise propagated through the nominal model
   (:class:`shevsim.calibrate.timing.PropagatedInputNoise`): what a correct model cannot remove.  Both parts
   are reported.  The combined floor judges the baseline failure, ``unexplained`` (the final model's floor)
   and the timing rule; the ``AT_NOISE`` gate uses the sensor floor (:meth:`_Run.at_noise_floor`).
   Channels whose final held-out residual still exceeds 3x the noise floor with a significant correlation
   are listed under ``unexplained``; a nominal model whose held-out error is more than
   ``BASELINE_FAILURE_RATIO`` = 10x the combined noise floor, or at least ``SENSOR_FAILURE_RATIO`` = 100x the
   sensor floor alone, is reported under ``baseline_failure`` (channel, both ratios, the rules it broke,
   correlated signals, likely causes) and in words.  The second rule does not depend on the nominal: the
   propagated part is the nominal's own response to the input noise, so a grossly wrong nominal inflates
   its own combined floor (the 15.5 t truck on a car's record: 8.7x its combined floor, 790x the sensor's).  A selected effect whose parameter ends on a bound or
   outside its plausible range (``Param.plausible``) is removed, the model refitted without it, and the
   effect reported under ``model_form_discrepancy`` with that evidence; a baseline failure the selected
   effects do not fix is stated there too.  A selected time shift (``timing``) that removes no more than
   ``TIMING_SHARE`` = 1/2 of the residual variance above the noise floor (of the model without it) is not a
   logger latency but a model bent towards dynamics of another form: removed, refitted and stated as a
   model-form discrepancy (:meth:`_Run.screen_timing`).

Parameters the record measures directly (``CalibrationModel.measured_params``, e.g. a current-sensor
offset read in the rests of a cell record): the parameter is held within its measurement's +-3 standard
errors, and its effect is not held to the ``MIN_GAIN`` held-out gain (its parameter is not inferred from
the residual): it passes when it improves the held-out error of its channels at all, worsens no channel by
more than ``MAX_WORSEN``; the BIC rule is not applied to a significant measurement (the BIC weighs an inferred
parameter's complexity against the training fit, and the training fit can worsen with a measured correction where the
nominal's declared parameters had bent to its absence there); measured as zero (not ``significant``), it does not
pass.  In a round, a passing effect whose parameters are all measured and significant is selected before the
inferred candidates (a measurement before an inference: on an out-of-sample PyBaMM Ai2020 record a capacity 15 %
high scored better than the offset the rests measured).  The measurement is in the report
(``measured_parameters``).  A significant measurement that fails those rules passes when the record's own
check of what the effect claims confirms it (``CalibrationModel.measurement_confirmed``: the cell's offset at the
relaxed rests, which no resistance reaches): the fit under load then carries the model's form error, and the
report gives its verdict beside the measurement; such an effect is kept by the backward elimination.

Sample timing (:mod:`shevsim.calibrate.timing`): the record's declared ``sample_convention`` moves the
prediction once; the ``timing`` effect (a fitted time shift between inputs and outputs) is a candidate of
every model, so a logger latency is named as timing, not read as a physical parameter.
7. **Close the loop**: the final parameters are written as a parameter overlay ``params.toml`` in the
   components' own names (:mod:`shevsim.core.overlay`), and the record's inputs are replayed through the
   component(s) with that overlay, stepped by the master; ``report["replay"]`` holds the replay's RMSE
   per channel (train / held-out), which equals the fit's (same physics, same grid).
"""
from __future__ import annotations

import itertools
import json
import math
import re
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..core.atomic import write_bytes_atomic, write_text_atomic
from ..core.overlay import write_overlay
from scipy import optimize, stats

from ..core.errors import DataError, ShevsimError
from .models import CalibrationModel, Param, get_model
from .timing import (DEFAULT_CONVENTION, PropagatedInputNoise, combined_floor, convention_offsets, convention_text,
                     parse_conventions,
                     input_noise_floor, median_dt, sensor_noise_floor, shift_prediction, timing_effect)

MIN_GAIN = 0.10
MAX_WORSEN = 0.10
DROP_TOL = 0.03        # backward elimination: drop an effect when removing it costs < 3 % held-out score
HALVING = 0.5          # an effect that halves a channel's held-out RMSE (and worsens none > MAX_WORSEN) passes
BASELINE_FAILURE_RATIO = 10.0   # baseline held-out RMSE / combined noise floor above which the nominal model "fails"
SENSOR_FAILURE_RATIO = 100.0    # ... or / the sensor floor alone, at or above which it fails whatever the model
MIN_DBIC = 10.0
TIE = 0.02
N_BLOCKS = 10
ACF_LAGS = 10
MAX_ROUNDS = 3
MAX_FIT_SAMPLES = 4000
N_STARTS_KEPT = 2
PRE_NFEV = 8
PAIR_TOP = 3
CAND_NFEV = 60
# every fit's weak prior (Fitter._prior): a parameter's nominal value with this many bound ranges (normalised, log
# where declared) as its standard deviation; it decides only directions the record leaves flat
PRIOR_SIGMA = 1.0
# the baseline's first fit also starts from the nominal with one parameter at a time moved by this many normalised
# ranges either way (clipped to the range): 2 x (number of declared parameters) starts, screened by PRE_NFEV
# evaluations.  A quarter of the range: a factor of about 7 on a parameter whose range spans 3-4 decades.  Starts at
# the range's ends (0.02, 0.98) were measured and not kept: they reached optima with a branch on its bound (an RC
# branch slow and large enough to be a series capacitor) that absorbed a capacity loss and a current offset (the
# OKane2022 swing records of the third new-user trial, each then named nothing)
BASELINE_STEP = 0.25
# an effect's claim tested on its own channel alone (Effect.channel_claim, _Run.channel_claim): its parameter
# refitted there must exceed 0 by CLAIM_SIGMA standard errors (one-sided 5 %) to keep a candidate that passed the
# held-out rule, and agree with the joint fit within a factor CLAIM_FACTOR (or the joint value lie within CLAIM_SIGMA
# standard errors of it).  A claim that waives the MIN_GAIN held-out gain asks for evidence, not a 5 % test:
# CLAIM_SIGNIFICANCE = 3 standard errors (one-sided 0.13 %).  At the 5 % level an out-of-sample PyBaMM Ai2020
# record with no temperature law and 2 K of warming passed an Arrhenius law of 3348 +- 1400 K (2.4 standard errors,
# held-out gain 3.5 %) on the waiver; the PyBaMM Arrhenius record shows 1483 +- 260 K (5.7)
CLAIM_SIGNIFICANCE = 3.0
CLAIM_SIGMA = 1.645
CLAIM_FACTOR = 2.0


# ------------------------------------------------------------------------------------------ helpers

def atomic_write_bytes(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically (see :mod:`shevsim.core.atomic`)."""
    write_bytes_atomic(path, data)


def atomic_write_text(path: Path, text: str) -> None:
    write_text_atomic(path, text)


def make_split(t: np.ndarray, holdout: float, method: str = "blocks"):
    """Training / held-out boolean masks and a JSON-able description of the split."""
    if not (0.0 < holdout < 0.9):
        raise DataError(f"--holdout {holdout}: must be in (0, 0.9)")
    t0, t1 = float(t[0]), float(t[-1])
    if method == "tail":
        tc = t1 - holdout * (t1 - t0)
        hold = t > tc
        intervals = [[tc, t1]]
    elif method == "blocks":
        m = max(1, int(round(holdout * N_BLOCKS)))
        idx = sorted({min(N_BLOCKS - 1, int((j + 0.5) * N_BLOCKS / m)) for j in range(m)})
        edges = np.linspace(t0, t1, N_BLOCKS + 1)
        blk = np.clip(np.searchsorted(edges, t, side="right") - 1, 0, N_BLOCKS - 1)
        hold = np.isin(blk, idx)
        intervals = [[float(edges[b]), float(edges[b + 1])] for b in idx]
    else:
        raise DataError(f"split method '{method}': expected 'blocks' or 'tail'")
    train = ~hold
    if train.sum() < 10 or hold.sum() < 10:
        raise DataError(f"split leaves too few samples (train {train.sum()}, holdout {hold.sum()})")
    return train, hold, {"method": method, "holdout_fraction": holdout, "holdout_intervals_s": intervals,
                         "n_train": int(train.sum()), "n_holdout": int(hold.sum()),
                         "n_blocks": N_BLOCKS if method == "blocks" else None}


def _acf(r: np.ndarray, lags: int) -> np.ndarray:
    r = r - r.mean()
    d = float(np.dot(r, r))
    if d <= 0 or r.size <= lags + 1:
        return np.zeros(lags)
    return np.array([float(np.dot(r[:-k], r[k:])) / d for k in range(1, lags + 1)])


def noise_floor(r: np.ndarray) -> float:
    """High-frequency noise estimate: robust std of first differences / sqrt(2)."""
    d = np.diff(r)
    if d.size < 3:
        return float("nan")
    return float(1.4826 * np.median(np.abs(d - np.median(d))) / math.sqrt(2.0))


def diagnose(r: np.ndarray, t: np.ndarray, regs: dict) -> dict:
    """Residual diagnostics of one channel on one part (see module docstring)."""
    n = r.size
    acf = _acf(r, ACF_LAGS)
    q = n * (n + 2) * float(np.sum(acf ** 2 / (n - np.arange(1, ACF_LAGS + 1))))
    slope = float(np.polyfit(t - t[0], r, 1)[0]) * 3600.0 if n > 2 and t[-1] > t[0] else 0.0
    corr = []
    for name, x in regs.items():
        if x.size != n or np.std(x) == 0 or np.std(r) == 0:
            continue
        corr.append((name, float(np.corrcoef(x, r)[0, 1])))
    corr.sort(key=lambda c: -abs(c[1]))
    return {"n": n, "bias": float(r.mean()), "rmse": float(np.sqrt(np.mean(r * r))),
            "drift_per_hour": slope, "acf": [round(float(a), 4) for a in acf],
            "ljung_box_q": q, "ljung_box_p": float(stats.chi2.sf(q, ACF_LAGS)),
            "white": bool(stats.chi2.sf(q, ACF_LAGS) > 0.01), "noise_floor": noise_floor(r),
            "correlations": [{"signal": a, "r": round(b, 4)} for a, b in corr[:6]]}


# ------------------------------------------------------------------------------------------ fitting

@dataclass
class FitResult:
    effects: tuple
    params: dict
    pred: dict
    rmse: dict               # channel -> {"train", "holdout"}
    sse_train: dict
    n_train: dict
    k: int
    cost: float
    nfev: int
    score: float = float("nan")
    bic: float = float("nan")
    dbic: float = float("nan")
    gain: float = float("nan")
    worsen: float = float("nan")
    passed: bool = False
    reason: str = ""
    #: RMSE per channel after the model's model-form terms (CalibrationModel.model_form_terms) are removed
    #: from the residual (None: the model has none): what the selection rule judges
    rmse_sel: dict | None = None
    #: the claims of its effects tested on their own channel (effect -> _Run.channel_claim's answer), when tested
    claims: dict | None = None
    #: parameters held at these values in this candidate fit (an effect with a channel claim, _Run.assess)
    held: dict | None = None
    #: passed on a direct measurement the record's own check confirmed, not on the held-out rule (_Run.assess)
    measured_confirmed: bool = False

    @property
    def judged(self) -> dict:
        return self.rmse_sel if self.rmse_sel is not None else self.rmse


class Fitter:
    """Least-squares fits of a model (+ effects) on the training part of one data set."""

    def __init__(self, model: CalibrationModel, data, train: np.ndarray, hold: np.ndarray,
                 sample_convention: str = DEFAULT_CONVENTION):
        self.model = model
        self.ctx = model.prepare(data)
        df = data.df
        self.channels = [c for c in model.channels + model.optional_channels if c in df.columns]
        # sample timing (shevsim.calibrate.timing): the declared convention moves the prediction once; the
        # ``timing`` effect (a fitted time shift) is a candidate of every model
        self.t = df["time_s"].to_numpy(float)
        self.dt = median_dt(self.t)
        conv = parse_conventions(sample_convention)
        self.sample_convention = convention_text(conv)
        inputs = [c for c in getattr(model, "inputs", ()) if c in df.columns]
        self.conv_offsets, self.conventions = convention_offsets(conv, self.channels, inputs,
                                                                 model.native_convention, self.dt)
        self.input_convention = self.conventions[inputs[0]] if inputs else None
        offs = set(self.conv_offsets.values())
        #: the offset [s] of every output channel's read when they share it, else ``{channel: s}``
        self.conv_offset = offs.pop() if len(offs) == 1 else dict(self.conv_offsets)
        self.effects = dict(model.effects)
        self.effects["timing"] = timing_effect(self.channels, self.dt)
        self.meas = {c: df[c].to_numpy(float) for c in self.channels}
        self.train, self.hold = train, hold
        self.weights = {c: 1.0 / max(float(np.std(self.meas[c])), 1e-12) for c in self.channels}
        self.bounds_override = model.param_bounds(self.ctx)
        #: parameters the record measures directly: {name: {"value", "se", "how"}}; held within +-3 standard errors
        self.measured = dict(model.measured_params(self.ctx)) if hasattr(model, "measured_params") else {}
        for k, m in self.measured.items():
            half = max(3.0 * float(m["se"]), 1e-9 * max(abs(float(m["value"])), 1.0))
            self.bounds_override[k] = (float(m["value"]) - half, float(m["value"]) + half)
        self.nsim = 0
        # the loss uses at most MAX_FIT_SAMPLES training samples per channel (uniform stride; the model is
        # still simulated at every sample): keeps the least-squares linear algebra small on long records
        tr_idx = np.flatnonzero(train)
        self.fit_idx = tr_idx[::max(1, int(math.ceil(tr_idx.size / MAX_FIT_SAMPLES)))]

    def _params_for(self, effects) -> list[Param]:
        ps = list(self.model.declared)
        for e in effects:
            ps += list(self.effects[e].params)
        return ps

    def _bounds(self, p: Param):
        lo, hi = self.bounds_override.get(p.name, (p.lo, p.hi))
        if p.log:
            return math.log(lo), math.log(hi)
        return lo, hi

    def _to_x(self, ps, values):
        x = np.empty(len(ps))
        for j, p in enumerate(ps):
            lo, hi = self._bounds(p)
            v = values[p.name]
            v = math.log(max(v, 1e-300)) if p.log else v
            x[j] = min(max((v - lo) / (hi - lo), 1e-6), 1 - 1e-6)
        return x

    def _to_values(self, ps, x):
        out = {}
        for j, p in enumerate(ps):
            lo, hi = self._bounds(p)
            v = lo + x[j] * (hi - lo)
            out[p.name] = math.exp(v) if p.log else v
        return out

    #: called with a progress line at most every PROGRESS_EVERY_S of wall time (long records)
    progress = None
    PROGRESS_EVERY_S = 10.0

    def simulate(self, values):
        self.nsim += 1
        if self.progress is not None:
            now = time.perf_counter()
            if not hasattr(self, "_t_start"):
                self._t_start = self._t_said = now
            elif now - self._t_said >= self.PROGRESS_EVERY_S:
                self._t_said = now
                self.progress(f"... {self.nsim} simulations, {now - self._t_start:.0f} s "
                              f"({(now - self._t_start) / self.nsim:.2g} s each)")
        return self.simulate_in(self.model, self.ctx, values)

    def simulate_in(self, model, ctx, values):
        """``model``'s prediction on ``ctx`` (a prepared record of the same sample times) read as the fit reads it."""
        own = {k: v for k, v in values.items() if k != "time_shift_s"}
        return shift_prediction(model.simulate(ctx, own), self.t, self.shift_of(values))

    def shift_of(self, values):
        """Offset [s] at which the model's prediction is read: sample convention and fitted time shift (a number,
        or ``{channel: s}`` when the record's output channels have different conventions)."""
        ts = float(values.get("time_shift_s", 0.0))
        if isinstance(self.conv_offset, dict):
            return {c: o - ts for c, o in self.conv_offset.items()}
        return self.conv_offset - ts

    def _resid(self, values):
        pred = self.simulate(values)
        parts = []
        for c in self.channels:
            r = (pred[c][self.fit_idx] - self.meas[c][self.fit_idx]) * self.weights[c]
            parts.append(r)
        r = np.concatenate(parts)
        if not np.all(np.isfinite(r)):
            r = np.where(np.isfinite(r), r, 1e6)
        return r

    def fit(self, effects=(), start: dict | None = None, max_nfev: int = 200, hold: dict | None = None) -> FitResult:
        """Fit the declared parameters and those of ``effects`` on the training part.  ``hold``: parameters held
        at the given values (not fitted; e.g. the thermal ones under an electrical law with a channel claim,
        :meth:`_Run.hold_for`)."""
        hold = {k: float(v) for k, v in (hold or {}).items() if k in {p.name for p in self._params_for(effects)}}
        ps = [p for p in self._params_for(effects) if p.name not in hold]
        base = self.model.defaults()
        for e in effects:
            base.update({p.name: p.default for p in self.effects[e].params})
        if start:
            base.update({k: v for k, v in start.items() if k in {p.name for p in ps}})
        base.update(hold)
        starts = [base]
        for e in effects:
            fn = self.effects[e].starts
            if fn is not None and not (start and all(p.name in start for p in self.effects[e].params)):
                # multi-start: from the current fit and from the declared defaults (the current fit may
                # have bent its declared parameters to mimic the effect)
                bases = starts + ([dict(base, **self.model.defaults())] if start else [])
                starts = [dict(s, **x) for s in bases for x in fn(self.ctx, s)] or starts
        x_starts = [self._to_x(ps, s0) for s0 in starts]
        if not effects and not start and ps:
            # the nominal model's own fit (the baseline's first stage) starts from the nominal and from it with one
            # parameter at a time moved by BASELINE_STEP of its normalised range either way, screened and finished
            # as an effect's starts are (the same starts on every run).  From the nominal alone the fit found one
            # of the optima a degenerate circuit has, as the rounding went: on the Chen2020 swing record
            # none_swing_2 a fast first RC branch (c1_scale on its lower bound, training cost 25.65) or a larger
            # series resistance (26.65, held-out temperature 0.131 K against 0.104 K)
            x0 = x_starts[0]
            for j in range(len(ps)):
                for step in (-BASELINE_STEP, BASELINE_STEP):
                    xs = x0.copy()
                    xs[j] = min(max(x0[j] + step, 0.0), 1.0)
                    x_starts.append(xs)
        prior = self._prior(ps, effects)
        if len(x_starts) > N_STARTS_KEPT:
            # screen the starting points with short fits, finish the best few
            pre = [self._lsq(ps, x0, PRE_NFEV, hold, prior) for x0 in x_starts]
            x_starts = [pre[j].x for j in np.argsort([p.cost for p in pre], kind="stable")[:N_STARTS_KEPT]]
        best = None
        for x0 in x_starts:
            sol = self._lsq(ps, x0, max_nfev, hold, prior)
            if best is None or sol.cost < best.cost:
                best = sol
        values = {**hold, **self._to_values(ps, best.x)}
        # the BIC's complexity counts the parameters inferred from the residual: one held within its direct
        # measurement's +-3 standard errors (measured_params: a sensor offset read in the rests) is not one
        k = sum(1 for p in ps if p.name not in self.measured)
        data_cost = float(best.cost) - 0.5 * float(np.sum((prior[1] * (best.x - prior[0])) ** 2))
        return self.evaluate(effects, values, k, data_cost, int(best.nfev))

    def _prior(self, ps, effects) -> tuple[np.ndarray, np.ndarray]:
        """The fit's weak prior: ``(centre, weight)`` in the normalised [0, 1] parameter space.  Each fitted
        parameter is pulled towards its nominal value (the model's default, an effect's own default) with a
        standard deviation of ``PRIOR_SIGMA`` bound ranges; a parameter the record measures directly (held
        within its measurement's standard errors) has none.  Why: where the record does not pin a parameter
        (a direction of the training loss flat to its noise: a slow RC branch's capacitance on a drive whose
        rests are shorter than the branch) the unregularised optimum is wherever the last rounding of the linear
        algebra leaves it - measured on the Ecker2015 capacity-swing record: the baseline's ``c2_scale`` 63.6
        with OpenBLAS's Haswell kernels, 3.21 with its Sandybridge ones, training costs equal to 2e-5.  With the
        prior it is the nominal's value there, the same on every machine, and a parameter the record does
        determine moves by a fraction ``1 / (1 + H)`` of its distance from the nominal, ``H`` its curvature in
        the loss (thousands of samples of unit weighted variance: negligible)."""
        nominal = self.model.defaults()
        for e in effects:
            nominal.update({p.name: p.default for p in self.effects[e].params})
        centre = np.clip(self._to_x(ps, {p.name: nominal.get(p.name, p.default) for p in ps}), 0.0, 1.0)
        weight = np.array([0.0 if p.name in self.measured else 1.0 / PRIOR_SIGMA for p in ps])
        return centre, weight

    def _lsq(self, ps, x0, max_nfev, hold=None, prior=None):
        hold = hold or {}
        if prior is None:
            fun = lambda x: self._resid({**hold, **self._to_values(ps, x)})  # noqa: E731
        else:
            c, w = prior
            fun = lambda x: np.concatenate([self._resid({**hold, **self._to_values(ps, x)}), w * (x - c)])  # noqa: E731
        return optimize.least_squares(fun, x0, bounds=(0.0, 1.0), method="trf", x_scale=1.0, diff_step=1e-5,
                                      max_nfev=max_nfev, ftol=1e-7, xtol=1e-7, gtol=1e-9)

    def evaluate(self, effects, values, k, cost=float("nan"), nfev=0) -> FitResult:
        pred = self.simulate(values)
        rmse, sse, ntr = {}, {}, {}
        for c in self.channels:
            r = pred[c] - self.meas[c]
            rt, rh = r[self.train], r[self.hold]
            rmse[c] = {"train": float(np.sqrt(np.mean(rt * rt))), "holdout": float(np.sqrt(np.mean(rh * rh)))}
            sse[c] = float(np.sum(rt * rt))
            ntr[c] = int(rt.size)
        full = dict(self.model.full_values(values), time_shift_s=float(values.get("time_shift_s", 0.0)))
        shown = {p.name: full[p.name] for p in self._params_for(effects)}
        sel = None
        terms = self.model.model_form_terms(self.ctx, full, pred, self.meas) or {}
        if terms:
            sel = {}
            for c in self.channels:
                r = pred[c] - self.meas[c]
                b = terms.get(c)
                if b is not None and np.all(np.isfinite(r)) and np.all(np.isfinite(b)):
                    b = np.asarray(b, float).reshape(r.size, -1)
                    r = r - b @ np.linalg.lstsq(b[self.train], r[self.train], rcond=None)[0]
                rt, rh = r[self.train], r[self.hold]
                sel[c] = {"train": float(np.sqrt(np.mean(rt * rt))), "holdout": float(np.sqrt(np.mean(rh * rh)))}
        return FitResult(tuple(effects), shown, pred, rmse, sse, ntr, k, cost, nfev, rmse_sel=sel)

    def residual(self, fr: FitResult, c: str) -> np.ndarray:
        return fr.pred[c] - self.meas[c]

    def channel_only(self, effects, values: dict, channels, fixed, max_nfev: int = CAND_NFEV):
        """Refit ``effects`` from ``values`` on ``channels`` alone (every other channel's weight 0), the
        parameters named in ``fixed`` held.  Returns ``(values, se)``: the refitted values and each free
        parameter's standard error from the Jacobian of the ``channels``' training residual at the optimum, by
        the sandwich estimator with a HAC (Newey-West) variance of the parameter's influence series
        (:func:`_hac_var`).  Why not the residual's lag-1 autocorrelation as a discount of the sample count
        ``n (1 - rho) / (1 + rho)``: that is the variance of a *mean* of the residual (a regressor constant over
        the record); a parameter whose sensitivity changes sign with the current (a resistance law: every pulse)
        averages the residual's slow model-form error out, and the discount overstates its standard error by
        an order of magnitude (the PyBaMM Arrhenius record: Ea/R 1431 +- 1975 K by the discount, +- 223 K by
        the sandwich; its no-Arrhenius twin, the same drive: 174 +- 296 K)."""
        ps = [p for p in self._params_for(effects) if p.name not in fixed]
        start = dict(values)
        saved = dict(self.weights)
        try:
            self.weights = {c: (w if c in channels else 0.0) for c, w in saved.items()}
            sol = optimize.least_squares(lambda x: self._resid({**start, **self._to_values(ps, x)}),
                                         self._to_x(ps, start), bounds=(0.0, 1.0), method="trf", x_scale=1.0,
                                         diff_step=1e-5, max_nfev=max_nfev, ftol=1e-7, xtol=1e-7, gtol=1e-9)
        finally:
            self.weights = saved
        #: the cost (half the sum of squared weighted residuals on ``channels``) at the refit's optimum
        self.last_channel_cost = float(sol.cost)
        n = self.fit_idx.size
        rows = np.concatenate([np.full(n, c in channels) for c in self.channels])
        jac, res = np.asarray(sol.jac)[rows], np.asarray(sol.fun)[rows]
        # the sandwich (heteroscedasticity- and autocorrelation-consistent) covariance: each parameter's influence
        # series psi_t = (J^T J)^-1 J_t^T r_t, its variance summed with the Bartlett weights of Newey-West over
        # the lags of Andrews' (1991) AR(1) plug-in bandwidth (_hac_var)
        psi = (jac * res[:, None]) @ np.linalg.pinv(jac.T @ jac)
        se = {}
        for j, p in enumerate(ps):
            lo, hi = self._bounds(p)
            v = _hac_var(psi[:, j])
            # a parameter the channels do not move at all (e.g. pinned at its bound with no gradient) has no
            # information: an infinite, not a zero, standard error
            if not np.any(jac[:, j]) or not v > 0.0:
                v = float("inf")
            se[p.name] = float(math.sqrt(v)) * (hi - lo) if not p.log else float("nan")
        return {**start, **self._to_values(ps, sol.x)}, se


def _hac_var(x: np.ndarray) -> float:
    """Long-run variance ``sum_t sum_s w_|t-s| x_t x_s`` of the series ``x`` (the variance of its sum, not of its
    mean): Bartlett weights ``w_k = 1 - k / (L + 1)`` (Newey-West 1987, never negative) with Andrews' (1991)
    AR(1) plug-in bandwidth ``L = 1.1447 (alpha n)^(1/3)``, ``alpha = 4 rho^2 / ((1 - rho)^2 (1 + rho)^2)``,
    rho the series' lag-1 autocorrelation (the more persistent the series, the more lags count)."""
    x = np.asarray(x, float)
    n = x.size
    if n < 3 or not np.all(np.isfinite(x)):
        return float("nan")
    xc = x - x.mean()
    d = float(xc @ xc)
    rho = float(np.clip(xc[1:] @ xc[:-1] / d, -0.99, 0.99)) if d > 0 else 0.0
    alpha = 4.0 * rho * rho / ((1.0 - rho) ** 2 * (1.0 + rho) ** 2)
    lags = int(min(n - 1, max(1, math.ceil(1.1447 * (alpha * n) ** (1.0 / 3.0)))))
    v = float(x @ x)
    for k in range(1, lags + 1):
        v += 2.0 * (1.0 - k / (lags + 1.0)) * float(x[k:] @ x[:-k])
    return v


IDENT_SE_MAX = 0.1      # 1-sigma uncertainty above this fraction of the bound range: "not identifiable"
IDENT_STEP = 1e-3       # finite-difference step in the normalised [0, 1] parameter space


def identifiability(fitter: "Fitter", effects, values: dict) -> list[dict]:
    """Local identifiability of every fitted parameter from this record (Fisher information).

    The Jacobian ``J`` of the training residual with respect to each parameter, normalised to its bound
    range ([0, 1], log where declared), is taken by central differences at the final values; each
    channel's rows are divided by its residual scale ``sigma_c`` = max(training RMSE, noise floor of the
    measurement), inflated by ``sqrt((1 + rho1) / (1 - rho1))`` for the residual's lag-1 autocorrelation
    (correlated samples carry less information).  The covariance ``(J^T J)^-1`` gives each parameter's
    1-sigma uncertainty as a fraction of its bound range (``se_frac``; the inverse is regularised so that
    a direction with no information has a huge, not a zero, variance).  A parameter with
    ``se_frac > IDENT_SE_MAX`` is **not identifiable** from this record: the data do not pin it (no
    excitation, or it trades off against another parameter - ``partner`` names the most correlated one).
    """
    ps = fitter._params_for(tuple(effects))
    if not ps:
        return []
    x0 = fitter._to_x(ps, values)
    idx = fitter.fit_idx
    base = fitter.simulate(fitter._to_values(ps, x0))
    sig = {}
    for c in fitter.channels:
        r = base[c][idx] - fitter.meas[c][idx]
        rmse = float(np.sqrt(np.mean(r * r))) if r.size else 0.0
        nf = noise_floor(fitter.meas[c][idx])
        rho = float(np.clip(_acf(r, 1)[0], 0.0, 0.999)) if r.size > 2 else 0.0
        scale = max(rmse, nf if math.isfinite(nf) else 0.0, 1e-12 * max(float(np.std(fitter.meas[c])), 1e-300))
        sig[c] = scale * math.sqrt((1.0 + rho) / (1.0 - rho))
    cols = []
    for j in range(len(ps)):
        xp, xm = x0.copy(), x0.copy()
        xp[j] = min(x0[j] + IDENT_STEP, 1.0)
        xm[j] = max(x0[j] - IDENT_STEP, 0.0)
        pp = fitter.simulate(fitter._to_values(ps, xp))
        pm = fitter.simulate(fitter._to_values(ps, xm))
        col = np.concatenate([(np.asarray(pp[c])[idx] - np.asarray(pm[c])[idx]) / (xp[j] - xm[j]) / sig[c]
                              for c in fitter.channels])
        cols.append(np.where(np.isfinite(col), col, 0.0))
    J = np.column_stack(cols)
    F = J.T @ J
    k = F.shape[0]
    eps = 1e-10 * max(float(np.trace(F)) / k, 1.0)
    cov = np.linalg.inv(F + eps * np.eye(k))
    se = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    d = np.sqrt(np.clip(np.diag(cov), 1e-300, None))
    corr = cov / np.outer(d, d)
    out = []
    for j, p in enumerate(ps):
        partner = None
        if k > 1:
            cj = np.abs(corr[j]).copy()
            cj[j] = 0.0
            m = int(np.argmax(cj))
            partner = {"parameter": ps[m].name, "correlation": round(float(corr[j, m]), 4)}
        out.append({"parameter": p.name, "se_frac": float(se[j]), "sensitivity": float(np.linalg.norm(J[:, j])),
                    "identifiable": bool(se[j] <= IDENT_SE_MAX), "partner": partner, "unit": p.unit})
    return out


DETECT_STEP = 1e-3      # finite-difference step of an effect's parameter, as a fraction of its bound range


def detection_limits(fitter: "Fitter", selected, final: FitResult, ref: dict, skip=(), held=(),
                     pushed=(), shapes: list | None = None, only_shapes: bool = False) -> list[dict]:
    """What the record could have shown, to first order: for every one-parameter effect not selected, the smallest
    change of its parameter from its neutral value (the effect off) whose own signal would gain the selection
    rule's ``MIN_GAIN`` held-out.

    For each direction from the neutral value, the effect's signal ``s`` per unit of its parameter (a difference
    of the prediction) less what a refit of the fitted parameters takes of it: ``s`` projected out of their
    Jacobian's span on the training samples with the fit's channel weights (a parameter on a bound moving only
    inwards, except one the record pushes against, ``pushed``: the model-form discrepancy's declared parameters on
    a bound, which move both ways - what of the signal they would take past the bound is the discrepancy's, not the
    effect's own evidence; FASTSim's Bolt on HWFET with 300 kg of payload, its regenerative efficiency scale on the
    upper bound: 178 kg with it held there, 386 kg with it free, while the mass candidate fitted 272 kg and gained
    7.7 %), the same coefficients applied to the held-out samples.  Not in that refit: parameters held within a
    direct measurement's standard errors and those an effect's channel claim holds (``held``).  If the record carried the effect
    at size ``d`` on top of the final model, channel ``c`` would show the held-out RMSE ``sqrt(r_c^2 + a_c^2 d^2)``
    (``r_c`` the final held-out RMSE, ``a_c`` the held-out RMS of the signal left), and the rule's two gains,
    (a) on the combined score over all channels (each over its baseline RMSE ``b_c``, ``ref``) and (d) on the
    effect's evidence channels, reach ``MIN_GAIN`` at ``d = sqrt(((1 - g)^-2 - 1) sum r_c^2 / b_c^2 /
    sum a_c^2 / b_c^2)`` over the channels of each; the limit is the larger (``binding``), per direction
    (``limit_up``, ``limit_down``; ``limit`` the smaller).  The signal is then
    taken again as the secant over +-d, and the limit recomputed until it settles (``tangent_limit``: the first
    value; ``nonlinear`` when they differ by more than 20 %: a time constant, a saturation).  A limit, not a
    promise: a true effect below it does not reach the gain by its own signal, but a candidate may still pass by
    also fitting the model's form error or the noise's cross term (PyBaMM's Ai2020 cell with 12 % lost capacity:
    limit down 0.47 A.h, the truth 0.27 A.h; the capacity candidate fitted 1.993 A.h against 2.006 and gained 8.2 %
    held-out, not named).  Measured against exact least squares on a linear model and by injection (a constant
    auxiliary load added to a FASTSim record at 0.5 and 2 times the limit: 2.1 % and 26.9 % gained, 2.8 % and
    28.2 % implied; ``tests/unit/test_calibrate_detection.py``).  On a record that already carries the effect
    (``r_c`` includes it) the threshold of a one-channel effect is ``(1 - g)`` times the limit.  Skipped: effects
    with several parameters, parameters measured directly, parameters already fitted; an effect whose claim is
    tested on its channel (``Effect.channel_claim``: verified, any held-out gain passes) is listed with
    ``limit`` None and the reason, as is one with no first-order signal at its neutral value (a limit not
    reached: ``regen_limit``).

    ``shapes`` (a list, when given) receives one row per effect with several parameters of one unit (knots: an OCV
    correction, dU/dT, grade segments; `shape_limit`), linear in them: per rule the held-out Gram matrix ``Q`` of
    the signals left after the refit (over the channels' baselines) and ``R``, so that a change ``delta`` of the
    knots gains the rule's ``MIN_GAIN`` when ``delta' Q delta >= need R``; and the rms knot change of its most and
    least visible shapes (the extremes over the rules' eigenvectors and 512 fixed random directions).
    ``only_shapes``: those rows alone (the one-parameter effects skipped)."""
    hold_names = set(held) | set(fitter.measured)
    ps, lb, ub = [], [], []
    for p in fitter._params_for(tuple(selected)):
        if p.name in hold_names or p.name not in final.params:
            continue
        lo, hi = fitter.bounds_override.get(p.name, (p.lo, p.hi))
        pos = _bound_position(p, float(final.params[p.name]), lo, hi)
        ps.append(p)      # a parameter on a bound moves only inwards in the refit, unless the record pushes past it
        lb.append(0.0 if pos <= BOUND_TOL and p.name not in pushed else -np.inf)
        ub.append(0.0 if pos >= 1.0 - BOUND_TOL and p.name not in pushed else np.inf)
    values = dict(fitter.model.full_values({k: v for k, v in final.params.items() if k != "time_shift_s"}))
    values.update({k: v for k, v in final.params.items()})
    chans = list(fitter.channels)
    idx, hold = fitter.fit_idx, fitter.hold
    w = {c: float(fitter.weights[c]) for c in chans}

    def finite(a):
        a = np.asarray(a, float)
        return np.where(np.isfinite(a), a, 0.0)

    x0 = fitter._to_x(ps, values) if ps else np.empty(0)
    cols = []
    for j in range(len(ps)):
        xp, xm = x0.copy(), x0.copy()
        xp[j] = min(x0[j] + IDENT_STEP, 1.0)
        xm[j] = max(x0[j] - IDENT_STEP, 0.0)
        pp = fitter.simulate({**values, **fitter._to_values(ps, xp)})
        pm = fitter.simulate({**values, **fitter._to_values(ps, xm)})
        step = xp[j] - xm[j]
        cols.append({c: finite((np.asarray(pp[c], float) - np.asarray(pm[c], float)) / step) for c in chans})
    J = (np.column_stack([np.concatenate([col[c][idx] * w[c] for c in chans]) for col in cols]) if cols else None)
    r = {c: float(final.rmse[c]["holdout"]) for c in chans}
    b = {c: max(float(ref.get(c, r[c])), 1e-300) for c in chans}
    need = (1.0 - MIN_GAIN) ** -2 - 1.0

    def left_rms(sig):
        """Held-out RMS per channel of the signal ``sig`` ({channel: array}) left after the refit; its training
        norm and the share the refit takes."""
        lv, norm, ab = left_vec(sig)
        return ({c: float(np.sqrt(np.mean(lv[c] ** 2))) if lv[c].size else 0.0 for c in chans}, norm, ab)

    def left_vec(sig):
        """The held-out samples per channel of the signal ``sig`` left after the refit; its training norm and the
        share the refit takes."""
        s_tr = np.concatenate([sig[c][idx] * w[c] for c in chans])
        if J is None:
            beta = np.empty(0)
        elif np.all(np.isinf(lb)) and np.all(np.isinf(ub)):
            beta = np.linalg.lstsq(J, s_tr, rcond=None)[0]
        else:
            beta = optimize.lsq_linear(J, s_tr, bounds=(np.asarray(lb), np.asarray(ub))).x
        norm = float(np.linalg.norm(s_tr))
        left_tr = s_tr - (J @ beta if J is not None else 0.0)
        lv = {}
        for c in chans:
            lc = sig[c] - sum((beta[k] * cols[k][c] for k in range(len(cols))), np.zeros_like(sig[c]))
            lv[c] = lc[hold] if hold.any() else np.zeros(0)
        return lv, norm, (float(1.0 - (np.linalg.norm(left_tr) / norm) ** 2) if norm > 0 else float("nan"))

    def limit_of(a, ev):
        out = {}
        for rule, cs in (("combined score", chans), ("its channels", ev)):
            q = sum((a[c] / b[c]) ** 2 for c in cs)
            out[rule] = math.sqrt(need * sum((r[c] / b[c]) ** 2 for c in cs) / q) if q > 0 else math.inf
        rule = max(out, key=out.get)
        return out[rule], rule

    out = []
    done = set(selected) | set(skip)
    for name, eff in fitter.effects.items():
        if name in done or len(eff.params) != 1 or only_shapes:
            continue
        prm = eff.params[0]
        if prm.name in fitter.measured or prm.name in {p.name for p in fitter._params_for(tuple(selected))}:
            continue
        ev = [c for c in (eff.evidence or eff.channels) if c in chans]
        n0 = float(eff.neutral.get(prm.name, prm.default))
        row = {"effect": name, "parameter": prm.name, "unit": prm.unit, "neutral": n0, "limit": None,
               "channels": ev}
        if eff.channel_claim is not None:
            out.append({**row, "why_none": "its claim is tested on its own channel: verified, any held-out gain "
                                           "passes, so no held-out limit applies"})
            continue
        lo, hi = fitter.bounds_override.get(prm.name, (prm.lo, prm.hi))
        p0 = fitter.simulate({**values, prm.name: n0})

        def signal(sign, d):
            """The effect's signal per unit over a change ``sign * d`` from the neutral value (None past a bound)."""
            v = n0 + sign * d
            if not lo <= v <= hi or d <= 0.0:
                return None
            pv = fitter.simulate({**values, prm.name: v})
            return {c: finite((np.asarray(pv[c], float) - np.asarray(p0[c], float)) / d) for c in chans}

        per, absorbed = {}, None
        for sign in (1.0, -1.0):
            sig = signal(sign, DETECT_STEP * (hi - lo))
            if sig is None or not ev:
                continue
            a, norm, ab = left_rms(sig)
            absorbed = ab if absorbed is None else max(absorbed, ab)
            if not norm > 0 or not any(a[c] > 0 for c in chans):
                continue
            lim, rule = limit_of(a, ev)
            tangent = lim
            for _ in range(4):        # the secant over the limit until it settles (time constants saturate)
                sig2 = signal(sign, lim) if math.isfinite(lim) else None
                if sig2 is None:
                    break
                a2, _n, _ab = left_rms(sig2)
                new, rule = limit_of(a2, ev)
                settled = abs(new / lim - 1.0) < 0.05 if math.isfinite(new) else True
                lim = new
                if settled:
                    break
            per[sign] = (lim, tangent, rule)
        if not ev or (absorbed is None and not per):
            continue
        if not per or not any(math.isfinite(v[0]) for v in per.values()):
            out.append({**row, "why_none": "no first-order signal at its neutral value (a limit or threshold the "
                                           "record does not reach there)", "absorbed_frac": absorbed})
            continue
        sign, (lim, tangent, rule) = min(per.items(), key=lambda kv: kv[1][0])
        up, dn = per.get(1.0), per.get(-1.0)
        lo_p, hi_p = prm.plausible or (lo, hi)
        out.append({**row, "limit": float(lim), "limit_up": (float(up[0]) if up and math.isfinite(up[0]) else None),
                    "limit_down": (float(dn[0]) if dn and math.isfinite(dn[0]) else None), "binding": rule,
                    "tangent_limit": float(tangent), "nonlinear": bool(abs(lim / tangent - 1.0) > 0.2),
                    "relative": (lim / abs(n0) if n0 != 0.0 else None),
                    "reachable": bool(n0 + lim <= hi_p or n0 - lim >= lo_p),
                    "absorbed_frac": absorbed})
    if shapes is not None:
        fitted_names = {p.name for p in fitter._params_for(tuple(selected))}
        for name, eff in fitter.effects.items():
            if name in done or len(eff.params) < 2 or len({p.unit for p in eff.params}) != 1 \
                    or len({re.sub(r"\[\d+\]$", "", p.name) for p in eff.params}) != 1 \
                    or not all(re.search(r"\[\d+\]$", p.name) for p in eff.params):
                continue      # knots: one indexed parameter name, one unit
            if any(p.name in fitter.measured or p.name in fitted_names for p in eff.params):
                continue
            ev = [c for c in (eff.evidence or eff.channels) if c in chans]
            if not ev or not hold.any():
                continue
            bounded = bool(np.isfinite(lb).any() or np.isfinite(ub).any()) if ps else False
            row = _shape_row(fitter, eff, values, chans, ev, left_vec, finite, r, b, need, int(hold.sum()), bounded)
            if row is not None:
                shapes.append(row)
    return out


def _shape_row(fitter, eff, values, chans, ev, left_vec, finite, r, b, need, n_hold, bounded=False) -> dict | None:
    """`detection_limits`' row of an effect with several parameters of one unit (see there).  With a refit
    parameter on a bound (``bounded``: it moves one way only, so the projection is not linear) the two extreme
    shapes' limits are taken again from their own signals, each sign (``linear`` False: `shape_limit` of any other
    shape is then the Gram matrix's approximation)."""
    n0 = {p.name: float(eff.neutral.get(p.name, p.default)) for p in eff.params}
    base = {**values, **n0}
    p0 = fitter.simulate(base)
    left, absorbed, sigs = [], [], []
    for prm in eff.params:
        lo, hi = fitter.bounds_override.get(prm.name, (prm.lo, prm.hi))
        step = DETECT_STEP * (hi - lo)
        sign = 1.0 if n0[prm.name] + step <= hi else -1.0
        pv = fitter.simulate({**base, prm.name: n0[prm.name] + sign * step})
        sig = {c: finite((np.asarray(pv[c], float) - np.asarray(p0[c], float)) / (sign * step)) for c in chans}
        lv, _norm, ab = left_vec(sig)
        sigs.append(sig)
        left.append(lv)
        absorbed.append(ab)
    k = len(left)
    rules = {}
    for rule, cs in (("combined score", chans), ("its channels", ev)):
        q = np.zeros((k, k))
        for c in cs:
            m = np.column_stack([left[j][c] for j in range(k)])
            q += m.T @ m / n_hold / b[c] ** 2
        rules[rule] = {"Q": q.tolist(), "R": float(sum((r[c] / b[c]) ** 2 for c in cs)), "channels": list(cs)}
    row = {"effect": eff.name, "parameters": [p.name for p in eff.params], "unit": eff.params[0].unit,
           "about": [p.doc for p in eff.params], "neutral": [n0[p.name] for p in eff.params], "need": need,
           "rules": rules, "channels": ev, "absorbed_frac": [float(a) for a in absorbed], "linear": not bounded}
    dirs = [np.asarray(v) for ru in rules.values() for v in np.linalg.eigh(np.asarray(ru["Q"]))[1].T]
    dirs += list(np.random.default_rng(0).standard_normal((512, k)))
    lims = [(shape_limit(row, u)["limit_rms"], i) for i, u in enumerate(dirs)]
    (lo_lim, i_lo), (hi_lim, i_hi) = min(lims), max(lims)
    if not math.isfinite(lo_lim):
        return None
    unit_vec = lambda u: (np.asarray(u, float) / np.linalg.norm(u)).tolist()   # noqa: E731
    if bounded:          # the extreme shapes from their own signals, each sign (the bounded refit is not linear)
        def own(u):
            lims = []
            for sgn in (1.0, -1.0):
                lv, _n, _ab = left_vec({c: sgn * sum(ui * sg[c] for ui, sg in zip(u, sigs)) for c in chans})
                lim = 0.0
                for ru in rules.values():
                    q = sum(float(np.mean(lv[c] ** 2)) / b[c] ** 2 for c in ru["channels"])
                    lim = max(lim, math.sqrt(need * ru["R"] / q) if q > 0 else math.inf)
                lims.append(lim / math.sqrt(k))
            return lims
        u_lo, u_hi = np.asarray(unit_vec(dirs[i_lo])), np.asarray(unit_vec(dirs[i_hi]))
        lo_lim, hi_lim = min(own(u_lo)), max(own(u_hi))
    row.update(limit_rms_min=float(lo_lim), limit_rms_max=float(hi_lim),
               shape_min=unit_vec(dirs[i_lo]), shape_max=unit_vec(dirs[i_hi]))
    return row


def shape_limit(row: dict, delta) -> dict:
    """For a `detection_limits` shape row (an effect with several parameters of one unit) and a change ``delta`` of
    its parameters from their neutral values: the rms size of the smallest change of that shape whose own signal
    gains the rule's held-out (the larger over the rules: ``limit_rms``), ``delta``'s rms size, and their ratio
    (>= 1: the record shows it to first order; on a record that already carries it, >= 1 - MIN_GAIN for one
    channel)."""
    d = np.asarray(delta, float)
    size = float(np.linalg.norm(d))
    if size == 0.0:
        return {"limit_rms": math.inf, "size_rms": 0.0, "ratio": 0.0}
    u = d / size
    lim = 0.0
    for ru in row["rules"].values():
        g = float(u @ np.asarray(ru["Q"]) @ u)
        lim = max(lim, math.sqrt(row["need"] * ru["R"] / g) if g > 0 else math.inf)
    k = math.sqrt(d.size)
    return {"limit_rms": lim / k, "size_rms": size / k, "ratio": (size / lim) if lim > 0 else math.inf}


def _score(fr: FitResult, ref: dict, channels=None, judged: bool = False) -> float:
    rm = fr.judged if judged else fr.rmse
    return float(np.sqrt(np.mean([(rm[c]["holdout"] / max(ref[c], 1e-300)) ** 2 for c in (channels or ref)])))


def _bic(fr: FitResult, rho: dict) -> float:
    total, neff_all = 0.0, 0.0
    for c, sse in fr.sse_train.items():
        n = fr.n_train[c]
        ne = n * (1 - rho[c]) / (1 + rho[c])
        ne = min(max(ne, 2.0), float(n))
        total += ne * math.log(max(sse / n, 1e-300))
        neff_all += ne
    return total + fr.k * math.log(max(neff_all, 2.0))


# ----------------------------------------------------------------------------------------- workflow

def run_workflow(model_name: str, data, known: dict | None = None, holdout: float = 0.3,
                 split: str = "blocks", out_dir=None, effects=None, plots: bool = True,
                 params_where: str = "<params>", log=None, sample_convention: str | None = None,
                 sensor_noise: dict | None = None) -> dict:
    """Run the whole calibration loop on ``data`` (:class:`~shevsim.calibrate.data.MeasuredData`).

    ``sample_convention``: what a logged value stands for (:data:`shevsim.calibrate.timing.CONVENTIONS`: one for
    every channel, or ``CHANNEL=NAME[,...]`` for some, :func:`~shevsim.calibrate.timing.parse_conventions`;
    default ``data.sample_convention`` when the data carry one, else ``instantaneous``); ``sensor_noise``:
    ``{channel: noise}`` declared sensor noise (otherwise estimated, :func:`~shevsim.calibrate.timing.sensor_noise_floor`).
    Returns the report dictionary (also written to ``out_dir/report.json`` with ``report.md`` and plots
    when ``out_dir`` is given).  BLAS is limited to one thread during the run (via threadpoolctl when
    installed): the least-squares SVDs of tall, thin Jacobians are ~100x slower when BLAS threads fight
    over a shared machine's cores.
    """
    given = sample_convention or getattr(data, "sample_convention", None)
    conv = convention_text(parse_conventions(given))        # an unknown convention: a DataError naming it
    opts = {"sample_convention": conv, "sensor_noise": dict(sensor_noise or {}), "convention_declared": bool(given)}
    args = (model_name, data, known, holdout, split, out_dir, effects, plots, params_where, log, opts)
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # pragma: no cover - optional
        return _run_workflow(*args)
    with threadpool_limits(limits=1):
        try:
            return _run_workflow(*args)
        except (ArithmeticError, ValueError, np.linalg.LinAlgError) as exc:
            # a numerical failure on this record: keep the original message, name the model and the data
            raise DataError(f"{getattr(data, 'path', '<data>')}: calibration of model '{model_name}' failed: "
                            f"{type(exc).__name__}: {exc} (check the record's units and excitation)") from exc


class _Run:
    """The state of one calibration run shared by the workflow's steps."""

    def __init__(self, model_name, data, known, holdout, split, effects, params_where, log, opts):
        self.t_start = time.perf_counter()
        self.say = log or (lambda msg: None)
        self.model_name, self.data = model_name, data
        self.model = model = get_model(model_name, known, params_where)
        used = model.defaults_used()
        if used:
            by: dict = {}
            for d in used:
                by.setdefault(d["default"], []).append(d["parameter"])
            self.say("note: not in --params, the project's defaults are used (give your own): "
                     + "; ".join(f"{src}: {', '.join(ps)}" for src, ps in by.items()))
        if data.model != model_name:
            raise DataError(f"{data.path}: loaded for model '{data.model}', not '{model_name}'")
        self.t = data.df["time_s"].to_numpy(float)
        try:
            self.train, self.hold, self.split_info = make_split(self.t, holdout, split)
        except DataError as exc:
            if not str(exc).startswith("split leaves"):
                raise
            # a record too short (or decimated too far, or with a gap where the held-out blocks fall): say which
            raise DataError(f"{data.path}: {exc}: the record has {self.t.size} samples over {self.t[-1] - self.t[0]:g} s "
                            f"and a calibration needs at least 10 to fit and 10 held out (--holdout {holdout}, --split "
                            f"{split}); give a longer record (or a smaller --decimate)") from None
        self.fitter = Fitter(model, data, self.train, self.hold, opts["sample_convention"])
        self.opts = opts
        self.fitter.progress = log
        self.sensor_noise = opts["sensor_noise"]
        self.inputs = [c for c in model.inputs if c in data.df.columns]
        for c in self.sensor_noise:
            if c not in self.fitter.channels and c not in self.inputs:
                raise DataError(f"--sensor-noise {c}: not a channel or input of model '{model_name}' in this record "
                                f"(channels: {', '.join(self.fitter.channels)}; inputs: {', '.join(self.inputs)})")
        effs = self.fitter.effects
        self.names = list(effs) if effects is None else list(effects)
        for e in self.names:
            if e not in effs:
                held = model.known.get("effects_in_nominal") or {}
                why = (f"'{e}' is already part of the nominal model (its parameters are set in --params)"
                       if e in held else f"unknown effect '{e}' for model '{model_name}'")
                raise DataError(f"{why}; available: {', '.join(effs)}")
        self.implausible_candidates: list[dict] = []
        self.unsupported_candidates: list[dict] = []
        #: effects named on a significant direct measurement that the record's own check confirmed (assess): kept
        #: by the backward elimination, whose held-out rule they were not named by
        self.measured_confirmed: set[str] = set()
        #: effect -> {parameter: value}: the parameters an effect with a channel claim does not act on (its
        #: ``channel_claim``'s held ones), held at the values of the model it was added to (hold_for)
        self.claim_hold: dict[str, dict] = {}
        self.regs = model.regressors(self.fitter.ctx)
        for col in data.extra_columns:
            self.regs["measured:" + col] = data.df[col].to_numpy(float)

    def rho_of(self, fr):
        f = self.fitter
        return {c: float(np.clip(_acf(f.residual(fr, c)[self.train], 1)[0], 0.0, 0.999)) for c in f.channels}

    def diag(self, fr):
        out = {}
        for c in self.fitter.channels:
            r = self.fitter.residual(fr, c)
            out[c] = {part: diagnose(r[m], self.t[m], {k: v[m] for k, v in self.regs.items()})
                      for part, m in (("train", self.train), ("holdout", self.hold))}
        return out

    def baseline(self):
        """Fit the nominal model, reweight by its training RMSE, refit; the noise floors of the channels."""
        f = self.fitter
        base = f.fit(())
        f.weights = {c: 1.0 / max(base.rmse[c]["train"], 1e-12) for c in f.channels}
        base = f.fit((), start=base.params)
        self.say(f"baseline fitted ({f.nsim} simulations)")
        base.score = 1.0
        self.base = base
        self.ref = {c: base.rmse[c]["holdout"] for c in f.channels}
        self.ref_sel = {c: base.judged[c]["holdout"] for c in f.channels}
        quiet = self.model.quiet_mask(f.ctx)
        sensor = {c: sensor_noise_floor(f.meas[c], f.residual(base, c), quiet, self.sensor_noise.get(c))
                  for c in f.channels}
        # the measured inputs' noise carried through the model (timing.PropagatedInputNoise): with the sensor
        # floor, what a correct model cannot remove
        self.input_floors = {c: input_noise_floor(self.data.df[c].to_numpy(float), self.sensor_noise.get(c))
                             for c in self.inputs}
        self.propagation = PropagatedInputNoise(self.model, self.data,
                                                {c: v["value"] for c, v in self.input_floors.items()})
        prop = self.propagation.floor(f.simulate_in, base.params, base.pred, f.channels, self.hold)
        self.noise = {c: combined_floor(sensor[c], prop[c], self.propagation.method, self.input_floors,
                                        self.propagation.non_proportional.get(c, 0.0)) for c in f.channels}
        self.say("noise floors: " + ", ".join(
            f"{c} {_g(n['value'])} (sensor {_g(n['sensor']['value'])} {n['sensor']['method']}, inputs propagated "
            f"{_g(n['propagated_inputs']['value'])})" for c, n in self.noise.items()))
        return base

    def floor_at(self, fr) -> dict:
        """The channels' noise floors (sensor (+) propagated inputs) under the fitted model ``fr``."""
        f = self.fitter
        prop = self.propagation.floor(f.simulate_in, fr.params, fr.pred, f.channels, self.hold)
        return {c: math.hypot(self.noise[c]["sensor"]["value"] if math.isfinite(self.noise[c]["sensor"]["value"])
                              else 0.0, prop[c]) for c in f.channels}

    def assess(self, selected, effs, start, current, rho, cur_score, rnd, without=None):
        """Fit ``selected + effs`` and judge it against ``current`` by the selection rule.  ``without``: for a
        pair, ``{effect: the fit with the other effect alone}`` - each effect must add its own gain on its own
        channels to what the other one does.  An effect with a channel claim new to the model that does not pass
        with every parameter free is fitted and judged again with the parameters it does not act on held at
        ``current``'s values (:meth:`hold_for`); that version is kept when it passes (and then stays held)."""
        fr = self._judge(selected, effs, start, current, rho, cur_score, rnd, without, self.hold_for(selected, current))
        new = [e for e in effs if self.fitter.effects[e].channel_claim is not None and e not in self.claim_hold]
        if fr.passed or not new:
            return fr
        hold = self.hold_for(tuple(selected) + tuple(effs), current, new)
        held = self._judge(selected, effs, {**start, **hold}, current, rho, cur_score, rnd, without, hold)
        if not held.passed:
            return fr
        held.held = hold
        held.reason += (f" - with {', '.join(k for k in hold)} held at the current model's values (the law does not "
                        f"act on them); with them free: {fr.reason}")
        return held

    def _judge(self, selected, effs, start, current, rho, cur_score, rnd, without, hold):
        """:meth:`assess` for one set of held parameters."""
        f = self.fitter
        fr = f.fit(tuple(selected) + tuple(effs), start=start, max_nfev=CAND_NFEV, hold=hold)
        fr.score = _score(fr, self.ref)
        fr.bic = _bic(fr, rho)
        fr.dbic = fr.bic - current.bic
        fr.gain = 1.0 - fr.score / cur_score
        # an effect that cannot act on the channels the model-form terms come from (the cell: the voltage, whose
        # error's heat is the temperature's model-form term) is judged after those terms are fitted out: the
        # heat of the circuit's voltage error is nominal model form that a thermal-only effect must not take
        # for itself; an effect on the voltage is judged on the plain residuals (fixing the voltage fixes its
        # heat too)
        src = set().union(*getattr(self.model, "model_form_sources", {}).values()) if getattr(
            self.model, "model_form_sources", None) else set()
        sel = bool(src) and fr.rmse_sel is not None and any(not any(c in f.effects[e].channels for c in src)
                                                            for e in effs)   # (a pair: if one of them is such)
        ref = self.ref_sel if sel else self.ref
        rm, cm = (fr.judged, current.judged) if sel else (fr.rmse, current.rmse)
        if sel:
            fr.gain = 1.0 - _score(fr, ref, judged=True) / _score(current, ref, judged=True)
        fr.worsen = max(rm[c]["holdout"] / max(cm[c]["holdout"], 1e-300) - 1.0 for c in f.channels)
        eff_params = [p.name for e in effs for p in self.fitter.effects[e].params]
        measured, min_gain, weak, own, off_note = self._own_channel_gains(fr, current, effs, rm, cm, src, without)
        # an effect whose claim is verified on its own channel (Effect.channel_claim: its parameter significant
        # there, by a HAC standard error, and the joint fit's size) is measured there, as a directly measured
        # parameter is: any held-out gain confirms it (the other rules stay); tested only when it matters
        claimed = False
        if (not measured and 0.0 < fr.gain < MIN_GAIN and not weak
                and all(f.effects[e].channel_claim is not None for e in effs)):
            fr.claims = {e: self.channel_claim(e, fr, CLAIM_SIGNIFICANCE) for e in effs}
            claimed = all(x["ok"] for x in fr.claims.values())
            min_gain = 0.0 if claimed else min_gain
        why = []
        if fr.gain <= min_gain if (measured or claimed) else fr.gain < min_gain:
            why.append(f"held-out score gain {fr.gain:.1%} {'<=' if (measured or claimed) else '<'} {min_gain:.0%}"
                       + (" (its parameter measured directly)" if measured else "")
                       + (" (its claim verified on its channel)" if claimed else ""))
        elif weak:
            why.append(f"held-out gain on the channels the effect acts on < {min_gain:.0%} ({'; '.join(weak)})")
        if fr.worsen > MAX_WORSEN:
            why.append(f"a channel's held-out RMSE rises {fr.worsen:.1%}")
        # the BIC weighs an inferred parameter's complexity against the training fit over every channel; a
        # parameter the record measures directly and significantly (measured_params) is not inferred from the
        # residual: the held-out part decides (an out-of-sample PyBaMM Mohtat2020 record: the rests read
        # 0.09998 A, the offset cut the held-out voltage error 45 %, dBIC +61 - all of it from the temperature,
        # +2.3 % on a near-white residual that the BIC counts as 2314 effective samples against the voltage's 40);
        # the other channels keep the worsening rule, which a measured correction otherwise reads on its own only
        sig_measured = measured and all(f.measured[k2].get("significant", False) for k2 in eff_params)
        if fr.dbic > -MIN_DBIC and not sig_measured:
            why.append(f"dBIC {fr.dbic:+.1f} > -{MIN_DBIC:g}")
        if sig_measured:
            off = [c for c in f.channels if c not in own
                   and rm[c]["holdout"] > (1.0 + MAX_WORSEN) * cm[c]["holdout"]]
            if off:
                why.append("with the BIC rule waived for a measurement, no other channel may worsen by more than "
                           f"{MAX_WORSEN:.0%}: " + ", ".join(
                               f"{c} {rm[c]['holdout'] / cm[c]['holdout'] - 1.0:+.1%}" for c in off))
        # measured as zero: the record's own measurement says the effect is absent, whatever the fit gains
        absent = [k for k in eff_params if k in f.measured and not f.measured[k].get("significant", True)]
        halved = [] if weak else [c for c in (own or f.channels) if rm[c]["holdout"] <= HALVING * cm[c]["holdout"]]
        fr.passed = not absent and (not why or (bool(halved) and fr.worsen <= MAX_WORSEN))
        confirmed = None
        if (measured and not fr.passed and not absent
                and all(f.measured[k].get("significant", False) for k in eff_params if k in f.measured)):
            # measured directly and significant: the record's own check of its claim decides, not the fit under
            # load (CalibrationModel.measurement_confirmed); the held-out loss is then the model's form error
            full = self.model.full_values({k: v for k, v in fr.params.items() if k != "time_shift_s"})
            xs = [self.model.measurement_confirmed(e, f.ctx, full, f.meas) for e in effs]
            if xs and all(x is not None and x["ok"] for x in xs):
                confirmed = xs
                fr.passed = True
                fr.measured_confirmed = True
        if absent:
            why.insert(0, "measured as zero: " + "; ".join(
                f"{k} = {f.measured[k]['value']:.3g} +- {f.measured[k]['se']:.2g} from {f.measured[k]['how']}"
                for k in absent))
        bad = [x for e in effs for x in self.implausible(e, fr.params)]
        if fr.passed and bad:
            # it improves the fit only with parameters no cell / vehicle / engine has: not the explanation
            fr.passed = False
            fr.reason = "implausible: " + "; ".join(f"{x['parameter']} = {x['value']:.4g} {x['why']}" for x in bad)
            self.implausible_candidates.append({"effect": "+".join(effs), "round": rnd + 1, "evidence": bad,
                                                "holdout_gain": fr.gain})
            self.say(f"round {rnd + 1}: {'+'.join(effs)}: {fr.reason}")
            return fr
        if fr.passed and self._not_supported(fr, effs, rnd, current):
            return fr
        if not why and claimed:
            fr.reason = (f"passes: held-out score gain {fr.gain:.1%} > 0 with its claim verified on its channel ("
                         + "; ".join(x["statement"] for x in fr.claims.values())
                         + f"; the {MIN_GAIN:.0%} held-out gain is not needed for a law its channel measures)")
        elif not why:
            fr.reason = "passes" + (" (its parameter measured directly: "
                                    + "; ".join(f"{k} = {f.measured[k]['value']:.4g} from {f.measured[k]['how']}"
                                                for e in effs for k in (p.name for p in f.effects[e].params))
                                    + (f"; the refit of the declared parameters moves {off_note}" if off_note else "")
                                    + ("; the BIC rule is not applied to a significant measurement" if sig_measured
                                       else "")
                                    + ")" if measured else "")
        elif confirmed:
            fr.reason = ("passes: its parameter measured directly ("
                         + "; ".join(f"{k} = {f.measured[k]['value']:.4g} +- {f.measured[k]['se']:.2g} from "
                                     f"{f.measured[k]['how']}" for k in eff_params if k in f.measured)
                         + ") and confirmed at the record's relaxed rests (" + "; ".join(x["statement"] for x in confirmed)
                         + f"); the fit under load does not confirm it ({'; '.join(why)}): the model's form error had "
                         "compensated for it")
        elif fr.passed:
            # held-out evidence decides: the autocorrelation-corrected BIC has few effective samples
            # exactly when a systematic residual (a missing effect) makes the residual autocorrelated
            fr.reason = (f"passes: halves the held-out RMSE of {', '.join(halved)} (the BIC rule alone would "
                         f"veto: {'; '.join(why)})")
        else:
            fr.reason = "; ".join(why)
        self.say(f"round {rnd + 1}: {'+'.join(effs)}: score {fr.score:.3f} gain {fr.gain:+.1%} dBIC {fr.dbic:+.1f} "
                 f"{'PASS' if fr.passed else ''}")
        return fr

    def _own_channel_gains(self, fr, current, effs, rm, cm, src, without):
        """The gain of each effect of ``effs`` on the channels it acts on (``Effect.evidence``, default its
        channels); whether its parameters are measured directly; returns ``(measured, min_gain, weak, own,
        off_note)`` and, for a measured correction, limits ``fr.worsen`` to its own channels."""
        f = self.fitter
        # the effect must explain the residual of the channels it acts on: a gain that shows only on other
        # channels comes from the refit of the declared parameters (the nominal's compromise between
        # channels coupled through them, e.g. the heat of a circuit whose resistances bend to a voltage
        # model-form error), not from the effect
        # (for a pair: each effect on its own channels, over the fit with the other effect alone)
        # an effect whose parameters the record measures directly is not inferred from the residual: any held-out
        # gain confirms it (the BIC and worsening rules stay)
        eff_params = [p.name for e in effs for p in f.effects[e].params]
        measured = bool(eff_params) and all(k in f.measured for k in eff_params)
        min_gain = 0.0 if measured else MIN_GAIN
        own_all, weak = set(), []
        for e in effs:
            own = [c for c in f.channels if c in (f.effects[e].evidence or f.effects[e].channels)]
            own_all.update(own)
            if own and len(own) < len(f.channels):
                se = bool(src) and fr.rmse_sel is not None and not any(c in f.effects[e].channels for c in src)
                re_ = self.ref_sel if se else self.ref
                g = 1.0 - _score(fr, re_, own, se) / _score(current, re_, own, se)
                if without and e in without:     # and over the other effect of the pair alone
                    g = min(g, 1.0 - _score(fr, re_, own, se) / _score(without[e], re_, own, se))
                # (an effect whose claim is tested on its own channel alone, Effect.channel_claim, is judged by
                # that test instead: a real law can be below what the held-out part resolves against the
                # model's form there, and still be what the channel shows)
                if (g < MIN_GAIN if not measured else g <= 0.0) and f.effects[e].channel_claim is None:
                    weak.append(f"{e} on {', '.join(own)} {g:.1%}")
        own = [c for c in f.channels if c in own_all]
        off_note = ""
        if measured and own:
            # a measured correction is applied, not inferred: what it worsens on channels it does not act on is
            # the refit of the declared parameters (their compromise with those channels' model form)
            off = {c: rm[c]["holdout"] / max(cm[c]["holdout"], 1e-300) - 1.0 for c in f.channels if c not in own}
            fr.worsen = max(rm[c]["holdout"] / max(cm[c]["holdout"], 1e-300) - 1.0 for c in own)
            off_note = "; ".join(f"{c} {v:+.1%}" for c, v in off.items() if v > MAX_WORSEN)
        return measured, min_gain, weak, own, off_note

    def _not_supported(self, fr, effs, rnd, current=None) -> bool:
        """True (and ``fr`` marked not passed, with the reason) when what an effect of ``effs`` claims does not
        show on the record itself."""
        f = self.fitter
        # what the effect claims must show on the record itself, not only as a better fit
        # (CalibrationModel.effect_evidence: e.g. a cooling change must change the cell's own rate of
        # heat loss per kelvin at the fitted time)
        full = self.model.full_values({k: v for k, v in fr.params.items() if k != "time_shift_s"})
        base = (self.model.full_values({k: v for k, v in current.params.items() if k != "time_shift_s"})
                if current is not None else None)
        ev = [(e, x) for e in effs
              for x in [self.model.effect_evidence(e, f.ctx, full, f.meas, base=base) if f.effects[e].channel_claim is None
                        else (fr.claims or {}).get(e) or self.channel_claim(e, fr)] if x is not None and not x["ok"]]
        if ev:
            fr.passed = False
            fr.reason = "not supported by the record: " + "; ".join(x["statement"] for _, x in ev)
            self.unsupported_candidates.append({"effect": "+".join(effs), "round": rnd + 1, "holdout_gain": fr.gain,
                                                "evidence": [dict(x["evidence"], effect=e) for e, x in ev],
                                                "statement": fr.reason})
            self.say(f"round {rnd + 1}: {'+'.join(effs)}: {fr.reason}")
            return True
        return False

    def hold_for(self, effects, current, new=()) -> dict:
        """The parameters held in a fit of ``effects``: for each effect with a channel claim selected in its held
        version (:meth:`assess`, ``claim_hold``) or named in ``new`` (a candidate's held version), the parameters
        it does not act on (``Effect.channel_claim``'s held ones: the thermal ones under the cell's Arrhenius law)
        at the values of the model it was added to (``current`` for a candidate).  Why: an electrical law reaches the
        temperature only through the heat of the resistances it changes; with the thermal parameters free, the
        joint fit trades the law against the temperature's model-form error (the PyBaMM Arrhenius record: Ea/R
        2662 K, held-out voltage +12.7 %, temperature -35 %; held: 1598 K, truth 1413 K)."""
        out = {}
        for e in effects:
            cc = self.fitter.effects[e].channel_claim
            if cc is None:
                continue
            held = self.claim_hold.get(e)
            if held is None and e in new:
                held = {k: float(current.params[k]) for k in cc[1] if k in current.params}
            out.update(held or {})
        return out

    def keep_hold(self, effects, fr) -> None:
        """``effects`` were selected with ``fr``: when ``fr`` is a held version (:meth:`assess`), the parameters
        their channel claims hold stay at these values while they are selected."""
        if not fr.held:
            return
        for e in effects:
            cc = self.fitter.effects[e].channel_claim
            if cc is not None and e not in self.claim_hold:
                self.claim_hold[e] = {k: float(fr.held[k]) for k in cc[1] if k in fr.held}

    def channel_claim(self, e, fr, sigma: float = CLAIM_SIGMA):
        """The claim of ``e`` tested on its own channel alone (``Effect.channel_claim``): e.g. "the resistances
        follow exp(Ea/R (1/T - 1/T_ref))" is a claim about the voltage; the temperature it also moves (through
        the circuit's heat, whose form is uncertain) cannot support it.  Its parameter is refitted on that
        channel alone from the candidate fit.  It must be significant there - more than ``sigma`` standard errors
        above its neutral value: ``CLAIM_SIGMA`` (one-sided 5 %) where the claim can veto a candidate that passed the
        held-out rule, ``CLAIM_SIGNIFICANCE`` (3) where a verified claim waives the held-out gain (a HAC standard error, :meth:`Fitter.channel_only`, the
        electrical parameters free to trade against it) - and agree with the joint estimate: within a factor
        ``CLAIM_FACTOR``, or the joint value within ``CLAIM_SIGMA`` standard errors.  Why a factor and not only
        the interval: the interval is the statistical spread under a right model form, and the voltage's form
        is never exact, so it comes out narrower than the disagreement a real law leaves between the channels;
        a factor 2 is the same order of magnitude, about the spread of activation energies between a cell's
        own resistances (ohmic vs charge transfer), which one lumped law stands for.  A law that only bends
        the heat refits on the voltage near 0, or not at all, or to another size.  The effect's confounders
        (``Effect.claim_nuisance``) are refitted beside it within their claim-test bounds, from each of their
        given starts (and, when the model has them already, from their fitted values), the lowest cost kept;
        their values are in the evidence.  When the claim fails beside them but holds without them, the
        statement says the record cannot tell the two apart."""
        f = self.fitter
        eff = f.effects[e]
        channels, fixed = eff.channel_claim
        # the claim's confounders (Effect.claim_nuisance), refitted beside it with their claim-test bounds and
        # starts; one the model has already (selected, with the library's bounds) gets the claim-test bounds
        # too, from its fitted values as well as from the starts: either sign stays open
        use = [(n, b, st if n not in fr.effects else ({},) + tuple(st))
               for n, b, st in eff.claim_nuisance if n in f.effects]
        nuis = [(n, b) for n, b, _ in use]
        saved = dict(f.bounds_override)
        try:
            for _, b in nuis:
                f.bounds_override.update(b)
            best = None
            # every combination of the confounders' starts (one confounder: its starts), the lowest cost kept
            combos = [{}] if not use else [dict(kv for d in c for kv in d.items())
                                           for c in itertools.product(*[st for _, _, st in use])]
            for x0 in combos:
                got = f.channel_only(tuple(fr.effects) + tuple(n for n, _ in nuis if n not in fr.effects),
                                     {**fr.params, **x0}, channels, fixed)
                if best is None or f.last_channel_cost < best[2]:
                    best = (*got, f.last_channel_cost)
            vals, se, _cost = best
        finally:
            f.bounds_override = saved
        out = {"ok": True, "evidence": {}, "statement": ""}
        out["ok"], why = self._claim_verdict(eff, fr, vals, se, channels, out["evidence"], sigma)
        if nuis:
            out["evidence"].update({k: float(vals[k]) for n, _ in nuis for k in f.effects[n].neutral})
            def _nv(k, b):
                lo, hi = b.get(k, (float("-inf"), float("inf")))
                on = any(abs(vals[k] - x) <= 1e-6 * (hi - lo) for x in (lo, hi) if math.isfinite(x))
                return f"{k} {vals[k]:.3g}" + (" at its bound" if on else "")
            why.append("beside " + ", ".join(n for n, _ in nuis) + " (" + ", ".join(
                _nv(k, b) for n, b in nuis for k in f.effects[n].neutral) + ")")
        confounded = False
        if nuis and not out["ok"]:
            # without its confounders would the channel show the law?  Then the record cannot tell the two apart
            v0, se0 = f.channel_only(fr.effects, fr.params, channels, fixed)
            ev0 = {}
            confounded, why0 = self._claim_verdict(eff, fr, v0, se0, channels, ev0, sigma)
            out["evidence"].update({f"without_confounders_{k}": x for k, x in ev0.items()})
            out["evidence"]["not_separable"] = confounded
            if confounded:
                why.append(", ".join(("with " + n + " within its library bounds") if n in fr.effects else ("without " + n)
                                     for n, _ in nuis) + ": " + "; ".join(why0))
        out["statement"] = "; ".join(why) + ("" if out["ok"] else (
            f" (needed: > {sigma:g} standard errors and within a factor {CLAIM_FACTOR:g} of the joint fit): "
            + (f"{', '.join(channels)} alone shows the law only where {', '.join(n for n, _ in nuis)} could be the "
               f"cause: the record cannot tell them apart (they trend together over it); a record that moves one "
               f"without the other (a rest or a cool-down at another state, pulses at two temperatures) can"
               if confounded else
               f"{', '.join(channels)} alone does not show the law: it bends the model to another channel's "
               f"model-form error")))
        self.say(f"{e}: " + out["statement"])
        return out

    def _claim_verdict(self, eff, fr, vals, se, channels, evidence, sigma: float = CLAIM_SIGMA):
        """``(ok, why)`` of a channel claim refitted to ``vals`` (standard errors ``se``) against the joint fit
        ``fr`` (:meth:`channel_claim`); fills ``evidence``.  A refitted value on its bound is said so (its
        standard error, from a one-sided optimum, means nothing there)."""
        ok_all, why = True, []
        for p in eff.params:
            lo, hi = self.fitter.bounds_override.get(p.name, (p.lo, p.hi))
            joint, own, s = float(fr.params[p.name]), float(vals[p.name]), float(se.get(p.name, float("nan")))
            at = ("lower" if abs(own - lo) <= 1e-6 * (hi - lo) else
                  "upper" if abs(own - hi) <= 1e-6 * (hi - lo) else "")
            neutral = float(eff.neutral.get(p.name, 0.0))
            sig = math.isfinite(s) and own - neutral > sigma * s
            same = (own - neutral) * (joint - neutral) > 0 and (
                abs(math.log((own - neutral) / (joint - neutral))) <= math.log(CLAIM_FACTOR)
                or abs(own - joint) <= CLAIM_SIGMA * s)
            ok = sig and same
            ok_all = ok_all and ok
            evidence.update({f"{p.name}_joint": joint, f"{p.name}_{'_'.join(channels)}_only": own,
                             f"{p.name}_se": s})
            size = (f"at its {at} bound {lo if at == 'lower' else hi:.4g} {p.unit}" if at
                    else f"{own:.4g} +- {s:.2g} {p.unit}")
            why.append(f"{p.name} refitted on {', '.join(channels)} alone is {size} (joint fit "
                       f"{joint:.4g})" + ("" if ok else (" - not significant" if not sig else " - not the joint value")))
        return ok_all, why

    def pairs(self, results, selected, current, rho, cur_score, rnd):
        """No single effect passes: pairs of the PAIR_TOP candidates with the best held-out gain, fitted together
        (two effects can each fix part of the residual while spoiling another part)."""
        top = [e for e, fr in sorted(results, key=lambda x: x[1].score) if fr.gain > 0.0][:PAIR_TOP]
        single = dict(results)
        out = []
        for a_i in range(len(top)):
            for b_i in range(a_i + 1, len(top)):
                a, b = top[a_i], top[b_i]
                st = dict(current.params)
                for e in (a, b):
                    st.update({p.name: single[e].params[p.name] for p in self.fitter.effects[e].params})
                out.append(((a, b), self.assess(selected, (a, b), st, current, rho, cur_score, rnd,
                                                without={a: single[b], b: single[a]})))
        return out

    def at_noise_floor(self) -> list[str]:
        """Channels whose nominal held-out residual is within ``AT_NOISE`` x their *sensor* floor: nothing to explain.

        The sensor floor, not the combined one: the inputs' propagated noise is the model's own response to
        its inputs, scaled by its parameters (the vehicle's by the mass), and an effect of its size is
        systematic where that noise is not - the held-out selection rule judges it (the FASTSim payload, 22 %
        mass, leaves the nominal at 1.4x the combined floor and is named with a 27 % held-out gain)."""
        return [c for c in self.fitter.channels
                if self.noise[c]["sensor"]["value"] > 0
                and self.base.rmse[c]["holdout"] <= AT_NOISE * self.noise[c]["sensor"]["value"]]

    def select(self):
        """Greedy forward selection (module docstring, step 5).  An effect acting only on channels already at
        their noise floor is not a candidate: there is no residual for it to explain."""
        f = self.fitter
        current, selected, rounds, first_round, first_results = self.base, [], [], [], []
        quiet = set(self.at_noise_floor())
        self.skipped = [e for e in self.names if set(f.effects[e].channels) and set(f.effects[e].channels) <= quiet]
        for e in self.skipped:
            self.say(f"{e}: not a candidate (acts only on {', '.join(f.effects[e].channels)}, already at the noise floor)")
        remaining = [e for e in self.names if e not in self.skipped]
        for rnd in range(MAX_ROUNDS):
            if not remaining:
                break
            rho = self.rho_of(current)
            current.bic = _bic(current, rho)
            cur_score = _score(current, self.ref)
            results = [(e, self.assess(selected, (e,), current.params, current, rho, cur_score, rnd))
                       for e in remaining]
            rounds.append({"round": rnd + 1, "on_top_of": list(selected), "current_score": cur_score,
                           "candidates": [_cand_json(e, fr, f.channels) for e, fr in results]})
            if rnd == 0:
                first_round = rounds[0]["candidates"]
                first_results = results
            ok = [((e,), fr) for e, fr in results if fr.passed and math.isfinite(fr.score)]
            if not ok and not selected and len(remaining) >= 2:
                pairs = self.pairs(results, selected, current, rho, cur_score, rnd)
                rounds[-1]["pairs"] = [_cand_json("+".join(k), fr, f.channels) for k, fr in pairs]
                ok = [(k, fr) for k, fr in pairs if fr.passed and math.isfinite(fr.score)]
            if not ok:
                break
            # a measurement before an inference: a passing effect whose parameters the record measures directly and
            # significantly (a current offset read in the rests) is selected before the inferred ones of its round,
            # which are then judged on top of it (an out-of-sample PyBaMM Ai2020 record: the rests read 0.1001 A,
            # and a capacity 15 % high scored 1.7 points better than the offset and was named in its place)
            meas = [(k, fr) for k, fr in ok if self.significant_measured(k)]
            pool = meas or ok
            best_score = min(fr.score for _, fr in pool)
            near = [(k, fr) for k, fr in pool if fr.score <= best_score * (1 + TIE)]
            k, fr = min(near, key=lambda x: (len(x[0]), x[1].bic))
            k, fr = self.parsimonious(k, fr, pool)
            if meas and len(meas) < len(ok):
                self.say(f"{'+'.join(k)} before the inferred candidates of round {rnd + 1}: its parameters are "
                         f"measured by the record")
            self.keep_hold(k, fr)
            if fr.measured_confirmed or self.significant_measured(k):
                # selected on its measurement: the backward elimination, the exchange and the bound screen keep it
                self.measured_confirmed.update(k)
            selected.extend(k)
            rounds[-1]["selected"] = "+".join(k)
            current = fr
            for e in k:
                remaining.remove(e)
        if selected:
            selected, current = self.exchange(selected, current, first_results, rounds)
        self.rounds, self.first_round = rounds, first_round
        return selected, current

    def significant_measured(self, effs) -> bool:
        """Whether every parameter of the effects ``effs`` is measured directly by the record and significant
        (``CalibrationModel.measured_params``)."""
        ps = [p.name for e in effs for p in self.fitter.effects[e].params]
        return bool(ps) and all(self.fitter.measured.get(k, {}).get("significant", False) for k in ps)

    def parsimonious(self, k, fr, ok):
        """The round's winner ``(k, fr)``, or the passing candidate of ``ok`` with the fewest parameters that no
        candidate with more parameters beats by ``MIN_GAIN``: extra parameters must earn their held-out gain
        over a simpler explanation, as every effect must over the model it is added to (an OCV correction's
        five knots stretch the SOC axis as a capacity does: on the Ecker2015 capacity record it scored 0.616
        against the capacity's 0.677, 9 % better, and was named in its place)."""
        npar = lambda ks: sum(len(self.fitter.effects[e].params) for e in ks)   # noqa: E731
        unbeaten = [(k2, fr2) for k2, fr2 in ok if npar(k2) < npar(k)
                    and not any(npar(k3) > npar(k2) and fr3.score <= (1.0 - MIN_GAIN) * fr2.score for k3, fr3 in ok)]
        if not unbeaten:
            return k, fr
        k2, fr2 = min(unbeaten, key=lambda x: (npar(x[0]), x[1].score))
        self.say(f"{'+'.join(k2)} ({npar(k2)} parameter(s), score {fr2.score:.3f}) before {'+'.join(k)} "
                 f"({npar(k)}, score {fr.score:.3f}): no candidate with more parameters is {MIN_GAIN:.0%} better")
        return k2, fr2

    def exchange(self, selected, current, first_results, rounds):
        """One exchange pass after the forward selection (stepwise selection's swap): a round-1 candidate that
        gained at least ``MIN_GAIN`` but did not pass replaces a selected effect when the exchanged model passes
        the selection rule against the selection.  Forward selection is greedy: an effect chosen first (e.g.
        an initial SOC taking up an OCV hysteresis's offset, on a record whose temperature the model cannot
        follow yet) can keep the right one out for good."""
        f = self.fitter
        pool = [e for e, fr in first_results if e not in selected and not fr.passed and fr.gain >= MIN_GAIN
                and math.isfinite(fr.score)]
        tried = []
        for cand in pool:
            rho = self.rho_of(current)
            current.bic = _bic(current, rho)
            cur_score = _score(current, self.ref)
            best = None
            for old in [x for x in selected if x not in self.measured_confirmed]:   # a measurement stays
                rest = [x for x in selected if x != old]
                own = {p.name for p in f.effects[old].params}
                start = {k: v for k, v in current.params.items() if k not in own}
                fr = self.assess(rest, (cand,), start, current, rho, cur_score, len(rounds))
                tried.append(dict(_cand_json(f"{cand} for {old}", fr, f.channels), exchange={"in": cand, "out": old}))
                if (fr.passed and math.isfinite(fr.score) and fr.score < cur_score
                        and (best is None or fr.score < best[1].score)):
                    best = (old, fr, tried[-1])
            if best is not None:
                old, fr, row = best
                self.say(f"exchange: {cand} replaces {old} (held-out score {cur_score:.3f} -> {fr.score:.3f})")
                selected = [x for x in selected if x != old] + [cand]
                self.claim_hold.pop(old, None)
                self.keep_hold((cand,), fr)
                current = fr
                row["selected"] = True
        if tried:
            rounds.append({"round": len(rounds) + 1, "on_top_of": list(selected), "exchange": True,
                           "current_score": _score(current, self.ref), "candidates": tried})
        return selected, current

    def finish(self, selected, current):
        """Refit the selection to convergence; backward elimination of effects made redundant by later ones."""
        f = self.fitter
        final = current
        if selected:
            final = f.fit(tuple(selected), start=current.params, hold=self.hold_for(selected, current))
            final.score = _score(final, self.ref)
        dropped = []
        while len(selected) >= 2:
            trials = []
            for e in [x for x in selected if x not in self.measured_confirmed]:
                rest = tuple(x for x in selected if x != e)
                own = {p.name for p in f.effects[e].params}
                fr = f.fit(rest, start={k: v for k, v in final.params.items() if k not in own},
                           hold=self.hold_for(rest, final))
                fr.score = _score(fr, self.ref)
                worse = max(fr.rmse[c]["holdout"] / max(final.rmse[c]["holdout"], 1e-300) - 1.0 for c in f.channels)
                trials.append((fr.score, e, fr, worse))
            if not trials:
                break
            score, e, fr, worse = min(trials, key=lambda x: x[0])
            if score <= final.score * (1.0 + DROP_TOL) and worse <= DROP_TOL:
                self.say(f"backward elimination: dropping {e} (held-out score {final.score:.3f} -> {score:.3f})")
                selected.remove(e)
                self.claim_hold.pop(e, None)
                dropped.append({"effect": e, "score_with": final.score, "score_without": score})
                final = fr
            else:
                break
        return final, dropped

    def implausible(self, effect: str, values: dict) -> list[dict]:
        """Parameters of ``effect`` on a bound or outside their plausible range (the evidence)."""
        f = self.fitter
        out = []
        for prm in f.effects[effect].params:
            v = values.get(prm.name)
            if v is None or prm.name in f.measured:     # held at its direct measurement: its bounds are that
                continue
            lo, hi = f.bounds_override.get(prm.name, (prm.lo, prm.hi))
            pos = _bound_position(prm, v, lo, hi)
            if pos <= BOUND_TOL or pos >= 1.0 - BOUND_TOL:
                out.append({"parameter": prm.name, "value": v, "unit": prm.unit,
                            "why": f"on its {'lower' if pos <= BOUND_TOL else 'upper'} bound [{lo:.4g}, {hi:.4g}]"})
            elif prm.plausible is not None and not (prm.plausible[0] <= v <= prm.plausible[1]):
                out.append({"parameter": prm.name, "value": v, "unit": prm.unit,
                            "why": f"outside its plausible range [{prm.plausible[0]:.4g}, {prm.plausible[1]:.4g}]"})
        return out

    def screen_discrepancy(self, selected, final):
        """Selected effects whose parameters are implausible are not the explanation: removed, refitted,
        reported as a model-form discrepancy with the evidence."""
        out = []
        for e in list(selected):
            ev = self.implausible(e, final.params)
            if not ev:
                continue
            rest = tuple(x for x in selected if x != e)
            without = self.fitter.fit(rest, start={k: v for k, v in final.params.items()
                                                   if k not in {p.name for p in self.fitter.effects[e].params}},
                                      hold=self.hold_for(rest, final))
            without.score = _score(without, self.ref)
            out.append({"effect": e, "evidence": ev, "holdout_score_with": final.score,
                        "holdout_score_without": without.score,
                        "statement": f"'{e}' improved the fit only with {', '.join(x['parameter'] + ' ' + x['why'] for x in ev)}: "
                                     f"read as a model-form discrepancy, not as the cause"})
            self.say(f"model-form discrepancy: {out[-1]['statement']}")
            selected.remove(e)
            self.claim_hold.pop(e, None)
            final = without
        return final, out

    #: how far past its bound a declared parameter is tried (a fraction of its range, in the fit's scale)
    BEYOND_STEP = 0.05

    def _on_bounds(self, fr, held=()):
        """The declared parameters of ``fr`` on a bound (not measured, not in ``held``): ``(param, value, lo, hi,
        upper?)``, the bounds those the fit ran in."""
        f = self.fitter
        for prm in self.model.declared:
            v = fr.params.get(prm.name)
            if v is None or prm.name in f.measured or prm.name in held:
                continue
            lo, hi = f.bounds_override.get(prm.name, (prm.lo, prm.hi))
            pos = _bound_position(prm, v, lo, hi)
            if BOUND_TOL < pos < 1.0 - BOUND_TOL:
                continue
            yield prm, v, lo, hi, pos >= 1.0 - BOUND_TOL

    def binding_bounds(self, fr, held=()) -> list[dict]:
        """The declared parameters of ``fr`` (the nominal's own freedom: an efficiency scale, the circuit's
        factors) that sit on a bound the record pushes against: with the parameter moved ``BEYOND_STEP`` of its
        range past the bound (the others as fitted) the autocorrelation-corrected BIC falls by at least
        ``MIN_DBIC`` - the same evidence every effect must give.  A parameter on a bound the record does not push
        against (a fast RC branch whose time constant is below the sample period) is not binding."""
        f = self.fitter
        rho = self.rho_of(fr)
        b0 = _bic(fr, rho)
        out = []
        for prm, v, lo, hi, up in self._on_bounds(fr, held):
            sgn = 1.0 if up else -1.0
            if prm.log:
                if not (lo > 0.0 and hi > 0.0):
                    continue
                v2 = math.exp(math.log(v) + sgn * self.BEYOND_STEP * (math.log(hi) - math.log(lo)))
            else:
                v2 = v + sgn * self.BEYOND_STEP * (hi - lo)
            try:
                fr2 = f.evaluate(fr.effects, {**fr.params, prm.name: v2}, fr.k)
            except (ShevsimError, ArithmeticError, ValueError):
                continue
            d = _bic(fr2, rho) - b0
            if math.isfinite(d) and d <= -MIN_DBIC:
                out.append({"parameter": prm.name, "value": float(v), "unit": prm.unit,
                            "bound": "upper" if up else "lower", "beyond": float(v2), "dbic_beyond": float(d)})
        return out

    #: a declared parameter with physical limits past its bounds (``Param.limits``) that sits on a bound is freed
    #: this fraction of its declared range past it (at most to its limits) for the profile (:meth:`screen_declared_bounds`)
    PROFILE_WIDEN = 0.5

    def declared_at_bound(self, fr, held=()) -> list[tuple]:
        """The declared parameters of ``fr`` with physical limits past their bounds (``Param.limits``) that sit on
        a bound (not held, not measured): ``(param, upper?, (lo, hi), (lo', hi'))``, the bound on that side moved
        ``PROFILE_WIDEN`` of the range past it, at most to the limit."""
        out = []
        for prm, _v, lo, hi, up in self._on_bounds(fr, held):
            if prm.limits is None:
                continue
            nb = _widened(prm, up, lo, hi, self.PROFILE_WIDEN)
            if nb != (lo, hi):
                out.append((prm, up, (lo, hi), nb))
        return out

    def screen_declared_bounds(self, selected, final):
        """The nominal's own declared parameters on a bound: the nominal cannot follow the record within its
        declared freedom, and an effect selected beside them may stand in for that.

        Declared parameters whose bounds are a plausibility guard inside physical limits (``Param.limits``: a
        vehicle's motor efficiency scales) are *profiled*: their bounds are moved ``PROFILE_WIDEN`` of the range
        past them (:meth:`declared_at_bound`), the selection is refitted, and its physical effects are eliminated
        backwards there - the one whose removal costs least, while that costs no more than ``DROP_TOL`` of
        held-out score (the backward elimination's tolerance).  An effect so removed only stood in for the
        declared freedom (the Bolt's no-effect record with its published efficiency curve x 0.88: a mass 6 % low
        took the push the scale could not follow; one parameter probed past its bound alone, :meth:`binding_bounds`,
        did not see it, the mass had taken the push): removed and reported as a model-form discrepancy with the
        evidence.  An effect the record still needs with the declared parameters free stays (the Bolt's payload
        record with the curve x 0.84: the one-at-a-time probe removed every physical effect and reported the true
        payload as a discrepancy).  When the profile's fit takes a declared parameter past its declared bound and
        beats the fit held within it by ``MIN_DBIC``, it is the final model (the effects' parameters are the
        record's, not the bound's: the Bolt payload with the curve x 0.88 gave 1801 kg held at the bound, 1923 kg
        free, truth 1926 kg), and the report says the declared parameter left its declared range: the given map
        is not this record's.  A measurement and a timing effect (the logger, not the model) are not judged;
        timing is screened again on a refit.  Declared parameters without such limits (the cell's circuit and
        thermal factors, whose bounds span decades) keep the probe of :meth:`binding_bounds`
        (:meth:`_remove_beside_pinned`).  Returns ``(final, discrepancy)``."""
        held = tuple(self.hold_for(selected, final))
        at = self.declared_at_bound(final, held)
        pinned = self.binding_bounds(final, held=held)
        profiled = {prm.name for prm, *_ in at}
        if any(b["parameter"] not in profiled for b in pinned) or not at:
            return self._remove_beside_pinned(selected, final, pinned)
        return self._profile_bounds(selected, final, at, pinned)

    def _profile_bounds(self, selected, final, at, pinned):
        """:meth:`screen_declared_bounds` for the declared parameters ``at`` (:meth:`declared_at_bound`)."""
        f = self.fitter
        keep = [e for e in selected if e == "timing" or e in self.measured_confirmed]
        phys = [e for e in selected if e not in keep]
        removed = []
        saved = dict(f.bounds_override)
        try:
            for prm, _up, _old, nb in at:
                f.bounds_override[prm.name] = nb
            cur = tuple(selected)
            top = f.fit(cur, start=final.params, hold=self.hold_for(cur, final))
            top.score = _score(top, self.ref)
            while phys:
                trials = []
                for e in phys:
                    rest = tuple(x for x in cur if x != e)
                    own = {p.name for p in f.effects[e].params}
                    fr = f.fit(rest, start={k: v for k, v in top.params.items() if k not in own},
                               hold=self.hold_for(rest, final))
                    fr.score = _score(fr, self.ref)
                    trials.append((fr.score / max(top.score, 1e-300) - 1.0, e, fr))
                cost, e, fr = min(trials, key=lambda x: x[0])
                if cost > DROP_TOL:
                    break
                removed.append({"effect": e, "cost": cost, "score_with": top.score, "score_without": fr.score,
                                "declared_without": {prm.name: float(fr.params[prm.name]) for prm, *_ in at}})
                phys.remove(e)
                cur = tuple(x for x in cur if x != e)
                top = fr
        finally:
            widened = dict(f.bounds_override)
            f.bounds_override = saved
        # still on a bound of the profile: the record asks for more than even that freedom - the given quantity is
        # not this record's at all (a map of another motor: the Bolt given the project's truck map, whose scale
        # went to the profile's limit with a drag 5 % low beside it), so the profile cannot say which effect is
        # real: every physical effect beside it is a discrepancy (:meth:`_remove_beside_pinned`)
        rho = self.rho_of(final)
        still = []
        for prm, up, old, nb in at:
            v = float(top.params[prm.name])
            if not BOUND_TOL < _bound_position(prm, v, *nb) < 1.0 - BOUND_TOL:
                still.append({"parameter": prm.name, "value": v, "unit": prm.unit,
                              "bound": "upper" if _bound_position(prm, v, *nb) >= 0.5 else "lower",
                              "beyond": v, "declared_range": list(old), "profile_range": list(nb),
                              "dbic_beyond": float(_bic(top, rho) - _bic(final, rho))})
        if still:
            self.say("the profile's fit is on the profiled bound too: " + ", ".join(
                f"{b['parameter']} {b['value']:.4g}" for b in still))
            return self._remove_beside_pinned(selected, final, pinned or still)
        gone = {r["effect"] for r in removed}
        rest = tuple(e for e in selected if e not in gone)
        if gone:
            own = {p.name for e in gone for p in f.effects[e].params}
            bounded = f.fit(rest, start={k: v for k, v in final.params.items() if k not in own},
                            hold=self.hold_for(rest, final))
            bounded.score = _score(bounded, self.ref)
        else:
            bounded = final
        rho = self.rho_of(bounded)
        dbic_past = _bic(top, rho) - _bic(bounded, rho)
        outside = [(prm, up, old) for prm, up, old, _nb in at if not old[0] <= float(top.params[prm.name]) <= old[1]]
        # the profile's fit is the final one only where an effect is named beside it: its parameters are then the
        # record's, not the guard's (the Bolt's payload with the curve x 0.88: 1923 kg free, 1801 kg held).  With
        # none named - nothing selected, or every effect removed as a stand-in - the final model stays within the
        # nominal's declared ranges and the profile is stated with its numbers: the declared freedom past the guard
        # is then one explanation among the candidates that did not pass (the Leaf's payload records: the two
        # efficiency scales take the payload's inertial power, regen 1.17 and 1.14, dBIC -108 and -32, where the
        # mass alone has dBIC -158 and -135 - and on payload_2 the profile's fit is worse on the held-out part,
        # 1551 W against 1539 W).  (The ninth session adopted it when effects had been selected going in, so the
        # Bolt's no-effect record x 0.88 ended past the guard and the Leaf's payload on it; a reviewer's finding,
        # and a second reviewer's against adopting it everywhere: it put the wrong physics in the final model.)
        adopt = bool(rest) and bool(outside) and dbic_past <= -MIN_DBIC
        new_final = top if adopt else bounded
        if adopt:
            # the declared range as the profile extended it: the report's bounds are the ones the final was fitted in
            for prm, *_ in at:
                f.bounds_override[prm.name] = widened[prm.name]
        out = []
        if adopt or pinned or (outside and dbic_past <= -MIN_DBIC):
            what = ", ".join(f"{prm.name} = {float(final.params[prm.name]):.4g} on its {'upper' if up else 'lower'} "
                             f"declared bound {old[1] if up else old[0]:.4g}" for prm, up, old, _nb in at)
            probe = ("; a step past it alone: " + ", ".join(f"{b['parameter']} dBIC {b['dbic_beyond']:+.0f}"
                                                            for b in pinned)) if pinned else ""
            if adopt:
                taken = ", ".join(f"{prm.name} {float(top.params[prm.name]):.4g}" for prm, _up, _old in outside)
                kept = [p.name for e in rest if e in f.effects for p in f.effects[e].params if p.name in top.params]
                tail = (f"; profiled up to {self.PROFILE_WIDEN:.0%} of the declared range past the bound, the record "
                        f"takes it past: {taken} (dBIC {dbic_past:+.0f} against the fit held within the declared "
                        f"range), and that fit is the final one" + (
                            " (" + ", ".join(f"{k} = {float(top.params[k]):.4g}" for k in kept)
                            + f"; {', '.join(f'{k} = {float(bounded.params[k]):.4g}' for k in kept)} with the "
                            f"bound held)" if kept else "") + (
                            "; no physical effect is named beside it, and a candidate that did not pass may explain "
                            "part of the same (its evidence is in the candidates)" if not set(rest) - set(keep) else ""))
            elif outside and dbic_past <= -MIN_DBIC:
                tail = (f"; profiled up to {self.PROFILE_WIDEN:.0%} of the declared range past the bound, the record "
                        f"takes it past (" + ", ".join(f"{prm.name} {float(top.params[prm.name]):.4g}"
                                                        for prm, _up, _old in outside)
                        + f", dBIC {dbic_past:+.0f} against the fit held within the declared range, held-out score "
                        f"{top.score:.3f} against {bounded.score:.3f}); not adopted: no effect is named beside it, the "
                        f"final model keeps the declared range, and a candidate that did not pass may explain the "
                        f"same (the evidence below)")
            else:
                tail = ""
            out.append({"declared_on_bound": [
                {"parameter": prm.name, "value": float(final.params[prm.name]), "unit": prm.unit,
                 "bound": "upper" if up else "lower", "declared_range": list(old),
                 "profiled_value": float(top.params[prm.name]), "dbic_past": float(dbic_past)}
                for prm, up, old, _nb in at] + [dict(b, probe=True) for b in pinned],
                "statement": (f"the nominal's declared {what}{probe}: the record asks for more than the nominal's "
                              f"declared freedom allows - its form or a given quantity (a map, a table) is not this "
                              f"record's{tail}")})
        for r in removed:
            e = r["effect"]
            dv = ", ".join(f"{k} {v:.4g}" for k, v in r["declared_without"].items())
            out.append({"effect": e, "evidence": [{"parameter": prm.name, "value": float(final.params[prm.name]),
                                                   "bound": "upper" if up else "lower", "profile_bounds": list(nb)}
                                                  for prm, up, _old, nb in at]
                        + [{"removal_cost_with_bounds_free": r["cost"], "declared_without_it": r["declared_without"]}],
                        "holdout_score_with": final.score, "holdout_score_without": new_final.score,
                        "statement": f"'{e}' was selected while the nominal's declared "
                                     f"{', '.join(prm.name for prm, *_ in at)} sat on a bound: with them free past it "
                                     f"({dv}) the record no longer needs it (removing it costs {r['cost']:+.1%} of "
                                     f"held-out score, <= {DROP_TOL:.0%}) - it stood in for the declared freedom the "
                                     f"nominal lacks, a model-form discrepancy, not the cause (removed; held-out score "
                                     f"{final.score:.3f} with it, {new_final.score:.3f} without)"})
        return self._drop_said(selected, [r["effect"] for r in removed], out, new_final)

    def _drop_said(self, selected, gone, out, fit):
        """Remove the effects ``gone`` from ``selected`` (and their held parameters), say the discrepancies ``out``,
        and screen a remaining timing effect again on ``fit`` (the refit without them): ``(fit, out)``."""
        for e in gone:
            selected.remove(e)
            self.claim_hold.pop(e, None)
        for x in out:
            self.say(f"model-form discrepancy: {x['statement']}")
        if gone and "timing" in selected:
            fit, again = self.screen_timing(selected, fit)
            out += again
        return fit, out

    def _remove_beside_pinned(self, selected, final, pinned):
        """Declared parameters without physical limits past their bounds (``Param.limits``: the cell's circuit and
        thermal factors, whose bounds span decades) held by a bound the record pushes against
        (:meth:`binding_bounds`): the nominal cannot follow the record within its declared freedom, so an effect
        that passes on top of it may stand in for that (the rule was made on a vehicle given without its motor map,
        whose efficiency scales are profiled since: :meth:`_profile_bounds`).  The physical effects selected are
        removed, refitted without, and reported as a model-form discrepancy
        with the evidence; a timing effect (the logger, not the model) stays.  Returns ``(final, discrepancy)``."""
        if not pinned:
            return final, []
        what = ", ".join(f"{b['parameter']} = {b['value']:.4g} on its {b['bound']} bound (dBIC {b['dbic_beyond']:+.0f} "
                         f"past it)" for b in pinned)
        # a measurement (a sensor offset read in the rests) is not inferred beside the declared parameters: it stays;
        # so does a timing effect (the logger, not the model), rescreened on the refit
        keep = [e for e in selected if e == "timing" or e in self.measured_confirmed]
        phys = [e for e in selected if e not in keep]
        with_effects = " with the selected effects" if phys else ""
        out = [{"declared_on_bound": pinned, "statement": (
            f"the nominal's declared {what}{with_effects}: the record asks for more than the nominal's declared "
            f"freedom allows - its form or a given quantity (a map, a table) is not this record's")}]
        if not phys:
            self.say(f"model-form discrepancy: {out[0]['statement']}")
            return final, out
        own = {p.name for e in phys for p in self.fitter.effects[e].params}
        rest = tuple(keep)
        without = self.fitter.fit(rest, start={k: v for k, v in final.params.items() if k not in own},
                                  hold=self.hold_for(rest, final))
        without.score = _score(without, self.ref)
        for e in phys:
            out.append({"effect": e, "evidence": pinned, "holdout_score_with": final.score,
                        "holdout_score_without": without.score,
                        "statement": f"'{e}' was selected while the nominal's declared "
                                     f"{', '.join(b['parameter'] for b in pinned)} sat on a bound the record pushes "
                                     f"against: the nominal cannot follow the record within its declared freedom, and "
                                     f"the effect may stand in for that - read as a model-form discrepancy, not as "
                                     f"the cause (removed; held-out score {final.score:.3f} with it, "
                                     f"{without.score:.3f} without)"})
        return self._drop_said(selected, phys, out, without)

    def screen_timing(self, selected, final):
        """A selected time shift must be the main explanation of what it repairs: a logger latency is a pure
        shift, so on a model of the right form it takes the residual (of the model without it) most of the
        way down to the noise floor.  When it removes no more than ``TIMING_SHARE`` of that residual's
        variance above the noise floor on every channel, the shift is only bending the model towards dynamics
        of another form (a faster or slower plant): removed, refitted, and reported as a model-form
        discrepancy with the evidence - never as timing."""
        if "timing" not in selected:
            return final, []
        f = self.fitter
        rest = tuple(x for x in selected if x != "timing")
        without = f.fit(rest, start={k: v for k, v in final.params.items() if k != "time_shift_s"},
                        hold=self.hold_for(rest, final))
        without.score = _score(without, self.ref)
        share = {}
        for c in f.channels:
            # the combined floor: a pure shift cannot remove the inputs' noise carried through the model either,
            # so a latency on a model of the right form takes the residual down to that floor, not below it
            nf = self.noise[c]["value"]
            nf2 = nf * nf if math.isfinite(nf) and nf > 0 else 0.0
            e0 = max(without.rmse[c]["holdout"] ** 2 - nf2, 0.0)
            e1 = max(final.rmse[c]["holdout"] ** 2 - nf2, 0.0)
            share[c] = 1.0 - e1 / e0 if e0 > 0 else 0.0
        if max(share.values()) > TIMING_SHARE:
            return final, []
        shift = float(final.params.get("time_shift_s", 0.0))
        ev = [{"parameter": "time_shift_s", "value": shift, "unit": "s",
               "why": "removes only " + ", ".join(f"{v:.0%} of {c}'s held-out residual variance above the noise floor"
                                                  for c, v in share.items())}]
        out = [{"effect": "timing", "evidence": ev, "holdout_score_with": final.score,
                "holdout_score_without": without.score,
                "statement": f"a time shift of {shift:+.3g} s improves the held-out fit, but removes only "
                             f"{max(share.values()):.0%} (<= {TIMING_SHARE:.0%}) of the residual variance above "
                             f"the noise floor: a logger latency would take it to the noise; the record's "
                             f"dynamics differ in form from the model's (model-form discrepancy, not timing)"}]
        self.say(f"model-form discrepancy: {out[0]['statement']}")
        selected.remove("timing")
        return without, out

    def verdicts(self, diag_before, diag_after, final):
        """Unexplained residuals and baseline failures, against the channels' noise floors: sensor (+) inputs
        propagated (the nominal's for the baseline, the final model's after the effects)."""
        f = self.fitter
        unexplained, failure = [], []
        after = self.floor_at(final) if final is not self.base else {c: self.noise[c]["value"] for c in f.channels}
        for c in f.channels:
            nf = self.noise[c]["value"]
            nfa = after[c]
            dh = diag_after[c]["holdout"]
            top = dh["correlations"][0] if dh["correlations"] else None
            if nfa > 0 and dh["rmse"] > 3.0 * nfa and (not dh["white"]):
                unexplained.append({"channel": c, "holdout_rmse": dh["rmse"], "noise_floor": nfa,
                                    "noise_floor_method": self.noise[c]["method"],
                                    "bias": dh["bias"], "drift_per_hour": dh["drift_per_hour"], "top_correlation": top,
                                    "note": "residual well above the noise floor and not white: structure the "
                                            "selected model does not explain"})
            db = diag_before[c]["holdout"]
            ratio = db["rmse"] / nf if nf > 0 else float("inf")
            # the sensor floor does not depend on the nominal; the propagated part does (a wrong nominal's own
            # amplification of the input noise: the 15.5 t truck on a car's record, 8.7x its combined floor at
            # 790x the sensor's), so a residual SENSOR_FAILURE_RATIO x the sensor floor fails whatever the model
            sf = self.noise[c]["sensor"]["value"]
            ratio_s = db["rmse"] / sf if math.isfinite(sf) and sf > 0 else float("nan")
            rules = ([f"> {BASELINE_FAILURE_RATIO:g}x the combined noise floor"] if ratio > BASELINE_FAILURE_RATIO
                     else []) + ([f">= {SENSOR_FAILURE_RATIO:g}x the sensor noise floor"]
                                 if ratio_s >= SENSOR_FAILURE_RATIO else [])
            if rules:
                ratio_s_after = dh["rmse"] / sf if math.isfinite(sf) and sf > 0 else float("nan")
                failure.append({
                    "channel": c, "holdout_rmse": db["rmse"], "noise_floor": nf,
                    "noise_floor_method": self.noise[c]["method"], "ratio_to_noise_floor": ratio,
                    "sensor_noise_floor": sf,
                    "propagated_input_floor": self.noise[c]["propagated_inputs"]["value"],
                    "ratio_to_sensor_floor": ratio_s, "rules": rules,
                    "bias": db["bias"], "drift_per_hour": db["drift_per_hour"],
                    "correlated_signals": db["correlations"][:4], "likely_causes": self.model.likely_causes(c, db, self.data),
                    "fixed_by_selected_effects": bool(dh["rmse"] <= BASELINE_FAILURE_RATIO * max(nfa, 1e-300)
                                                      and not ratio_s_after >= SENSOR_FAILURE_RATIO),
                    "noise_floor_after": nfa, "ratio_after": dh["rmse"] / nfa if nfa > 0 else float("inf"),
                    "ratio_to_sensor_floor_after": ratio_s_after})
        for b in failure:
            self.say(f"baseline failure: {b['channel']} held-out RMSE {b['holdout_rmse']:.4g} = "
                     f"{b['ratio_to_noise_floor']:.1f}x the combined noise floor ({b['noise_floor_method']}), "
                     f"{b['ratio_to_sensor_floor']:.0f}x the sensor floor ({'; '.join(b['rules'])}); likely: "
                     f"{'; '.join(b['likely_causes'][:2])}")
        return unexplained, failure

    def close_loop(self, selected, final, out_dir):
        """The overlay in the component's own parameters, replayed through the simulator (step 7)."""
        f, model = self.fitter, self.model
        full_final = model.full_values({k: v for k, v in final.params.items() if k != "time_shift_s"})
        own_tmp = out_dir is None
        odir = Path(tempfile.mkdtemp(prefix="shevsim_calibration_")) if own_tmp else Path(out_dir)
        odir.mkdir(parents=True, exist_ok=True)
        replay, overlay = None, None
        try:
            overlay = model.overlay(full_final, odir)
            write_overlay(odir / "params.toml", overlay, meta={
                "source": f"shevsim calibrate {self.model_name} {self.data.path}",
                "selected_effects": ", ".join(selected) or "none",
                "use": "shevsim run SCENARIO --params params.toml (path of this file; each table goes to the "
                       "component of that name, or --params COMPONENT=params.toml for one table)"})
            # the logger's timing (convention, fitted shift) belongs to the record, not the component
            pred = shift_prediction(model.replay(self.data, odir / "params.toml"), self.t, f.shift_of(final.params))
            replay = {}
            for c in f.channels:
                r = pred[c] - f.meas[c]
                rt, rh = r[self.train], r[self.hold]
                replay[c] = {"train": float(np.sqrt(np.mean(rt * rt))), "holdout": float(np.sqrt(np.mean(rh * rh)))}
            self.say("replay through the simulator: " + ", ".join(
                f"{c} held-out {replay[c]['holdout']:.4g} (fit {final.rmse[c]['holdout']:.4g})" for c in replay))
        except NotImplementedError:
            replay = None
        except ShevsimError as exc:       # e.g. the replayed plant leaves its range (SOC < 0): said, not hidden
            replay = {"error": f"the replay through the simulator stopped: {exc}"}
            self.say(replay["error"])
        finally:
            if own_tmp:
                import shutil
                shutil.rmtree(odir, ignore_errors=True)   # our own temporary folder, nothing of the user's
        return replay, overlay

    def bounds_and_identifiability(self, selected, final):
        """Fitted parameters on a bound and the local identifiability of every fitted parameter."""
        f = self.fitter
        at_bounds = []
        for prm in f._params_for(tuple(selected)):
            lo, hi = f.bounds_override.get(prm.name, (prm.lo, prm.hi))
            v = final.params.get(prm.name)
            if v is None or prm.name in f.measured:
                continue
            pos = _bound_position(prm, v, lo, hi)
            if pos <= BOUND_TOL or pos >= 1.0 - BOUND_TOL:
                at_bounds.append({"parameter": prm.name, "value": v, "bound": "lower" if pos <= BOUND_TOL else "upper",
                                  "bounds": [lo, hi], "unit": prm.unit})
        ident = identifiability(f, tuple(selected), final.params)
        for d in ident:      # a directly measured parameter: identified by its measurement, not by the fit
            if d["parameter"] in f.measured:
                d["identifiable"], d["measured"] = True, f.measured[d["parameter"]]
        by_name = {d["parameter"]: d for d in ident}
        for b in at_bounds:
            b["identifiable"] = by_name.get(b["parameter"], {}).get("identifiable")
            self.say(f"parameter {b['parameter']} = {b['value']:.4g} {b['unit']} sits on its {b['bound']} bound: not "
                     f"identifiable from this record (or the bound is wrong)")
        for d in ident:
            if not d["identifiable"]:
                self.say(f"parameter {d['parameter']} is not identifiable from this record: its 1-sigma uncertainty "
                         f"is {d['se_frac']:.3g} of its bound range (> {IDENT_SE_MAX:g}); the record does not excite it"
                         + (f" or it trades off against {d['partner']['parameter']} (r = {d['partner']['correlation']:+.2f})"
                            if d["partner"] else ""))
        return at_bounds, ident


BOUND_TOL = 1e-3
TRADE_GAIN = 0.02       # a candidate gaining less than this held-out ...
TRADE_AWAY = 0.05       # ... with its parameter this far from neutral, the declared ones moved 2x: said, not named
TIMING_SHARE = 0.5      # a kept time shift removes more than half of the residual variance above the noise floor
AT_NOISE = 1.5          # a channel whose nominal held-out residual is <= 1.5x its noise floor (variance <= 2.25x) has nothing to explain


def _widened(prm: Param, up: bool, lo: float, hi: float, frac: float) -> tuple[float, float]:
    """The bounds ``(lo, hi)`` with the upper (``up``) or lower one moved ``frac`` of the range past it, at most to
    ``prm.limits``; for a parameter fitted in logs the range and the move are ratios (a linear move could reach 0 or
    below, where its log is not defined: the bound then stays positive whatever the limit)."""
    if prm.log and lo > 0.0:
        r = (hi / lo) ** frac
        return (lo, min(hi * r, prm.limits[1])) if up else (max(lo / r, prm.limits[0]), hi)
    w = frac * (hi - lo)
    return (lo, min(hi + w, prm.limits[1])) if up else (max(lo - w, prm.limits[0]), hi)


def _bound_position(prm: Param, v: float, lo: float, hi: float) -> float:
    """Position of ``v`` between the bounds, 0..1 (log scale where the parameter is fitted in logs)."""
    span = (math.log(hi) - math.log(lo)) if prm.log else (hi - lo)
    if span <= 0:
        return 0.5
    return ((math.log(max(v, 1e-300)) - math.log(lo)) if prm.log else (v - lo)) / span


def _run_workflow(model_name, data, known, holdout, split, out_dir, effects, plots, params_where, log, opts):
    run = _Run(model_name, data, known, holdout, split, effects, params_where, log, opts)
    base = run.baseline()
    selected, current = run.select()
    final, dropped = run.finish(selected, current)
    final, discrepancy = run.screen_discrepancy(selected, final)
    final, timing_discrepancy = run.screen_timing(selected, final)
    discrepancy += timing_discrepancy
    final, bound_discrepancy = run.screen_declared_bounds(selected, final)
    discrepancy += bound_discrepancy
    # one statement per effect (a candidate is assessed with its parameters free and held: the better gain said)
    seen: dict = {}
    for c in run.implausible_candidates:
        if c["round"] == 1 and c["holdout_gain"] >= MIN_GAIN and c["effect"] not in selected:
            if c["effect"] not in seen or c["holdout_gain"] > seen[c["effect"]]["holdout_gain"]:
                seen[c["effect"]] = c
    for c in seen.values():
        discrepancy.append({**c, "statement": f"'{c['effect']}' would improve the held-out fit by {c['holdout_gain']:.0%} "
                            f"but only with {', '.join(x['parameter'] + ' = ' + format(x['value'], '.4g') + ' ' + x['why'] for x in c['evidence'])}: "
                            f"a model-form discrepancy, not this effect"})
    # an effect that must show on declared channels (Effect.evidence) and fits the training part there but not
    # the held-out part: the record does not resolve it against the model's form (said, with the numbers)
    for c in run.first_round:
        eff = run.fitter.effects.get(c["name"])
        if eff is None or not eff.evidence or c["name"] in selected or c["passed"]:
            continue
        for ch in (x for x in eff.evidence if x in base.rmse):
            tr = c["train_rmse"][ch] / max(base.rmse[ch]["train"], 1e-300) - 1.0
            ho = c["holdout_rmse"][ch] / max(base.rmse[ch]["holdout"], 1e-300) - 1.0
            if tr <= -MIN_GAIN / 2 and ho > -MIN_GAIN:
                own = {k: v for k, v in c["parameters"].items() if k in {p.name for p in eff.params}}
                discrepancy.append({"effect": c["name"], "evidence": [{"channel": ch, "train_change": tr,
                                                                        "holdout_change": ho, **own}],
                                    "statement": f"'{c['name']}' ({', '.join(f'{k} = {v:.4g}' for k, v in own.items())}) "
                                                 f"lowers the training {ch} residual by {-tr:.0%} but changes the "
                                                 f"held-out one by {ho:+.0%}: the record does not resolve it against "
                                                 f"the model's form on {ch}, where it must show (not named)"})
    # an effect fitted well away from its neutral value with next to no held-out gain, while the declared
    # parameters moved far to make room for it: on this record it cannot be told from them - neither named nor
    # excluded (a new user's trial, PyBaMM Marquis2019 with 12 % lost capacity: the capacity fitted at 0.615 A.h,
    # 2.7 % from the truth, gained 0.2 % - the baseline had stretched its slow RC branch, r2_scale 3.15 and c2_scale
    # 35.0, which went to 0.85 and 0.29 with it; the report said nothing of it).  Only effects whose every parameter
    # is an amplitude with a nonzero neutral value (a capacity, a mass, a coefficient: a shape parameter of an
    # effect that is off means nothing), and only declared parameters not on a bound in the baseline, moved by a
    # factor 2 or more (in logs for a log-fitted one)
    base_declared = {p.name: p for p in run.model.declared}
    on_bound = {prm.name for prm, *_ in run._on_bounds(base)}
    for c in run.first_round:
        eff = run.fitter.effects.get(c["name"])
        if eff is None or c["name"] in selected or c["passed"] or abs(c["gain"]) >= TRADE_GAIN:
            continue
        own = [(p, c["parameters"].get(p.name), float(eff.neutral.get(p.name, 0.0))) for p in eff.params]
        if any(v is None or n == 0.0 or not math.isfinite(n) for _p, v, n in own):
            continue
        away = [(p, v, n) for p, v, n in own if abs(v / n - 1.0) >= TRADE_AWAY]
        if not away:
            continue
        moved = []
        for k, prm in base_declared.items():
            b, v = base.params.get(k), c["parameters"].get(k)
            if b is None or v is None or k in on_bound or not (b > 0.0 and v > 0.0):
                continue
            if abs(math.log(v / b)) >= math.log(2.0):
                moved.append((k, b, v))
        if not moved:
            continue
        what = ", ".join(f"{p.name} = {v:.4g} ({v / n - 1.0:+.1%} from the nominal's {n:.4g})" for p, v, n in away)
        dv = ", ".join(f"{k} {b:.3g} -> {v:.3g}" for k, b, v in moved)
        discrepancy.append({"effect": c["name"], "evidence": [{"parameter": p.name, "value": v, "neutral": n}
                                                               for p, v, n in away]
                            + [{"declared_moved": {k: [b, v] for k, b, v in moved}, "holdout_gain": c["gain"]}],
                            "statement": f"'{c['name']}' fitted at {what} changes the held-out score by "
                                         f"{c['gain']:+.1%} while the nominal's declared parameters move to make room "
                                         f"({dv}): on this record it cannot be told from them - neither named nor "
                                         f"excluded (a record that separates them - a long rest, another current "
                                         f"profile - can)"})
    for c in run.unsupported_candidates:
        if c["round"] == 1 and c["effect"] not in selected:
            discrepancy.append({"effect": c["effect"], "evidence": c["evidence"],
                                "statement": f"'{c['effect']}' would improve the held-out fit by {c['holdout_gain']:.0%}, "
                                             f"but {c['statement']}: a model-form discrepancy, not this effect"})
    diag_before, diag_after = run.diag(base), run.diag(final)
    unexplained, baseline_failure = run.verdicts(diag_before, diag_after, final)
    for b in baseline_failure:
        if not b["fixed_by_selected_effects"]:
            discrepancy.append({"channel": b["channel"], "evidence": [{"ratio_to_noise_floor_after": b["ratio_after"],
                                                                      "ratio_to_sensor_floor_after":
                                                                          b["ratio_to_sensor_floor_after"]}],
                                "statement": f"{b['channel']}: the held-out residual stays {b['ratio_after']:.1f}x the "
                                             f"noise floor ({b['ratio_to_sensor_floor_after']:.0f}x the sensor floor) "
                                             f"after the selected effects: the model's form does not "
                                             f"explain this record (read any selected effect as a partial repair)"})
    replay, overlay = run.close_loop(selected, final, out_dir)
    at_bounds, ident = run.bounds_and_identifiability(selected, final)
    report = _report(run, selected, final, dropped=dropped, discrepancy=discrepancy, diag_before=diag_before,
                     diag_after=diag_after, unexplained=unexplained, baseline_failure=baseline_failure,
                     replay=replay, overlay=overlay, at_bounds=at_bounds, ident=ident, out_dir=out_dir)
    try:
        held = {k for e in selected for k in (run.claim_hold.get(e) or {})}
        pushed = {b.get("parameter") for d in discrepancy for b in (d.get("declared_on_bound") or [])}
        report["detection_limits"] = detection_limits(run.fitter, selected, final, run.ref,
                                                      skip=[e for e in run.fitter.effects if e not in run.names],
                                                      held=held, pushed=pushed)
    except (ArithmeticError, ValueError, np.linalg.LinAlgError) as exc:   # a statement of the report, not the result
        report["detection_limits"] = []
        report["detection_error"] = f"{type(exc).__name__}: {exc}"
    try:        # the knots' shapes on their own: a failure there does not take the limits above with it
        shapes: list = []
        detection_limits(run.fitter, selected, final, run.ref, skip=[e for e in run.fitter.effects
                                                                     if e not in run.names],
                         held=held, pushed=pushed, shapes=shapes, only_shapes=True)
        report["detection_shapes"] = shapes
    except (ArithmeticError, ValueError, np.linalg.LinAlgError) as exc:
        report["detection_shapes"] = []
        report["detection_shapes_error"] = f"{type(exc).__name__}: {exc}"
    report["detection_rule"] = {"min_holdout_gain": MIN_GAIN, "finite_difference_step": DETECT_STEP,
                                "at": "the final model, to first order (secant over the limit)",
                                "refit": "declared and selected parameters (not measured or held; one on a bound "
                                         "moves inwards only, unless the record pushes past it)"}
    report["n_simulations"] = run.fitter.nsim
    report["elapsed_s"] = time.perf_counter() - run.t_start
    if out_dir is not None:
        write_report(Path(out_dir), report, run.fitter, base, final, run.t, plots)
    return report


def _report(run, selected, final, *, dropped, discrepancy, diag_before, diag_after, unexplained, baseline_failure,
            replay, overlay, at_bounds, ident, out_dir) -> dict:
    f, model, data, base = run.fitter, run.model, run.data, run.base
    replay_dev = (max(abs(replay[c][part] / max(final.rmse[c][part], 1e-300) - 1.0)
                      for c in replay for part in ("train", "holdout")) if replay and "error" not in replay else None)
    timing = {"sample_convention": f.sample_convention, "declared": bool(run.opts.get("convention_declared", True)),
              "channel_conventions": dict(f.conventions), "input_convention": f.input_convention,
              "model_convention": model.native_convention,
              "convention_offset_s": f.conv_offset, "sample_interval_s": f.dt,
              "time_shift_s": float(final.params.get("time_shift_s", 0.0)) if "timing" in selected else 0.0}
    return {
        "model": run.model_name,
        "data": {"path": data.path, "n_samples": int(run.t.size), "duration_s": float(run.t[-1] - run.t[0]),
                 "channels": f.channels, "notes": data.notes, "extra_columns": data.extra_columns},
        "known_parameters": {k: (list(v) if isinstance(v, tuple) else v) for k, v in model.known.items()},
        "defaults_used": model.defaults_used(),
        "split": run.split_info,
        "timing": timing,
        "noise_floor": run.noise,
        "selection_rule": {"min_holdout_gain": MIN_GAIN, "max_channel_worsening": MAX_WORSEN,
                           "min_bic_drop": MIN_DBIC, "tie_fraction": TIE, "bic": "autocorrelation-corrected",
                           "halving_passes": HALVING},
        "baseline_parameters": base.params,
        # the value each effect's parameter starts from (the effect off: the nominal's), the baseline of its row
        "effect_neutral": {k: float(v) for e in model.effects.values() for k, v in e.neutral.items()},
        "differentiated_inputs": list(getattr(model, "differentiated_inputs", ())),
        "measured_parameters": f.measured,
        "record_resolution": (model.record_resolution() if hasattr(model, "record_resolution") else {}),
        "selected_effects": selected,
        "final_parameters": final.params,
        "candidates": run.first_round,
        "rounds": run.rounds,
        "rmse_before": base.rmse,
        "rmse_after": final.rmse,
        "score_after": final.score,
        "diagnostics_before": diag_before,
        "diagnostics_after": diag_after,
        "unexplained": unexplained,
        "nothing_found": not selected,
        "dropped_by_backward_elimination": dropped,
        "not_candidates_at_noise_floor": {"effects": run.skipped, "channels": run.at_noise_floor(),
                                          "ratio": AT_NOISE},
        "model_form_discrepancy": discrepancy,
        "baseline_failure": baseline_failure,
        "parameters_at_bounds": at_bounds,
        "identifiability": ident,
        "not_identifiable": [d["parameter"] for d in ident if not d["identifiable"]],
        "identifiability_rule": {"se_frac_max": IDENT_SE_MAX, "finite_difference_step": IDENT_STEP},
        "overlay": {"file": "params.toml" if out_dir is not None else None, "component": model.component_name,
                    "tables": overlay},
        "replay": replay,
        "replay_max_relative_deviation": replay_dev,
        "n_simulations": f.nsim,
        "elapsed_s": time.perf_counter() - run.t_start,
    }


def _cand_json(name, fr: FitResult, channels) -> dict:
    return {"name": name, "effects": list(fr.effects),
            "parameters": {k: float(v) for k, v in fr.params.items()},
            "holdout_rmse": {c: fr.rmse[c]["holdout"] for c in channels},
            "train_rmse": {c: fr.rmse[c]["train"] for c in channels},
            "score": fr.score, "gain": fr.gain, "bic": fr.bic, "delta_bic": fr.dbic,
            "max_channel_worsening": fr.worsen, "passed": fr.passed, "reason": fr.reason}


# ------------------------------------------------------------------------------------------ report

def _savefig(fig, path: Path):
    import io
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90)
    atomic_write_bytes(path, buf.getvalue())


def write_report(out: Path, rep: dict, fitter: Fitter, base: FitResult, final: FitResult, t, plots=True):
    out.mkdir(parents=True, exist_ok=True)
    pngs = []
    if plots:
        from shevsim.plotting import headless_pyplot
        plt = headless_pyplot()
        step = max(1, t.size // 4000)
        ts = t[::step]
        chans = fitter.channels
        hold_iv = rep["split"]["holdout_intervals_s"]
        for kind in ("fit", "residuals"):
            fig, axes = plt.subplots(len(chans), 1, figsize=(10, 2.8 * len(chans)), sharex=True, squeeze=False)
            for ax, c in zip(axes[:, 0], chans):
                for a, b in hold_iv:
                    ax.axvspan(a, b, color="0.9", lw=0)
                if kind == "fit":
                    ax.plot(ts, fitter.meas[c][::step], "k", lw=0.8, label="measured")
                    ax.plot(ts, base.pred[c][::step], "C0", lw=0.8, label="model before")
                    ax.plot(ts, final.pred[c][::step], "C3", lw=0.8, ls="--", label="model after")
                else:
                    ax.plot(ts, fitter.residual(base, c)[::step], "C0", lw=0.6, label="residual before")
                    ax.plot(ts, fitter.residual(final, c)[::step], "C3", lw=0.6, label="residual after")
                    ax.axhline(0, color="k", lw=0.5)
                ax.set_ylabel(c)
                ax.legend(loc="best", fontsize=7)
            axes[-1, 0].set_xlabel("time_s (grey: held-out blocks)")
            fig.suptitle(f"{rep['model']}: {kind} before / after (selected: {', '.join(rep['selected_effects']) or 'none'})")
            fig.tight_layout()
            name = f"{kind}_before_after.png"
            _savefig(fig, out / name)
            plt.close(fig)
            pngs.append(name)
        rounds = rep["rounds"]
        if rounds:
            nrow = sum(len(rd["candidates"]) + len(rd.get("pairs", [])) for rd in rounds)
            fig, axes = plt.subplots(len(rounds), 1, figsize=(8, 0.4 * nrow + 1.0 * len(rounds) + 0.5), squeeze=False)
            for ax, rd in zip(axes[:, 0], rounds):
                cs = rd["candidates"] + rd.get("pairs", [])
                ax.barh([c["name"] for c in cs], [c["score"] for c in cs],
                        color=["C2" if c["passed"] else "C7" for c in cs])
                ax.axvline(rd["current_score"], color="k", lw=0.8, label="current model")
                ax.axvline(rd["current_score"] * (1.0 - MIN_GAIN), color="C3", ls="--", lw=0.8,
                           label=f"-{MIN_GAIN:.0%} threshold")
                ax.set_title(f"round {rd['round']} (on top of: {', '.join(rd['on_top_of']) or 'baseline'}; "
                             f"selected: {rd.get('selected', 'none')})", fontsize=8)
                ax.legend(fontsize=6, loc="lower right")
            axes[-1, 0].set_xlabel("combined held-out score (baseline = 1; lower is better; green = passes the rule)")
            fig.tight_layout()
            _savefig(fig, out / "evidence.png")
            plt.close(fig)
            pngs.append("evidence.png")
    rep["plots"] = pngs
    traces = _fit_traces(fitter, base, final, t, rep["split"]["holdout_intervals_s"])
    from ..core.atomic import write_csv_atomic
    write_csv_atomic(out / "fit_traces.csv", traces, index=False, float_format="%.7g")
    atomic_write_text(out / "report.json", json.dumps(rep, indent=2, default=float))
    atomic_write_text(out / "report.md", render_markdown(rep))
    if plots:                                   # the interactive report: fit, residuals, evidence, parameters
        from ..report.write import write_calibration_html
        write_calibration_html(out, rep, traces)


def _fit_traces(fitter: Fitter, base: FitResult, final: FitResult, t, hold_iv, max_points: int = 20000):
    """Measured and modelled channels before and after (``fit_traces.csv``: what the HTML report plots)."""
    import pandas as pd
    step = max(1, t.size // max_points)
    ts = np.asarray(t)[::step]
    cols = {"time_s": ts, "holdout": np.zeros(ts.size, dtype=bool)}
    for a, b in hold_iv:
        cols["holdout"] |= (ts >= a) & (ts <= b)
    for c in fitter.channels:
        cols[f"{c}_measured"] = np.asarray(fitter.meas[c])[::step]
        cols[f"{c}_before"] = np.asarray(base.pred[c])[::step]
        cols[f"{c}_after"] = np.asarray(final.pred[c])[::step]
    return pd.DataFrame(cols)


def _g(x):
    return f"{x:.4g}" if isinstance(x, (int, float)) and math.isfinite(x) else str(x)


def _md_timing_noise(rep: dict) -> list[str]:
    """The report's sample-timing and noise-floor lines."""
    L = []
    tm = rep.get("timing")
    if tm:
        off = tm["convention_offset_s"]
        off = (", ".join(f"`{c}` {o:+.3g} s" for c, o in off.items()) if isinstance(off, dict) else f"{off:+.3g} s")
        inp = tm.get("input_convention")
        L.append(f"Sample timing: the record is read as `{tm['sample_convention']}` ("
                 + ("declared" if tm.get("declared", True) else "the default: no --sample-convention was given")
                 + (f"; its driving input `{inp}`" if inp else "")
                 + f"; the model's prediction is `{tm['model_convention']}` from inputs taken at their sample "
                 f"times, read {off} later); "
                 f"sample interval {_g(tm['sample_interval_s'])} s; fitted time shift {_g(tm['time_shift_s'])} s "
                 f"(> 0: the output lags).")
    for c, nf in (rep.get("noise_floor") or {}).items():
        sn, pr = nf.get("sensor", nf), nf.get("propagated_inputs")
        line = (f"Noise floor of `{c}`: {_g(nf['value'])}" + (f" = sensor {_g(sn['value'])} (+) measured inputs "
                f"propagated through the model {_g(pr['value'])} (in quadrature)" if pr else "")
                + f". Sensor floor: {sn['method']} (estimates: "
                + ", ".join(f"{k} {_g(v)}" for k, v in sn["estimates"].items()) + ")")
        if pr:
            line += (f"; inputs: {pr['method']} (input floors: "
                     + (", ".join(f"{k} {_g(v['value'])} {v['method']}" for k, v in pr["inputs"].items()) or "none")
                     + ")")
        L.append(line + ".")
    from ..report.calibration_text import decimate_advice
    adv = decimate_advice(rep)
    if adv:
        L.append(f"**Advice:** {adv}")
    return L + [""]


def _md_evidence(rep: dict) -> list[str]:
    """The report's evidence: the selection rule, each round's candidates, the parameters, the residual
    diagnostics."""
    L = []
    r = rep["selection_rule"]
    L += ["", "## Evidence", "",
          f"Rule: held-out score gain >= {r['min_holdout_gain']:.0%}, no channel worse by > {r['max_channel_worsening']:.0%}, "
          f"autocorrelation-corrected BIC drop >= {r['min_bic_drop']:g}; or a held-out RMSE halved on some channel "
          f"with no channel worse by > {r['max_channel_worsening']:.0%}.  A parameter the record measures directly "
          f"and significantly: any held-out gain, no BIC rule, selected before the inferred candidates of its round.  "
          f"An effect selected while a declared parameter of the nominal sits on a bound the record pushes against "
          f"(the BIC falls by >= {r['min_bic_drop']:g} a step past it) is a model-form discrepancy.", ""]
    for rd in rep["rounds"]:
        L += [f"Round {rd['round']} (on top of: {', '.join(rd['on_top_of']) or 'baseline'}; current score "
              f"{rd['current_score']:.3f}; selected: {rd.get('selected', 'none')})", "",
              "| effect | held-out score | gain | dBIC | held-out RMSE | parameters | verdict |", "|---|---|---|---|---|---|---|"]
        for c in sorted(rd["candidates"], key=lambda c: c["score"]) + rd.get("pairs", []):
            hr = ", ".join(f"{k} {_g(v)}" for k, v in c["holdout_rmse"].items())
            own = {k: v for k, v in c["parameters"].items() if k not in rep["baseline_parameters"]}
            pr = ", ".join(f"{k}={_g(v)}" for k, v in own.items())
            L.append(f"| {c['name']} | {c['score']:.3f} | {c['gain']:+.1%} | {c['delta_bic']:+.1f} | {hr} | {pr} | {c['reason']} |")
        L.append("")
    from ..report.calibration_text import md_parameters
    L += md_parameters(rep, _g)
    L += ["", "## Residual diagnostics (held-out part)", "",
          "| channel | when | bias | RMSE | drift /h | acf lag 1 | Ljung-Box p | noise floor | top correlations |",
          "|---|---|---|---|---|---|---|---|---|"]
    for c in rep["diagnostics_before"]:
        for when, d in (("before", rep["diagnostics_before"][c]["holdout"]), ("after", rep["diagnostics_after"][c]["holdout"])):
            cr = ", ".join(f"{x['signal']} {x['r']:+.2f}" for x in d["correlations"][:3])
            L.append(f"| {c} | {when} | {_g(d['bias'])} | {_g(d['rmse'])} | {_g(d['drift_per_hour'])} | {d['acf'][0]:.3f} | "
                     f"{d['ljung_box_p']:.2g} | {_g(d['noise_floor'])} | {cr} |")
    return L


def render_markdown(rep: dict) -> str:
    L = [f"# Calibration report: model `{rep['model']}`", "",
         f"Data: `{rep['data']['path']}` ({rep['data']['n_samples']} samples, {rep['data']['duration_s']:.0f} s); "
         f"channels: {', '.join(rep['data']['channels'])}."]
    for n in rep["data"]["notes"]:
        L.append(f"- note: {n}")
    if rep.get("defaults_used"):
        by: dict = {}
        for d in rep["defaults_used"]:
            by.setdefault(d["default"], []).append(
                f"`{d['parameter']}` = {_g(d['value']) if isinstance(d['value'], float) else d['value']}")
        L += ["", "**Not in `--params`: the project's defaults were used** (a result is no better than the nominal it "
              "is given; give your own): " + "; ".join(f"{src}: {', '.join(v)}" for src, v in by.items()) + "."]
    sp = rep["split"]
    L += ["", f"Split: `{sp['method']}`, held-out fraction {sp['holdout_fraction']}, held-out intervals (s): "
          + ", ".join(f"{a:.0f}-{b:.0f}" for a, b in sp["holdout_intervals_s"])
          + f" ({sp['n_train']} training / {sp['n_holdout']} held-out samples).", ""]
    L += _md_timing_noise(rep)
    sel = rep["selected_effects"]
    L.append("## Result")
    L.append("")
    L.append(f"**Selected effects: {', '.join(sel)}**" if sel else
             "**Nothing found**: no candidate effect passed the selection rule.")
    L += ["", "| channel | RMSE before train | before held-out | after train | after held-out | held-out change |",
          "|---|---|---|---|---|---|"]
    for c, b in rep["rmse_before"].items():
        a = rep["rmse_after"][c]
        ch = a["holdout"] / b["holdout"] - 1 if b["holdout"] > 0 else float("nan")
        L.append(f"| {c} | {_g(b['train'])} | {_g(b['holdout'])} | {_g(a['train'])} | {_g(a['holdout'])} | {ch:+.1%} |")
    if rep.get("baseline_failure"):
        L += ["", "**The nominal model fails on this record** (fitted, its held-out error stays far above the "
              "noise floor; read the selected effects as a partial repair, not a diagnosis):"]
        for b in rep["baseline_failure"]:
            cs = ", ".join(f"`{x['signal']}` (r = {x['r']:+.2f})" for x in b["correlated_signals"][:3])
            L.append(f"- `{b['channel']}`: held-out RMSE {_g(b['holdout_rmse'])} = {b['ratio_to_noise_floor']:.1f}x the "
                     f"noise floor {_g(b['noise_floor'])}"
                     + (f" (sensor {_g(b['sensor_noise_floor'])} (+) inputs propagated {_g(b['propagated_input_floor'])})"
                        f", {b['ratio_to_sensor_floor']:.0f}x the sensor floor alone"
                        if "sensor_noise_floor" in b else "")
                     + (f" (fails: {'; '.join(b['rules'])})" if b.get("rules") else "")
                     + f"; most correlated with {cs or 'nothing'}; likely causes: "
                     + "; ".join(b["likely_causes"])
                     + (" (the selected effects bring it within range)" if b["fixed_by_selected_effects"] else ""))
    # a candidate refused or removed (its fit bends the model to an error of another form) is not the same news as
    # a residual the final model leaves (a new user read "not explained by any effect" beside a grade that took the
    # record's error from 3562 W to 740 W, and two implausible drag and rolling fits listed under it)
    mfd = rep.get("model_form_discrepancy") or []
    refused = [d for d in mfd if d.get("effect")]
    left = [d for d in mfd if not d.get("effect")]
    if refused:
        L += ["", "**Candidates refused or removed as explanations** (each fitted the record only by bending the model "
              "to an error of another form - outside its plausible range, its claim not shown by the record, or "
              "standing in for another freedom; the evidence):"]
        for d in refused:
            L.append(f"- {d['statement']}")
    if left:
        L += ["", "**Model-form discrepancy** (what the final model, with the selected effects, does not explain; the "
              "evidence):"]
        for d in left:
            L.append(f"- {d['statement']}")
    if rep.get("measured_parameters"):
        fp = rep.get("final_parameters") or {}

        def _applied(k, m):
            if k in fp:
                return f"in the final model: {_g(fp[k])}"
            return ("measured as zero: not applied" if not m.get("significant", True) else
                    "**not applied**: not in the final model or params.toml (the candidates' table, the backward "
                    "elimination and the discrepancy list say why)"
                    + (f"; {m['alternative']}" if m.get("alternative") else ""))
        L += ["", "Measured directly by the record (a candidate fit holds it within +-3 standard errors): " + "; ".join(
            f"`{k}` = {_g(m['value'])} (standard error {_g(m['se'])}) from {m['how']} - {_applied(k, m)}"
            for k, m in rep["measured_parameters"].items()) + "."]
    if (rep.get("record_resolution") or {}).get("statement"):
        L += ["", f"What the record resolves: {rep['record_resolution']['statement']}."]
    if rep.get("parameters_at_bounds"):
        L += ["", "Parameters that ended on a bound (not identifiable from this record, or the bound is wrong): "
              + ", ".join(f"`{b['parameter']}` = {_g(b['value'])} {b['unit']} ({b['bound']})"
                          for b in rep["parameters_at_bounds"]) + "."]
    if rep.get("not_identifiable"):
        by = {d["parameter"]: d for d in rep.get("identifiability", [])}
        L += ["", "**Not identifiable from this record** (1-sigma uncertainty > "
              f"{rep['identifiability_rule']['se_frac_max']:g} of the bound range; the value reported is not "
              "a measurement): " + ", ".join(
                  f"`{n}` (uncertainty {by[n]['se_frac']:.3g} of its range"
                  + (f", trades off against `{by[n]['partner']['parameter']}`" if by[n].get("partner") else "")
                  + ")" for n in rep["not_identifiable"]) + "."]
    dl = [d for d in rep.get("detection_limits") or [] if d.get("limit") is not None]
    if dl:
        L += ["", f"**What this record can detect, to first order** (for each one-parameter effect not selected, the "
              f"smallest change whose own signal would gain the rule's "
              f"{rep['detection_rule']['min_holdout_gain']:.0%} held-out - on the combined score and on its own "
              f"channels - with the fitted parameters refitted beside it; a true effect below it does not reach the "
              f"gain by its own signal, though a candidate can still pass by also fitting the model's form error): "
              + "; ".join(
                  (f"`{d['effect']}` {d['parameter']} +{_g(d['limit_up'])} / -{_g(d['limit_down'])} {d['unit']}"
                   if d.get("limit_up") and d.get("limit_down")
                   and abs(d["limit_up"] / d["limit_down"] - 1.0) > 0.05
                   else f"`{d['effect']}` {d['parameter']} "
                        + ("+-" if d.get("limit_up") and d.get("limit_down") else "+" if d.get("limit_up") else "-")
                        + f"{_g(d['limit'])} {d['unit']}")
                  + (f" ({d['relative']:.1%} of {_g(d['neutral'])})" if d.get("relative") is not None else "")
                  + ("" if d["reachable"] else ", beyond its plausible range")
                  + (", nonlinear (the tangent at the neutral value gave " + _g(d["tangent_limit"]) + ")"
                     if d.get("nonlinear") else "")
                  + (f", {d['absorbed_frac']:.0%} of its signal taken by the fitted parameters"
                     if d.get("absorbed_frac") is not None and d["absorbed_frac"] >= 0.5 else "")
                  for d in dl) + "."]
    shp = rep.get("detection_shapes") or []
    if shp:
        L += ["", "**Effects with several parameters of one unit** (knots; linear): the rms change of the knots whose "
              "own signal would gain the rule's held-out, from the effect's most visible shape to its least visible: "
              + "; ".join(f"`{d['effect']}` ({len(d['parameters'])} knots) {_g(d['limit_rms_min'])} {d['unit']} to "
                          + (f"{_g(d['limit_rms_max'])} {d['unit']}" if math.isfinite(d["limit_rms_max"])
                             else "never (a shape the record does not see, or that the fitted parameters take whole)")
                          + ("" if d.get("linear", True) else " (a fitted parameter on a bound: approximate)")
                          for d in shp) + "."]
    if rep.get("replay") and "error" in rep["replay"]:
        L += ["", f"Replay through the simulator: {rep['replay']['error']}"]
    elif rep.get("replay"):
        L += ["", f"Replay through the simulator (the `{rep['overlay']['component']}` component(s) stepped by the master "
              f"with the overlay `params.toml`; use it with `shevsim run SCENARIO --params params.toml`):", "",
              "| channel | fit train | replay train | fit held-out | replay held-out |", "|---|---|---|---|---|"]
        for c, r in rep["replay"].items():
            a = rep["rmse_after"][c]
            L.append(f"| {c} | {_g(a['train'])} | {_g(r['train'])} | {_g(a['holdout'])} | {_g(r['holdout'])} |")
        L.append(f"\nLargest relative deviation replay vs fit: {rep['replay_max_relative_deviation']:.2e}.")
    if rep["unexplained"]:
        L += ["", "Not explained by the selected model:"]
        for u in rep["unexplained"]:
            tc = u["top_correlation"]
            L.append(f"- `{u['channel']}`: held-out RMSE {_g(u['holdout_rmse'])} vs noise floor {_g(u['noise_floor'])}, "
                     f"bias {_g(u['bias'])}, drift {_g(u['drift_per_hour'])}/h"
                     + (f", most correlated with `{tc['signal']}` (r = {tc['r']:+.2f})" if tc else ""))
    L += _md_evidence(rep)
    if rep.get("plots"):
        L += ["", "## Plots", ""]
        for p in rep["plots"]:
            L.append(f"![{p}]({p})")
    L += ["", f"Run time {rep['elapsed_s']:.1f} s, {rep['n_simulations']} model simulations.", ""]
    return "\n".join(L)
