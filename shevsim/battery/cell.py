"""cell.py - OCV-R-RC-RC electrical model of one A123 26650 LFP cell (seed 4.6, B.4-B.5, 5.16).

Model (current ``i`` positive = discharge, seed App. B)::

    dSOC/dt = -i / (3600 Q)                                  (4.6a)
    dV_j/dt = -V_j / (R_j C_j) + i / C_j,   j = 1, 2          (4.6b, B.5)
    V_t     = V_oc(SOC) - R_s i - V_1 - V_2                   (4.6c, B.4)

with R_s, R_j, C_j looked up (bilinear, clamped at the table edges) in SOC and temperature,
from separate tables for discharge (``i >= 0``) and charge (``i < 0``).

Heat generation (seed 5.16, with the RC-RC plant's two branches)::

    q = i^2 R_s + sum_j V_j^2 / R_j - i T dU_oc/dT,     dU_oc/dT = Delta S / F   (n = 1)

Sign convention: with ``i`` positive on discharge this is Bernardi's form
``q = i (U_oc - V_t) - i T dU_oc/dT`` with the capacitor storage term removed (the resistors
dissipate ``V_j^2/R_j``; ``i V_j - V_j^2/R_j = C_j V_j dV_j/dt`` is energy stored in C_j, not heat).
``T`` is in kelvin.  With Delta S < 0 (low SOC for LFP) discharge releases reversible heat
(q_rev > 0) and charge absorbs it, which is the seed's 4.1c sign for discharge-positive current.

The model itself (step, heat, power-to-current) is written once in :mod:`shevsim.battery.model`; this
module holds the cell tables (CSV reading, validation, packing) and their lookups.

Parameter tables live in ``components/battery/`` (CSV, representative values, not measured;
provenance in ``components/battery/make_a123_tables.py``).  Everything here is plain Python
floats for the simulation hot path.
"""
from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path

from shevsim.core.errors import DataError
from shevsim.core.params import name_rule
from shevsim.core.lookup import t1_integral, t1_slope, t1_value, ecm_lookup
from shevsim.core.paths import data_path
from shevsim.core.filecache import memo_file

__all__ = [
    "FARADAY_C_MOL",
    "CellTables",
    "default_tables",
    "cell_params",
    "ocv",
    "docv_dsoc",
    "entropy_change",
    "DATA_DIR",
]

FARADAY_C_MOL = 96485.3365  # seed 5.16
DATA_DIR = data_path("components", "battery")
_ECM_COLS = ("soc_frac", "t_c", "rs_ohm", "r1_ohm", "c1_f", "r2_ohm", "c2_f")


@memo_file
def read_csv_table(path: Path, cols: tuple[str, ...]) -> tuple[tuple[float, ...], ...]:
    from shevsim.core.textfile import read_text_file, text_lines
    path = Path(path)
    # not found, a folder, a device, a binary file: said as such; UTF-8 (a spreadsheet's byte-order mark is not part
    # of the first column's name), UTF-16 or Windows-1252
    text = read_text_file(path, "table file")[0]
    rows: list[list[float]] = []
    lines = [ln for ln in text_lines(text) if ln.strip() and not ln.lstrip().startswith("#")]
    # ';' (with decimal commas) or a tab (a spreadsheet's "Unicode text" export) where the header has no comma
    sep = (";" if ";" in lines[0] else "\t" if "\t" in lines[0] else ",") if lines and "," not in lines[0] else ","
    reader = csv.reader(lines, delimiter=sep)
    header = [h.strip() for h in next(reader, [])]
    missing = [c for c in cols if c not in header]
    if missing:
        raise DataError(f"{path}: missing column(s) {', '.join(missing)} (header: {', '.join(header)})")
    idx = [header.index(c) for c in cols]
    rules = [name_rule(c) for c in cols]
    for lineno, row in enumerate(reader, start=2):
        try:
            vals = [float(row[i].replace(",", ".") if sep == ";" else row[i]) for i in idx]
        except (ValueError, IndexError) as exc:
            raise DataError(f"{path}: data row {lineno}: cannot parse {row!r} ({exc})") from exc
        for c, v, r in zip(cols, vals, rules):
            if not math.isfinite(v):
                raise DataError(f"{path}: data row {lineno}, column '{c}': non-finite value {v!r}")
            if not r.ok(v):
                raise DataError(f"{path}: data row {lineno}, column '{c}': value {v!r} outside the physical "
                                f"range {r.describe()}")
        rows.append(vals)
    if len(rows) < 2:
        raise DataError(f"{path}: need at least two data rows")
    return tuple(tuple(r) for r in rows)


def _check_increasing(xs: list[float], path: Path, col: str) -> None:
    for a, b in zip(xs, xs[1:]):
        if not b > a:
            raise DataError(f"{path}: column '{col}' must be strictly increasing ({a} then {b})")


