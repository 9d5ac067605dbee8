"""fmu_overhead.py - per-step cost of an FMU through shevsim's adapter vs fmpy's bare loop vs native.

Builds the C FMU ``fmus/src/rc_thermal`` (FMI 2.0, RK4 with 10 sub-steps) into a
temporary directory and times, per communication step (2 inputs set, doStep,
2 outputs read, the same work in every case):

(a) fmpy's bare loop: ``fmu.setReal(vrs, vals); fmu.doStep(t, h); fmu.getReal(vrs)``
(b) the same FMU through :class:`shevsim.fmu.FMUComponent` (``u`` dict -> one
    fmi2SetReal, fmi2DoStep, one fmi2GetReal -> ``y`` dict), as the master drives it
(c) the native twin :class:`shevsim.fmu.reference.RCThermalNode`
(d) for reference: the native component exported with pythonfmu and imported
    back (Python inside the FMU: the cost of the pythonfmu C++/Python bridge)
(e) (b) with the default ``step_timeout_s`` (the step runs on a helper thread so a hanging
    FMU can be bounded): the price of the bound per step

Model exchange (issue 16): the Reference-FMUs ``Dahlquist`` (x' = -k x) and ``BouncingBall``
(state events) FMI 2.0 model-exchange FMUs, built from ``fmus/src/reference_fmus``, run over the
same communication grid by (f) fmpy's own ``simulate_fmu`` (CVode, output_interval = step) and
(g) ``FMUComponent`` (CVode from fmpy's sundials wrapper, inputs held, events as fmpy), whole
runs including instantiation, same relative tolerance; the two trajectories are compared.

Usage: ``python benchmarks/fmu_overhead.py [--steps N] [--repeats R]``. Reports
the best of R repeats (µs/step) and the adapter overhead (b) - (a).
"""
from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path


def _best(fn, steps: int, repeats: int) -> float:
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn(steps)
        best = min(best, time.perf_counter() - t0)
    return best / steps * 1e6


