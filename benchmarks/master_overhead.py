"""Master overhead: eight trivial components exchanging 20 signals for 10^5 steps.

Prints µs per communication step for (a) the shevsim master (Gauss-Seidel, with
recording and the NaN check on), (b) a bare Python loop doing the same work
(same component objects, hand-wired copies, no recording), and their ratio.
Target: master under 10 µs per step.
"""
from __future__ import annotations

import time

from shevsim.components.verification import Trivial, TrivialParams
from shevsim.core import Connection, Master, MasterSettings

N_STEPS = 100_000


def make():
    comps = [Trivial(f"c{i}", TrivialParams(gain=0.1)) for i in range(8)]
    conns = []
    # ring + chords: 20 connections between the 8 components
    for i in range(8):
        conns.append(Connection(f"c{i}", "out0_1", f"c{(i + 1) % 8}", "in0_1"))
        conns.append(Connection(f"c{i}", "out1_1", f"c{(i + 3) % 8}", "in1_1"))
    for i in range(4):
        conns.append(Connection(f"c{i}", "out2_1", f"c{i + 4}", "in2_1"))
    return comps, conns


def main():
    comps, conns = make()
    assert len(conns) == 20
    m = Master(comps, conns, MasterSettings(step_s=1e-3))
    m.initialize(0.0)
    m.components["c0"].u["in2_1"] = 1.0
    t = time.perf_counter()
    for _ in range(N_STEPS):
        m.step()
    master_us = (time.perf_counter() - t) / N_STEPS * 1e6

    comps, conns = make()
    for c in comps:
        c.initialize(0.0)
    by = {c.name: c for c in comps}
    links = [(by[c.dst].u, c.dst_port, by[c.src].y, c.src_port) for c in conns]
    h = 1e-3
    t = time.perf_counter()
    for k in range(N_STEPS):
        for du, dk, sy, sk in links:
            du[dk] = sy[sk]
        for c in comps:
            c.do_step(k * h, h)
    bare_us = (time.perf_counter() - t) / N_STEPS * 1e6
    print(f"master (Gauss-Seidel, recording + NaN check): {master_us:.2f} us/step")
    print(f"bare Python loop, same components and copies : {bare_us:.2f} us/step")
    print(f"master / bare ratio                          : {master_us / bare_us:.2f}")
    print(f"target < 10 us/step: {'met' if master_us < 10 else 'NOT met'}")


if __name__ == "__main__":
    main()
