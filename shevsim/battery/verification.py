"""verification.py - verification of the battery thermal models (seed Sec. 2.2.4, 2.3.1, 3.3).

* :func:`frequency_responses` - H11 (Q->T_c), H12 (T_amb->T_c), H21 (Q->T_s), H22 (T_amb->T_s)
  of the analytical solution (modified Bessel functions), the two-state model and an N-node
  radial discretisation (seed Fig. 2.2).
* :func:`kappa_coefficients`, :func:`identifiability_jacobian` - structural identifiability of
  theta = (k_t, c_p, h) from the transfer-function coefficients (seed 2.29-2.32).  Two printed
  coefficients are wrong and are corrected here (checked against the state-space model, see
  the tests): kappa_2 = 24 V k_t alpha R (7hR + 20k_t) (the seed drops k_t) and
  kappa_8 = 4 V k_t h R^4 (the seed has a spurious alpha).
* :func:`fim_estimability` - Fisher-information estimability of (k_t, c_p, h) (seed 3.5-3.9).
* :func:`drive_like_current` - a reproducible drive-cycle-like cell current for studies.
* :func:`run_thermal_verification` - writes the frequency-response PNG + CSV and a JSON summary.

CLI: ``python -m shevsim.battery.verification OUT_DIR``.
"""
from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np

from .thermal import (ThermalParams, analytical_tf, fd_matrices, state_space_tf, two_state_matrices, zoh)

__all__ = [
    "frequency_responses",
    "divergence_frequency",
    "kappa_coefficients",
    "identifiability_jacobian",
    "simulate_two_state",
    "fim_estimability",
    "drive_like_current",
    "run_thermal_verification",
]

TF_NAMES = {(0, 0): "H11_q_to_core", (0, 1): "H12_amb_to_core", (1, 0): "H21_q_to_surface",
            (1, 1): "H22_amb_to_surface"}


def frequency_responses(p: ThermalParams, h_w_m2k: float, f_hz, n_nodes: int = 30, scheme: str = "fv"):
    """Complex frequency responses of the three models at frequencies ``f_hz`` [Hz].

    Returns
    -------
    dict with keys ``"analytical"``, ``"two_state"``, ``"fd"``: arrays (len(f), 2, 2) indexed
    ``[:, output(core, surface), input(q_w, t_amb_c)]``.  Gains in K/W and K/K.
    """
    f = np.asarray(f_hz, dtype=float)
    s = 2j * math.pi * f
    A, B, C, D = two_state_matrices(p, h_w_m2k)
    An, Bn, Cn, Dn, _ = fd_matrices(p, h_w_m2k, n_nodes, scheme)
    return {
        "analytical": analytical_tf(p, h_w_m2k, s),
        "two_state": state_space_tf(A, B, C, D, s),
        "fd": state_space_tf(An, Bn, Cn, Dn, s),
    }


def mag_phase_error(H, Href):
    """Magnitude error [dB] and phase error [deg] of ``H`` relative to ``Href``."""
    ratio = H / Href
    return 20.0 * np.log10(np.abs(ratio)), np.degrees(np.angle(ratio))


def divergence_frequency(f_hz, H, Href, tol_db: float = 0.5, tol_deg: float = 5.0):
    """Lowest frequency [Hz] at which ``H`` departs from ``Href`` by more than ``tol_db`` or
    ``tol_deg`` (``nan`` if it never does)."""
    e_db, e_deg = mag_phase_error(H, Href)
    bad = (np.abs(e_db) > tol_db) | (np.abs(e_deg) > tol_deg)
    idx = np.flatnonzero(bad)
    return float(np.asarray(f_hz)[idx[0]]) if idx.size else float("nan")


