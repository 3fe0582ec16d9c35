"""The time-stepping methods, ``sim.method``: what each one is and what it can do. Code that depends on the method
asks its entry here (``methods.get(sim.method).adaptive``) instead of testing its name; `finrft.integrate`
implements them. Adding a method: its C stepper (plugins/steppers.c), its numpy twin and its stepper in
`finrft.integrate`, its entry here, and its test.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Method:
    """One value of ``sim.method``."""

    name: str
    doc: str
    implicit: bool  # takes the RFT forces implicitly (the segment laws', differenced on the scale of rft.v_reg, and
                    # the attached surfaces' wrench on each body, its slope in the twist assembled from each
                    # element's analytic Jacobian, or differenced for a law without one); such a method extends
                    # MuJoCo's implicitfast integrator; every other force is MuJoCo's, as implicitfast takes it
    newton: bool    # solves the step by Newton's method at the new velocity (else one linearised iteration)
    adaptive: bool  # sizes its steps by an error estimate (sim.tolerance, sim.max_step); sim.dt is then only the
                    # grid of reversals and samples
    stepper: str    # the native stepper, a function of plugins/steppers.c; "": MuJoCo's own mj_step
    midpoint: float = 0.0  # the RFT force is taken at the positions this fraction of a step ahead, at the
                           # step's starting velocity (0: at the step's start, as MuJoCo takes every force)


METHODS: dict[str, Method] = {m.name: m for m in (
    Method("explicit", "MuJoCo's step, the RFT force as it is (light bodies need dt < 2 m v_reg / F)",
           implicit=False, newton=False, adaptive=False,
           stepper=""),
    Method("implicit", "implicitfast with the RFT force linearised in velocity", implicit=True, newton=False,
           adaptive=False, stepper="finrft_implicit_step"),
    Method("newton", "implicitfast with the RFT force at the new velocity, solved by Newton's method (stable and "
           "accurate at large steps on light segments and bodies)", implicit=True, newton=True, adaptive=False,
           stepper="finrft_implicit_step"),
    Method("newton-midpoint", "newton with the RFT force at the step's midpoint positions (predicted at the "
           "starting velocity): second order in quasi-static motion such as a robot's in sand, but it damps "
           "inertial motion against depth-stiff forces (a dropped body bounces less)", implicit=True, newton=True,
           adaptive=False, stepper="finrft_implicit_step", midpoint=0.5),
    Method("adaptive", "implicit steps sized by an error estimate (dt is then the grid of samples)", implicit=True,
           newton=False, adaptive=True, stepper="finrft_adaptive_advance"),
    Method("adaptive-newton", "newton steps sized by the same estimate", implicit=True, newton=True, adaptive=True,
           stepper="finrft_adaptive_advance"),
)}


# ``sim.method = "auto"``, a robot's default (`scene.RobotSim`): no method of its own but a choice among these, with
# its step, that each run makes before it steps (`finrft.choice`); past that point every scene names a method.
AUTO = "auto"
AUTO_DOC = ("auto: the run chooses the method and step that meet the error limits at the least cost, by short pilot "
            "runs (explicit at its largest accurate step, newton and newton-midpoint at sim.dt or finer)")


def names() -> tuple[str, ...]:
    """Every method, by name, in the table's order."""
    return tuple(METHODS)


def chooses(name: str) -> bool:
    """Whether ``sim.method`` asks the run to choose its method (`AUTO`)."""
    return name == AUTO


def get(name: str) -> Method:
    """The entry of a method named in a validated scene (not `AUTO`, which the run resolves first)."""
    if chooses(name):
        raise ValueError(f"sim.method = {AUTO!r} is resolved by the run (finrft.choice) before a method's entry is "
                         f"read")
    return METHODS[name]


def explicit() -> tuple[str, ...]:
    """The methods that take no force implicitly (MuJoCo's own step): all a scene whose only moving joint is
    prescribed (`finrft.scene.ExplicitSim`) needs, as no free body there feels the medium."""
    return tuple(name for name, m in METHODS.items() if not m.implicit)


def adaptive() -> tuple[str, ...]:
    """The methods that size their steps by an error estimate: the ones that read sim.tolerance and sim.max_step."""
    return tuple(name for name, m in METHODS.items() if m.adaptive)


def described() -> str:
    """Every method in one sentence each, as the schema's documentation of ``sim.method``."""
    return "; ".join(f"{m.name}: {m.doc}" for m in METHODS.values())
