"""Simulation: slip profiles, the RK4 scan loop, batching, run status."""

from pfjax.sim.loop import stack, unstack
from pfjax.sim.simulate import Final, Scenario, SensorNoise, SimConfig, SimResult, Trajectory, simulate, simulate_batch
from pfjax.sim.slip_profiles import (
    SlipProfile,
    constant_slip,
    sampled_slip,
    sinusoid_slip,
    slip_at,
    slip_profile,
    step_slip,
)
from pfjax.sim.status import STATUS_NAMES, Status

__all__ = [
    "STATUS_NAMES",
    "Final",
    "Scenario",
    "SensorNoise",
    "SimConfig",
    "SimResult",
    "SlipProfile",
    "Status",
    "Trajectory",
    "constant_slip",
    "sampled_slip",
    "simulate",
    "simulate_batch",
    "sinusoid_slip",
    "slip_at",
    "slip_profile",
    "stack",
    "step_slip",
    "unstack",
]
