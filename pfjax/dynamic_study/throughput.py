"""Cost per rollout-step of the kinematic, ST and STD simulators in the same loop, at the study's
horizon and step (:func:`pfjax.bench.models.model_costs`, which ``pfjax bench`` runs too)."""

from __future__ import annotations

from pfjax.bench.models import model_costs
from pfjax.dynamic_study.config import KinematicVsDynamic


def throughput(config: KinematicVsDynamic) -> dict:
    """Wall time per rollout-step of the kinematic, ST and STD simulators on batches of the same size
    and step count (``bench_runs`` runs of the study's horizon and step on the sine path, Stanley,
    metrics only; best of ``bench_repeats`` interleaved calls after a compiling call), float32 and
    float64. The ST and kinematic runs are the robot's; the STD runs are vehicle 2's at 10 m/s with a
    2 ms step (its wheel modes need it), the same number of steps."""
    sim = config.study.get("sim", {})
    horizon, dt = float(sim.get("horizon", 20.0)), float(sim.get("dt", 0.005))
    return model_costs(config.bench_runs, round(horizon / dt), dt, config.bench_repeats)


__all__ = ["throughput"]