# ---------------------------------------------------------------------------------
# structural identifiability (2.29-2.32)
# ---------------------------------------------------------------------------------
def kappa_coefficients(p: ThermalParams, h_w_m2k: float, kt_w_mk: float | None = None,
                       cp_j_kgk: float | None = None, corrected: bool = True) -> np.ndarray:
    """Transfer-function coefficients kappa_1..kappa_12 of the two-state model (seed 2.31).

    ``H11 = (k4 s + k5)/(k1 s^2 + k2 s + k3)``, ``H21 = (k6 s + k7)/den``,
    ``H12 = (k8 s^2 + k9 s + k10)/den``, ``H22 = (k11 s^2 + k12 s + k10)/den``.
    ``corrected=False`` gives the printed (wrong) kappa_2 and kappa_8.
    """
    k = p.kt_w_mk if kt_w_mk is None else kt_w_mk
    cp = p.cp_j_kgk if cp_j_kgk is None else cp_j_kgk
    h = h_w_m2k
    R, V = p.radius_m, p.volume_m3
    a = k / (p.density_kg_m3 * cp)
    k1 = V * k * R ** 3 * (h * R + 24 * k)
    k2 = 24 * V * a * R * (7 * h * R + 20 * k) * (k if corrected else 1.0)
    k3 = 960 * V * a ** 2 * k * h
    k4 = 3 * a * R ** 3 * (8 * k - h * R)
    k5 = 240 * a ** 2 * R * (h * R + 2 * k)
    k6 = 24 * a * k * R ** 3
    k7 = 480 * a ** 2 * k * R
    k8 = 4 * V * k * h * R ** 4 * (1.0 if corrected else a)
    k9 = -72 * V * a * k * h * R ** 2
    k10 = 960 * V * a ** 2 * k * h
    k11 = V * k * h * R ** 4
    k12 = 168 * V * a * k * h * R ** 2
    return np.array([k1, k2, k3, k4, k5, k6, k7, k8, k9, k10, k11, k12])


def identifiability_jacobian(p: ThermalParams, h_w_m2k: float, normalise: bool = True,
                             rel_step: float = 1e-5):
    """Jacobian of the coefficient vector w.r.t. ln(k_t, c_p, h) by central differences.

    With ``normalise=True`` the coefficients are divided by kappa_1 (the transfer function only
    fixes them up to a common factor, so this is the honest test) and each row is scaled by its
    nominal value, i.e. the Jacobian of ln(kappa_i/kappa_1), i = 2..12.

    Returns
    -------
    J : ndarray (n_coeff, 3), singular_values : ndarray (3,), rank : int
        Rank counted with a relative tolerance of 1e-8 of the largest singular value.
    """
    theta0 = np.array([p.kt_w_mk, p.cp_j_kgk, h_w_m2k])

    def phi(th):
        c = kappa_coefficients(p, th[2], kt_w_mk=th[0], cp_j_kgk=th[1])
        return np.log(np.abs(c[1:] / c[0])) if normalise else c

    cols = []
    for j in range(3):
        d = np.zeros(3)
        d[j] = rel_step
        cols.append((phi(theta0 * np.exp(d)) - phi(theta0 * np.exp(-d))) / (2 * rel_step))
    J = np.column_stack(cols)
    sv = np.linalg.svd(J, compute_uv=False)
    rank = int(np.sum(sv > 1e-8 * sv[0]))
    return J, sv, rank


# ---------------------------------------------------------------------------------
# FIM estimability (3.5-3.9)
# ---------------------------------------------------------------------------------
def simulate_two_state(p: ThermalParams, h_w_m2k: float, dt_s: float, q_w, t_amb_c, t0_c: float | None = None):
    """Simulate the two-state model (exact ZOH) and return outputs (n, 2): [T_core, T_surface]."""
    A, B, C, D = two_state_matrices(p, h_w_m2k)
    Ad, Bd = zoh(A, B, dt_s)
    q = np.asarray(q_w, dtype=float)
    ta = np.broadcast_to(np.asarray(t_amb_c, dtype=float), q.shape)
    x = np.array([ta[0] if t0_c is None else t0_c, 0.0])
    y = np.empty((q.size, 2))
    for i in range(q.size):
        y[i] = C @ x + D[:, 1] * ta[i]
        x = Ad @ x + Bd[:, 0] * q[i] + Bd[:, 1] * ta[i]
    return y