def main(argv=None) -> dict[str, float]:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=20000)
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args(argv)

    import fmpy
    from fmpy.fmi2 import FMU2Slave

    from shevsim.fmu import FMUComponent
    from shevsim.fmu.build import build_c_fmu, fmu_sources_dir
    from shevsim.fmu.export import export_component
    from shevsim.fmu.reference import RCThermalNode

    h = 0.1
    with tempfile.TemporaryDirectory(prefix="shevsim_bench_") as tmp:
        tmp = Path(tmp).absolute()
        path = build_c_fmu(fmu_sources_dir() / "rc_thermal", tmp / "rc_thermal.fmu")

        # (a) fmpy bare loop
        md = fmpy.read_model_description(str(path))
        vr = {v.name: v.valueReference for v in md.modelVariables}
        unzipdir = fmpy.extract(str(path), str(tmp / "bare"))
        fmu = FMU2Slave(guid=md.guid, unzipDirectory=str(unzipdir), modelIdentifier=md.coSimulation.modelIdentifier,
                        instanceName="bare")
        fmu.instantiate()
        fmu.setupExperiment(startTime=0.0)
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        vin = [vr["heat_w"], vr["t_ambient_c"]]
        vout = [vr["t_c"], vr["heat_loss_w"]]
        state = {"t": 0.0}

        def bare(n):
            t = state["t"]
            for i in range(n):
                fmu.setReal(vin, [100.0, 20.0])
                fmu.doStep(t, h)
                out = fmu.getReal(vout)
                t += h
            state["t"] = t

        # (b) adapter
        comp = FMUComponent("node", path, step_timeout_s=None)
        comp.initialize(0.0)
        st_b = {"t": 0.0}
        comp_to = FMUComponent("node_to", path)          # default step_timeout_s: helper thread
        comp_to.initialize(0.0)
        st_e = {"t": 0.0}

        def adapter(n, comp=comp, st=st_b):
            u, y = comp.u, comp.y
            t = st["t"]
            for i in range(n):
                u["heat_w"] = 100.0
                u["t_ambient_c"] = 20.0
                comp.do_step(t, h)
                a = y["t_c"]
                b = y["heat_loss_w"]
                t += h
            st["t"] = t

        # (c) native
        nat = RCThermalNode("native")
        nat.initialize(0.0)
        st_c = {"t": 0.0}

        # (d) exported native component (pythonfmu) through the adapter
        exp_path = export_component(RCThermalNode, None, tmp / "node_export.fmu", fmi_version=2)
        comp_py = FMUComponent("node_py", exp_path, step_timeout_s=None)
        comp_py.initialize(0.0)
        st_d = {"t": 0.0}

        res = {
            "fmpy_bare_us": _best(bare, args.steps, args.repeats),
            "adapter_c_fmu_us": _best(adapter, args.steps, args.repeats),
            "native_us": _best(lambda n: adapter(n, nat, st_c), args.steps, args.repeats),
            "adapter_pythonfmu_us": _best(lambda n: adapter(n, comp_py, st_d), max(args.steps // 4, 1),
                                          args.repeats),
            "adapter_c_fmu_timeout_us": _best(lambda n: adapter(n, comp_to, st_e), args.steps, args.repeats),
        }
        res.update(_model_exchange(tmp, args.repeats))
        # sanity: the three C/native paths integrate the same model
        assert st_b["t"] == st_c["t"] and abs(comp.y["t_c"] - nat.y["t_c"]) < 1e-6, (comp.y, nat.y)
        fmu.terminate()
        fmu.freeInstance()
        comp.terminate()
        comp_to.terminate()
        comp_py.terminate()

    res["adapter_overhead_us"] = res["adapter_c_fmu_us"] - res["fmpy_bare_us"]
    print(f"per communication step (2 inputs set, doStep, 2 outputs read), best of {args.repeats} x "
          f"{args.steps} steps:")
    print(f"  (a) fmpy bare loop, C FMU            {res['fmpy_bare_us']:8.2f} us/step")
    print(f"  (b) FMUComponent, same C FMU         {res['adapter_c_fmu_us']:8.2f} us/step")
    print(f"  (c) native RCThermalNode             {res['native_us']:8.2f} us/step")
    print(f"  (d) FMUComponent, pythonfmu export   {res['adapter_pythonfmu_us']:8.2f} us/step "
          f"(Python model inside the FMU)")
    print(f"  (e) (b) with step_timeout_s bound    {res['adapter_c_fmu_timeout_us']:8.2f} us/step "
          f"(helper-thread hand-off)")
    print(f"  adapter overhead (b) - (a)           {res['adapter_overhead_us']:+8.2f} us/step "
          f"(negative: the adapter's preallocated ctypes calls beat fmpy's per-call array building)")
    print("model exchange, whole runs (instantiate, initialise, integrate with CVode, terminate):")
    for name in ("dahlquist", "bouncingball"):
        print(f"  {name:13s} {res[name + '_steps']:6d} steps of {res[name + '_h']:g} s: fmpy simulate_fmu "
              f"{res[name + '_fmpy_us']:8.2f} us/step, FMUComponent {res[name + '_ours_us']:8.2f} us/step "
              f"(ratio {res[name + '_ours_us'] / res[name + '_fmpy_us']:.2f}), max |ours - fmpy| "
              f"{res[name + '_maxdiff']:.2e}")
    return res


def _model_exchange(tmp: Path, repeats: int) -> dict[str, float]:
    """(f) fmpy simulate_fmu vs (g) FMUComponent on two FMI 2.0 model-exchange FMUs, same grid and tolerance."""
    import numpy as np
    from fmpy import simulate_fmu

    from shevsim.fmu import FMUComponent
    from shevsim.fmu.build import build_reference_fmu

    out: dict[str, float] = {}
    for name, model, stop, h, var in (("dahlquist", "Dahlquist", 20.0, 0.01, "x"),
                                      ("bouncingball", "BouncingBall", 3.0, 0.001, "h")):
        path = build_reference_fmu(model, tmp / f"{model}_me.fmu", 2, interfaces=("me",))
        n = int(round(stop / h))
        rtol = 1e-6

        def fmpy_run():
            return simulate_fmu(str(path), fmi_type="ModelExchange", solver="CVode", stop_time=stop,
                                output_interval=h, relative_tolerance=rtol, output=[var])

        def ours_run():
            comp = FMUComponent("me", path, tolerance=rtol, step_timeout_s=None)
            comp.initialize(0.0)
            vals = []
            for k in range(n):
                comp.do_step(k * h, h)
                vals.append(comp.y[var])
            comp.terminate()
            return np.array(vals)

        best_f = best_o = float("inf")
        for _ in range(repeats):
            t0 = time.perf_counter()
            rf = fmpy_run()
            best_f = min(best_f, time.perf_counter() - t0)
            t0 = time.perf_counter()
            ro = ours_run()
            best_o = min(best_o, time.perf_counter() - t0)
        ref = np.interp(h * np.arange(1, n + 1), rf["time"], rf[var])
        out.update({f"{name}_steps": n, f"{name}_h": h, f"{name}_fmpy_us": best_f / n * 1e6,
                    f"{name}_ours_us": best_o / n * 1e6, f"{name}_maxdiff": float(np.max(np.abs(ro - ref)))})
    return out


if __name__ == "__main__":
    main()
