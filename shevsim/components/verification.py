"""verification.py - small components with known answers, used to verify the master.

Two-body system: mass 1 tied to a wall by spring ``k1``, coupled to mass 2
through a spring-damper ``(k, c)``. Split into two co-simulation components:

* ``MassSpring`` (one mass, integrates exactly with RK4 sub-steps): input
  ``force_n`` (external force on the mass, + along x), outputs ``position_m``,
  ``velocity_mps`` (state only, no feedthrough).
* ``SpringDamper`` carrying mass 2: inputs ``position_m``, ``velocity_mps`` of
  mass 1; state of mass 2; output ``force_n`` = force on mass 1 (feedthrough
  from the inputs), ``position2_m``, ``velocity2_mps``.
"""
from __future__ import annotations

from dataclasses import dataclass, field

from ..core.component import Component
from ..core.params import rng
from ..core.variables import inp, out


@dataclass(frozen=True, slots=True)
class MassSpringParams:
    mass_kg: float = 1.0
    stiffness_n_per_m: float = 10.0
    x0_m: float = field(default=1.0, metadata=rng(what="a displacement, either sign"))
    v0_mps: float = 0.0
    substeps: int = 10


class MassSpring(Component):
    """Mass on a spring to the wall.

    Ports
    -----
    force_n : input [N], external force on the mass (+ along x)
    position_m, velocity_mps : outputs (state)
    """

    TYPE = "mass_spring"
    Params = MassSpringParams
    VARIABLES = (inp("force_n", "N", 0.0, "external force (+x)"),
                 out("position_m", "m", 0.0, "position (+x)"),
                 out("velocity_mps", "m/s", 0.0, "velocity (+x)"))

    def initialize(self, t0):
        self.x = self.params.x0_m
        self.v = self.params.v0_mps
        self.y["position_m"] = self.x
        self.y["velocity_mps"] = self.v

    def do_step(self, t, h):
        p = self.params
        f = self.u["force_n"]
        k, m = p.stiffness_n_per_m, p.mass_kg
        n = p.substeps
        dt = h / n
        x, v = self.x, self.v
        for _ in range(n):
            a1 = (f - k * x) / m
            x2, v2 = x + 0.5 * dt * v, v + 0.5 * dt * a1
            a2 = (f - k * x2) / m
            x3, v3 = x + 0.5 * dt * v2, v + 0.5 * dt * a2
            a3 = (f - k * x3) / m
            x4, v4 = x + dt * v3, v + dt * a3
            a4 = (f - k * x4) / m
            x += dt / 6 * (v + 2 * v2 + 2 * v3 + v4)
            v += dt / 6 * (a1 + 2 * a2 + 2 * a3 + a4)
        self.x, self.v = x, v
        self.y["position_m"] = x
        self.y["velocity_mps"] = v


@dataclass(frozen=True, slots=True)
class SpringDamperParams:
    mass_kg: float = 1.0
    stiffness_n_per_m: float = 10.0
    damping_ns_per_m: float = 0.5
    x0_m: float = field(default=0.0, metadata=rng(what="a displacement, either sign"))
    v0_mps: float = 0.0
    substeps: int = 10


class SpringDamper(Component):
    """Second mass coupled to mass 1 through a spring-damper.

    Ports
    -----
    position_m, velocity_mps : inputs, state of mass 1
    force_n : output [N], coupling force acting on mass 1 (+x); direct feedthrough
    position2_m, velocity2_mps : outputs, state of mass 2
    """

    TYPE = "spring_damper"
    Params = SpringDamperParams
    VARIABLES = (inp("position_m", "m", 0.0, "position of mass 1"),
                 inp("velocity_mps", "m/s", 0.0, "velocity of mass 1"),
                 out("force_n", "N", 0.0, "coupling force on mass 1 (+x)", depends_on=("position_m", "velocity_mps")),
                 out("position2_m", "m", 0.0, "position of mass 2"),
                 out("velocity2_mps", "m/s", 0.0, "velocity of mass 2"))

    def _force(self):
        p = self.params
        return (p.stiffness_n_per_m * (self.x2 - self.u["position_m"])
                + p.damping_ns_per_m * (self.v2 - self.u["velocity_mps"]))

    def initialize(self, t0):
        self.x2 = self.params.x0_m
        self.v2 = self.params.v0_mps
        self._out()

    def _out(self):
        self.y["force_n"] = self._force()
        self.y["position2_m"] = self.x2
        self.y["velocity2_mps"] = self.v2

    def do_step(self, t, h):
        p = self.params
        x1, v1 = self.u["position_m"], self.u["velocity_mps"]
        k, c, m = p.stiffness_n_per_m, p.damping_ns_per_m, p.mass_kg
        n = p.substeps
        dt = h / n
        x, v = self.x2, self.v2

        def acc(x, v):
            return (-k * (x - x1) - c * (v - v1)) / m
        for _ in range(n):
            a1 = acc(x, v)
            x2, v2 = x + 0.5 * dt * v, v + 0.5 * dt * a1
            a2 = acc(x2, v2)
            x3, v3 = x + 0.5 * dt * v2, v + 0.5 * dt * a2
            a3 = acc(x3, v3)
            x4, v4 = x + dt * v3, v + dt * a3
            a4 = acc(x4, v4)
            x += dt / 6 * (v + 2 * v2 + 2 * v3 + v4)
            v += dt / 6 * (a1 + 2 * a2 + 2 * a3 + a4)
        self.x2, self.v2 = x, v
        self._out()


@dataclass(frozen=True, slots=True)
class TrivialParams:
    gain: float = 0.5
    n_io: int = 3


class Trivial(Component):
    """A first-order lag on the sum of three inputs (benchmark component).

    Ports: inputs ``in0_1``..``in2_1``, outputs ``out0_1``..``out2_1`` (dimensionless).
    """

    TYPE = "trivial"
    Params = TrivialParams
    VARIABLES = tuple(inp(f"in{i}_1", "1") for i in range(3)) + tuple(out(f"out{i}_1", "1") for i in range(3))

    def initialize(self, t0):
        self.x = 0.0

    def do_step(self, t, h):
        u = self.u
        s = u["in0_1"] + u["in1_1"] + u["in2_1"]
        self.x += h * self.params.gain * (s - self.x)
        y = self.y
        x = self.x
        y["out0_1"] = x
        y["out1_1"] = 0.5 * x
        y["out2_1"] = -x


@dataclass(frozen=True, slots=True)
class GainParams:
    gain: float = 1.0
    offset: float = 0.0


class Gain(Component):
    """Static gain ``out_1 = gain * in_1 + offset`` (direct feedthrough; dimensionless)."""

    TYPE = "gain"
    Params = GainParams
    VARIABLES = (inp("in_1", "1", 0.0, "input"),
                 out("out_1", "1", 0.0, "gain * input + offset", depends_on=("in_1",)))

    def initialize(self, t0):
        self.y["out_1"] = self.params.gain * self.u["in_1"] + self.params.offset

    def do_step(self, t, h):
        self.y["out_1"] = self.params.gain * self.u["in_1"] + self.params.offset
