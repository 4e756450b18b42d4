"""The source's test scenarios (spec §6) and a builder for single scenarios.

| test     | path        | initial (x, y) | initial theta |
|----------|-------------|----------------|---------------|
| line     | y = x       | (1, 0)         | pi/2          |
| parabola | y = x^2     | (-2, 3)        | -pi/2         |
| sine     | y = sin x   | (0, -0.2)      | pi/4          |

Slip ``beta_r = beta_f = 5 deg`` in all tests (source). *Assumed*: steering limit 30 deg,
horizon 20 s, direction of travel increasing ``x``. The circle (radius 2 m, centre (0, 2),
start (0, -0.3), heading 0) is pfjax's own extra scenario, not the source's.
"""

from __future__ import annotations

import math

import jax.numpy as jnp

from pfjax.models.slip import CONVENTIONS, Pose, SlipParams
from pfjax.paths import shapes
from pfjax.sim.simulate import Scenario
from pfjax.sim.slip_profiles import SlipProfile, constant_slip

PAPER_SLIP_DEG = 5.0
PAPER_TESTS = ("line", "parabola", "sine")

#: name -> (path factory, (x0, y0, theta0))
SCENARIOS = {
    "line": (shapes.line, (1.0, 0.0, math.pi / 2)),
    "parabola": (shapes.parabola, (-2.0, 3.0, -math.pi / 2)),
    "sine": (shapes.sine, (0.0, -0.2, math.pi / 4)),
    "circle": (lambda: shapes.circle(radius=2.0, cy=2.0), (0.0, -0.3, 0.0)),
}


def make_scenario(path, pose0, gains, *, slip: SlipProfile | None = None, v=1.0, L=0.2,
                  delta_max_deg=30.0, convention="source") -> Scenario:
    """One scenario from plain values (angles in ``pose0`` in rad; ``delta_max_deg`` in degrees)."""
    if convention not in CONVENTIONS:
        raise ValueError(f"convention: expected one of {sorted(CONVENTIONS)}, got {convention!r}")
    f = lambda a: jnp.asarray(a, dtype=float)
    return Scenario(
        pose0=Pose(*(f(a) for a in pose0)),
        slip=constant_slip(0.0, 0.0) if slip is None else slip,
        params=SlipParams(v=f(v), L=f(L), delta_max=f(math.radians(delta_max_deg)),
                          convention=jnp.asarray(CONVENTIONS[convention], jnp.int32)),
        path=path,
        gains=gains,
    )


def paper_scenario(test: str, gains, *, beta_r_deg=PAPER_SLIP_DEG, beta_f_deg=PAPER_SLIP_DEG, pose0=None,
                   **kwargs) -> Scenario:
    """The source's ``test`` ("line", "parabola", "sine"; or pfjax's "circle") with constant slip."""
    if test not in SCENARIOS:
        raise ValueError(f"path: expected one of {sorted(SCENARIOS)}, got {test!r}")
    factory, default_pose = SCENARIOS[test]
    slip = constant_slip(math.radians(beta_r_deg), math.radians(beta_f_deg))
    return make_scenario(factory(), default_pose if pose0 is None else pose0, gains, slip=slip, **kwargs)
