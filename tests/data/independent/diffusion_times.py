"""The solid-diffusion time R^2/D of each electrode of the PyBaMM parameter sets the independent cell records use.

    python tests/data/independent/diffusion_times.py          # PyBaMM 26.x (a test/benchmark dependency)

Every PyBaMM SPMe record carries solid diffusion in its particles, whatever effect was switched in or not: it is
the generator's own physics, which the user's nominal (an equivalent circuit, no diffusion) lacks.  The
calibration's ``solid_diffusion`` effect has one parameter, ``diffusion_time_s`` = R^2/D; its truth on these
records is the particles' R^2/D - one value per electrode, the effect a lumped single particle between them.
This script writes, into each ``cell*_truth.json``, ``solid_diffusion_time_s``: ``{"negative": ..,
"positive": .., "at": ..}`` (the particle radius squared over the solid diffusivity at stoichiometry 0.5 and
25 degC, the temperature every record's diffusivities are held at or start from).  The make scripts call
:func:`electrode_diffusion_times_s` too, so a regenerated truth file keeps it.
"""
import json
import sys
from pathlib import Path

#: the records' file prefix -> the PyBaMM parameter set its particles come from
SETS = {"cell": "Chen2020", "cell_lfp": "Prada2013", "cell_nmc2": "Ecker2015", "cell_ai2020": "Ai2020",
        "cell_mohtat2020": "Mohtat2020"}
STO, T_K = 0.5, 298.15


def electrode_diffusion_times_s(set_name: str) -> dict:
    """``{"negative": R^2/D [s], "positive": R^2/D [s], "at": ...}`` of PyBaMM's parameter set ``set_name``."""
    import pybamm
    p = pybamm.ParameterValues(set_name)
    out = {}
    for el in ("negative", "positive"):
        name = el.capitalize()
        r = float(p[f"{name} particle radius [m]"])
        d = p[f"{name} particle diffusivity [m2.s-1]"]
        if callable(d):
            d = d(pybamm.Scalar(STO), pybamm.Scalar(T_K))
        d = float(d.evaluate()) if hasattr(d, "evaluate") else float(d)
        out[el] = r * r / d
    out["at"] = f"PyBaMM {pybamm.__version__} {set_name}: R^2/D at stoichiometry {STO}, {T_K - 273.15:g} degC"
    return out


def main() -> int:
    here = Path(__file__).resolve().parent
    for prefix, set_name in SETS.items():
        path = here / f"{prefix}_truth.json"
        truth = json.loads(path.read_text())
        truth["solid_diffusion_time_s"] = electrode_diffusion_times_s(set_name)
        tmp = path.with_suffix(".json.tmp")
        tmp.write_text(json.dumps(truth, indent=2) + "\n")
        tmp.replace(path)
        print(prefix, truth["solid_diffusion_time_s"])
    return 0


if __name__ == "__main__":
    sys.exit(main())