def fim_estimability(p: ThermalParams, h_w_m2k: float, dt_s: float, q_w, t_amb_c,
                     outputs: tuple = ("surface",), rel_step: float = 1e-4):
    """Fisher-information estimability of p = (k_t, c_p, h) (seed 3.5-3.9).

    Normalised sensitivities ``(p_j / y(t_i)) dy/dp_j`` (3.6) are computed by central
    differences of the simulated outputs (equivalent to integrating 3.7 for this linear
    model); ``FIM = Psi^T Psi`` (3.8).  Outputs are in degC as in the seed (the normalisation
    by y therefore depends on the temperature scale).

    Parameters
    ----------
    outputs : tuple of {"surface", "core"}
        Measured outputs (case 1 of the seed: surface only; case 2: surface and core).

    Returns
    -------
    dict with ``fim`` (3x3), ``eigenvalues`` (ascending), ``eigenvectors`` (columns),
    ``condition_number``, ``covariance`` (inverse FIM), ``ranking`` (parameter names from the
    least to the most estimable: repeatedly drop the parameter with the largest |component| in
    the eigenvector of the smallest eigenvalue of the remaining FIM).
    """
    names = ("kt_w_mk", "cp_j_kgk", "h_w_m2k")
    sel = [{"core": 0, "surface": 1}[o] for o in outputs]
    th0 = np.array([p.kt_w_mk, p.cp_j_kgk, h_w_m2k])

    def sim(th):
        pp = dataclasses.replace(p, kt_w_mk=float(th[0]), cp_j_kgk=float(th[1]))
        return simulate_two_state(pp, float(th[2]), dt_s, q_w, t_amb_c)[:, sel]

    y0 = sim(th0)
    blocks = []
    for j in range(3):
        d = np.zeros(3)
        d[j] = rel_step * th0[j]
        dy = (sim(th0 + d) - sim(th0 - d)) / (2 * d[j])
        blocks.append((th0[j] * dy / y0).reshape(-1, order="F"))
    Psi = np.column_stack(blocks)
    fim = Psi.T @ Psi
    w, V = np.linalg.eigh(fim)
    remaining = list(range(3))
    ranking = []
    while len(remaining) > 1:
        sub = fim[np.ix_(remaining, remaining)]
        ws, Vs = np.linalg.eigh(sub)
        worst = remaining[int(np.argmax(np.abs(Vs[:, 0])))]
        ranking.append(names[worst])
        remaining.remove(worst)
    ranking.append(names[remaining[0]])
    return {
        "fim": fim,
        "eigenvalues": w,
        "eigenvectors": V,
        "condition_number": float(w[-1] / w[0]) if w[0] > 0 else float("inf"),
        "covariance": np.linalg.inv(fim),
        "ranking": ranking,
        "parameters": names,
    }


# ---------------------------------------------------------------------------------
# inputs for studies
# ---------------------------------------------------------------------------------
def drive_like_current(duration_s: float, dt_s: float, seed: int = 0, i_max_a: float = 25.0,
                       mean_segment_s: float = 10.0) -> np.ndarray:
    """Reproducible drive-cycle-like cell current [A] (+ discharge).

    Piecewise-constant segments of exponentially distributed length (mean ``mean_segment_s``):
    30 % rest, 50 % discharge U(0, 1) i_max, 20 % regeneration -U(0, 0.6) i_max, then a
    first-order smoothing with a 2 s time constant (driver/powertrain dynamics).  A stand-in
    for the seed's measured Urban-Assault / Escort-Convoy cycles, which are not available.
    """
    rng = np.random.default_rng(seed)
    n = int(round(duration_s / dt_s))
    out = np.empty(n)
    i = 0
    while i < n:
        m = max(1, int(round(rng.exponential(mean_segment_s) / dt_s)))
        u = rng.random()
        if u < 0.3:
            level = 0.0
        elif u < 0.8:
            level = rng.random() * i_max_a
        else:
            level = -0.6 * rng.random() * i_max_a
        out[i:i + m] = level
        i += m
    a = math.exp(-dt_s / 2.0)
    y = np.empty(n)
    acc = 0.0
    for k in range(n):
        acc = a * acc + (1 - a) * out[k]
        y[k] = acc
    return y