class _Grid2:
    """A regular (soc, T) grid of several quantities (data only: looked up by
    :func:`shevsim.core.lookup.ecm_lookup` on the packed arrays)."""

    def __init__(self, rows: list[list[float]], path: Path):
        socs = sorted({r[0] for r in rows})
        temps = sorted({r[1] for r in rows})
        if len(socs) * len(temps) != len(rows):
            raise DataError(f"{path}: rows must form a full soc x temperature grid "
                            f"({len(socs)} x {len(temps)} != {len(rows)} rows)")
        self.socs, self.temps = socs, temps
        nq = len(rows[0]) - 2
        table = {(r[0], r[1]): r[2:] for r in rows}
        # vals[it][is] -> list of nq values
        self.vals = [[table[(s, t)] for s in socs] for t in temps]
        for r in rows:
            if any(v <= 0.0 for v in r[2:]):
                raise DataError(f"{path}: resistances and capacitances must be > 0 (soc {r[0]}, T {r[1]} degC)")
        self.nq = nq


def _row_at(g: "_Grid2", t_c: float) -> list:
    """The grid's values at temperature ``t_c`` (linear between its temperatures, clamped): one list of
    ``nq`` values per SOC knot."""
    ts = g.temps
    if t_c <= ts[0] or len(ts) == 1:
        return [list(c) for c in g.vals[0]]
    if t_c >= ts[-1]:
        return [list(c) for c in g.vals[-1]]
    j = max(k for k in range(len(ts) - 1) if ts[k] <= t_c)
    w = (t_c - ts[j]) / (ts[j + 1] - ts[j])
    return [[(1.0 - w) * a + w * b for a, b in zip(ca, cb)] for ca, cb in zip(g.vals[j], g.vals[j + 1])]


class _Table1:
    """Piecewise-linear 1-D table with clamped ends (data only: its slopes and the cumulative integral at
    the knots are precomputed for :func:`shevsim.core.lookup.t1_value` / ``t1_slope`` / ``t1_integral``)."""

    def __init__(self, xs: list[float], ys: list[float]):
        self.xs, self.ys = xs, ys
        self.slopes = [(ys[k + 1] - ys[k]) / (xs[k + 1] - xs[k]) for k in range(len(xs) - 1)]
        cum = [0.0]
        for k in range(len(xs) - 1):
            cum.append(cum[-1] + 0.5 * (ys[k] + ys[k + 1]) * (xs[k + 1] - xs[k]))
        self.cum = cum


@dataclass(frozen=True)
class _Paths:
    ocv: Path
    entropy: Path
    discharge: Path
    charge: Path


