"""Cost per rollout-step of the kinematic, ST and STD simulators in the same loop
(:func:`pfjax.simulate`), float32 and float64."""

from __future__ import annotations

import math
import time

import jax

import pfjax
from pfjax.dynamic_study.config import KinematicVsDynamic


def throughput(config: KinematicVsDynamic) -> dict:
    """Wall time per rollout-step of the kinematic, ST and STD simulators on batches of the same size
    and step count (``bench_runs`` runs of the study's horizon and step on the sine path, Stanley,
    metrics only; best of ``bench_repeats`` interleaved calls after a compiling call), float32 and
    float64. The ST and kinematic runs are the robot's; the STD runs are vehicle 2's at 10 m/s with a
    2 ms step (its wheel modes need it), the same number of steps."""
    sim = config.study.get("sim", {})
    horizon, dt = float(sim.get("horizon", 20.0)), float(sim.get("dt", 0.005))
    steps = round(horizon / dt)
    n = config.bench_runs
    out: dict = {"runs": n, "steps": steps, "controller": "stanley", "path": "sine"}
    setups: dict[str, tuple[dict, float]] = {
        "kinematic": ({"beta_r_deg": 5.0, "beta_f_deg": 5.0}, dt),
        "st": ({"model": "st", "mu": 0.65}, dt),
        "std": ({"model": "std", "vehicle_params": "vehicle2", "mu": 0.65, "speed": 10.0}, 0.002),
    }
    for dtype in ("float32", "float64"):
        with jax.enable_x64(dtype == "float64"):
            calls = {}
            for model, (kw, step) in setups.items():
                runs = pfjax.scenarios("sine", n=n, lateral_offset=pfjax.uniform(-0.5, 0.5), key=0, **kw)
                cfg = {"horizon": steps * step, "dt": step}
                calls[model] = lambda runs=runs, cfg=cfg: pfjax.simulate(runs, "stanley", config=cfg)
                calls[model]()  # compiles
            best = dict.fromkeys(calls, math.inf)
            for _ in range(config.bench_repeats):  # interleaved, so all see the same load on a shared machine
                for model, call in calls.items():
                    t = time.perf_counter()
                    call()
                    best[model] = min(best[model], time.perf_counter() - t)
            row: dict = {m: {"wall_s": b, "ns_per_rollout_step": 1e9 * b / (n * steps)} for m, b in best.items()}
            row["ratio_st_over_kinematic"] = best["st"] / best["kinematic"]
            row["ratio_std_over_kinematic"] = best["std"] / best["kinematic"]
            out[dtype] = row
    return out


__all__ = ["throughput"]