# ---------------------------------------------------------------------------------
# report
# ---------------------------------------------------------------------------------
def run_thermal_verification(out_dir, h_w_m2k: float = 5.0, n_nodes: int = 30,
                             f_min_hz: float = 1e-6, f_max_hz: float = 1.0, n_freq: int = 241) -> dict:
    """Frequency-response comparison (seed Fig. 2.2, Table 2.1 cell), identifiability and FIM.

    Writes ``thermal_freq_response.png``, ``thermal_freq_response.csv`` and
    ``thermal_verification.json`` into ``out_dir`` and returns the summary dict.
    """
    from shevsim.plotting import headless_pyplot
    plt = headless_pyplot()

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    p = ThermalParams.table_2_1()
    f = np.logspace(math.log10(f_min_hz), math.log10(f_max_hz), n_freq)
    H = frequency_responses(p, h_w_m2k, f, n_nodes=n_nodes)
    Ha, Hp, Hf = H["analytical"], H["two_state"], H["fd"]

    cols = {"frequency_hz": f}
    for (i, j), name in TF_NAMES.items():
        for tag, HH in (("as", Ha), ("pa", Hp), ("fd", Hf)):
            cols[f"{name}_{tag}_mag_db"] = 20 * np.log10(np.abs(HH[:, i, j]))
            cols[f"{name}_{tag}_phase_deg"] = np.degrees(np.unwrap(np.angle(HH[:, i, j])))
    header = ",".join(cols)
    data = np.column_stack(list(cols.values()))
    with open(out / "thermal_freq_response.csv", "w") as fh:
        fh.write(f"# frequency responses of the cell thermal models, Table 2.1 cell, h = {h_w_m2k} W/m2K; "
                 f"as = analytical (modified Bessel), pa = two-state polynomial model, fd = {n_nodes}-node "
                 "control-volume model; magnitude in dB re 1 K/W (q inputs) or 1 K/K (ambient inputs)\n")
        fh.write(header + "\n")
        np.savetxt(fh, data, delimiter=",", fmt="%.8g")

    summary = {"h_w_m2k": h_w_m2k, "n_nodes": n_nodes, "params": dataclasses.asdict(p), "transfer_functions": {}}
    for (i, j), name in TF_NAMES.items():
        e_db, e_deg = mag_phase_error(Hp[:, i, j], Ha[:, i, j])
        f_db, f_deg = mag_phase_error(Hf[:, i, j], Ha[:, i, j])
        summary["transfer_functions"][name] = {
            "static_gain_analytical": float(Ha[0, i, j].real),
            "two_state_max_abs_err_db": float(np.max(np.abs(e_db))),
            "two_state_max_abs_err_deg": float(np.max(np.abs(e_deg))),
            "two_state_divergence_hz_0p5db_5deg": divergence_frequency(f, Hp[:, i, j], Ha[:, i, j]),
            "fd_max_abs_err_db": float(np.max(np.abs(f_db))),
            "fd_max_abs_err_deg": float(np.max(np.abs(f_deg))),
            "fd_divergence_hz_0p5db_5deg": divergence_frequency(f, Hf[:, i, j], Ha[:, i, j]),
        }
    # the seed's node-based scheme (2.9-2.12, corrected) at the same N, for comparison with Fig. 2.2
    Hs = frequency_responses(p, h_w_m2k, f, n_nodes=n_nodes, scheme="fd")["fd"]
    summary["fd_seed_scheme_max_abs_err_db"] = {
        name: float(np.max(np.abs(mag_phase_error(Hs[:, i, j], Ha[:, i, j])[0]))) for (i, j), name in TF_NAMES.items()}
    summary["two_state_divergence_hz_1db_10deg"] = {
        name: divergence_frequency(f, Hp[:, i, j], Ha[:, i, j], 1.0, 10.0) for (i, j), name in TF_NAMES.items()}
    _, sv, rank = identifiability_jacobian(ThermalParams(), 56.2)
    _, sv5, rank5 = identifiability_jacobian(p, h_w_m2k)
    summary["identifiability"] = {"rank_table_3_1_h56": rank, "singular_values_table_3_1": sv.tolist(),
                                  "rank_table_2_1_h5": rank5, "singular_values_table_2_1": sv5.tolist()}
    dt = 1.0
    cur = drive_like_current(3600.0, dt, seed=1)
    q = cur ** 2 * 0.012
    p31 = ThermalParams()
    fim = {}
    for case, outs in (("case1_surface", ("surface",)), ("case2_surface_core", ("surface", "core"))):
        r = fim_estimability(p31, 56.2, dt, q, 25.0, outputs=outs)
        fim[case] = {"eigenvalues": r["eigenvalues"].tolist(), "condition_number": r["condition_number"],
                     "ranking_least_to_most_estimable": r["ranking"],
                     "covariance_diag": np.diag(r["covariance"]).tolist()}
    summary["fim"] = fim

    fig, axes = plt.subplots(2, 1, figsize=(8, 8), sharex=True)
    colors = {"H11_q_to_core": "C0", "H12_amb_to_core": "C1", "H21_q_to_surface": "C2", "H22_amb_to_surface": "C3"}
    for (i, j), name in TF_NAMES.items():
        c = colors[name]
        for tag, HH, ls in (("AS", Ha, "-"), ("PA", Hp, "--"), ("FD", Hf, ":")):
            axes[0].semilogx(f, 20 * np.log10(np.abs(HH[:, i, j])), ls, color=c, label=f"{name} {tag}")
            axes[1].semilogx(f, np.degrees(np.unwrap(np.angle(HH[:, i, j]))), ls, color=c)
    axes[0].set_ylabel("magnitude [dB]")
    axes[0].set_ylim(-80, 40)
    axes[1].set_ylabel("phase [deg]")
    axes[1].set_ylim(-400, 10)
    axes[1].set_xlabel("frequency [Hz]")
    axes[0].legend(fontsize=6, ncol=2)
    axes[0].set_title(f"Cell thermal models, Table 2.1 cell, h = {h_w_m2k} W/m$^2$K "
                      f"(AS analytical, PA two-state, FD {n_nodes}-node)", fontsize=9)
    for ax in axes:
        ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    fig.savefig(out / "thermal_freq_response.png", dpi=120)
    plt.close(fig)
    with open(out / "thermal_verification.json", "w") as fh:
        json.dump(summary, fh, indent=2)
    return summary


def _main(argv=None) -> None:
    import argparse

    ap = argparse.ArgumentParser(description="battery thermal model verification (frequency responses, "
                                             "identifiability, FIM)")
    ap.add_argument("out_dir")
    ap.add_argument("--h", type=float, default=5.0, help="convection coefficient [W/m2K]")
    ap.add_argument("--nodes", type=int, default=30)
    a = ap.parse_args(argv)
    s = run_thermal_verification(a.out_dir, h_w_m2k=a.h, n_nodes=a.nodes)
    print(json.dumps(s["transfer_functions"], indent=1))
    print("seed FD scheme max |err| dB:", json.dumps(s["fd_seed_scheme_max_abs_err_db"]))
    print("two-state divergence (1 dB / 10 deg) Hz:", json.dumps(s["two_state_divergence_hz_1db_10deg"]))
    print(json.dumps(s["identifiability"], indent=1))
    print(json.dumps(s["fim"], indent=1))


if __name__ == "__main__":
    _main()