class CellTables:
    """The cell's OCV, entropy-change and ECM parameter tables.

    Parameters
    ----------
    ocv_file, entropy_file, discharge_file, charge_file : path-like, optional
        CSV tables (``#`` comment lines allowed). Defaults: the representative A123 26650
        tables in ``components/battery/``. Columns: ``soc_frac, ocv_v``;
        ``soc_frac, delta_s_j_molk``; ``soc_frac, t_c, rs_ohm, r1_ohm, c1_f, r2_ohm, c2_f``.
    scales : 5 floats, optional
        Factors on the ECM tables' ``rs, r1, c1, r2, c2`` (a calibrated cell's ``rs_scale`` ...
        ``c2_scale``; default 1: the tables as read).
    fixed_t_c : float, optional
        Look the ECM tables up at this temperature whatever the cell's (a cell model without
        temperature dependence, as the battery's ``temperature_dependent = false`` at 25 degC).
    """

    def __init__(self, ocv_file=None, entropy_file=None, discharge_file=None, charge_file=None,
                 scales=(1.0, 1.0, 1.0, 1.0, 1.0), fixed_t_c: float | None = None):
        p = _Paths(Path(ocv_file or DATA_DIR / "a123_26650_ocv.csv"),
                   Path(entropy_file or DATA_DIR / "a123_26650_entropy.csv"),
                   Path(discharge_file or DATA_DIR / "a123_26650_ecm_discharge.csv"),
                   Path(charge_file or DATA_DIR / "a123_26650_ecm_charge.csv"))
        self.paths = p
        rows = read_csv_table(p.ocv, ("soc_frac", "ocv_v"))
        xs = [r[0] for r in rows]
        _check_increasing(xs, p.ocv, "soc_frac")
        _check_increasing([r[1] for r in rows], p.ocv, "ocv_v")
        self._ocv = _Table1(xs, [r[1] for r in rows])
        rows = read_csv_table(p.entropy, ("soc_frac", "delta_s_j_molk"))
        xs = [r[0] for r in rows]
        _check_increasing(xs, p.entropy, "soc_frac")
        self._ds = _Table1(xs, [r[1] for r in rows])
        self._dch = _Grid2(read_csv_table(p.discharge, _ECM_COLS), p.discharge)
        self._chg = _Grid2(read_csv_table(p.charge, _ECM_COLS), p.charge)
        self.scales = tuple(float(k) for k in scales)
        if self.scales != (1.0,) * 5:         # a calibrated cell: factors on R_s, R1, C1, R2, C2
            if len(self.scales) != 5 or not all(k > 0.0 and math.isfinite(k) for k in self.scales):
                raise DataError(f"cell tables: scales must be 5 finite factors > 0 (rs, r1, c1, r2, c2), got {scales!r}")
            for g in (self._dch, self._chg):
                g.vals = [[[v * k for v, k in zip(cell, self.scales)] for cell in row] for row in g.vals]
        self.fixed_t_c = None if fixed_t_c is None else float(fixed_t_c)
        if self.fixed_t_c is not None:        # a cell model without temperature dependence: every row = T
            for g in (self._dch, self._chg):
                g.vals = [list(_row_at(g, self.fixed_t_c)) for _ in g.temps]
        self._d, self._ix = self.packed()

    # -- lookups (soc as a fraction 0..1, temperature in degC): the one lookup module, compiled -----
    def params(self, soc: float, t_c: float, sign: float) -> tuple[float, float, float, float, float]:
        """``(rs_ohm, r1_ohm, c1_f, r2_ohm, c2_f)``; ``sign >= 0`` discharge table, ``< 0`` charge."""
        return ecm_lookup(self._d, self._ix, float(soc), float(t_c), float(sign))

    def ocv(self, soc: float) -> float:
        """Open-circuit voltage [V]."""
        return t1_value(self._d, self._ix[0], self._ix[1], float(soc))

    def docv_dsoc(self, soc: float) -> float:
        """dV_oc/dSOC [V per unit SOC] (right slope at knots; the end segments' slopes beyond the table)."""
        return t1_slope(self._d, self._ix[0], self._ix[1], float(soc))

    def ocv_integral(self, soc: float) -> float:
        """Integral of V_oc from the table's first SOC to ``soc`` [V * unit SOC] (exact)."""
        return t1_integral(self._d, self._ix[0], self._ix[1], float(soc))

    def entropy_change(self, soc: float) -> float:
        """Delta S = F dU_oc/dT [J/mol/K]."""
        return t1_value(self._d, self._ix[2], self._ix[3], float(soc))

    def packed(self):
        """All tables in one float array plus int offsets, for compiled lookups.

        Layout (``idx``): ``[o_ocv, n_ocv, o_ds, n_ds, o_dch, ns_dch, nt_dch, o_chg, ns_chg, nt_chg, nq]``;
        a 1-D table at ``o`` holds ``xs (n), ys (n), slopes (n-1), cum (n)``; an ECM grid at ``o`` holds
        ``socs (ns), temps (nt), vals (nt x ns x nq)``.
        """
        import numpy as np
        data: list[float] = []
        idx: list[int] = []
        for t in (self._ocv, self._ds):
            idx += [len(data), len(t.xs)]
            data += list(t.xs) + list(t.ys) + list(t.slopes) + list(t.cum)
        nq = self._dch.nq
        for g in (self._dch, self._chg):
            if g.nq != nq:
                raise DataError("charge and discharge ECM tables must have the same columns")
            idx += [len(data), len(g.socs), len(g.temps)]
            data += list(g.socs) + list(g.temps) + [v for row in g.vals for cell in row for v in cell]
        idx.append(nq)
        return np.array(data, dtype=np.float64), np.array(idx, dtype=np.int64)


_DEFAULT: CellTables | None = None


def default_tables() -> CellTables:
    """The default (representative A123 26650) tables, loaded once."""
    global _DEFAULT
    if _DEFAULT is None:
        _DEFAULT = CellTables()
    return _DEFAULT


def cell_params(soc: float, t_c: float, sign: float = 1.0):
    """ECM parameters ``(rs_ohm, r1_ohm, c1_f, r2_ohm, c2_f)`` at SOC [frac], temperature [degC].

    ``sign >= 0`` selects the discharge table, ``sign < 0`` the charge table.
    """
    return default_tables().params(soc, t_c, sign)


def ocv(soc: float) -> float:
    """Open-circuit voltage [V] of the default cell at SOC [frac] (LFP shape, clamped ends)."""
    return default_tables().ocv(soc)


def docv_dsoc(soc: float) -> float:
    """dV_oc/dSOC [V/unit SOC] of the default cell."""
    return default_tables().docv_dsoc(soc)


def entropy_change(soc: float) -> float:
    """Entropy change Delta S [J/mol/K] of the default cell (Fig. 5.5 shape)."""
    return default_tables().entropy_change(soc)
