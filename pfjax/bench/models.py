"""Cost per rollout-step of the vehicle models in the one simulation loop: the kinematic slip
model, the single-track model (ST) and the single-track drift model (STD), each through
:func:`pfjax.simulate` (the full simulator: metrics, statuses, the steering actuator and speed loop
of the dynamic models), on batches of the same size and step count, float32 and float64.

The problem: ``n`` runs on the sine path under Stanley, lateral offsets uniform in ±0.5 m, metrics
only. The kinematic and ST runs are the robot's (1 m/s, the study's step); the STD runs are
CommonRoad's vehicle 2 at 10 m/s with a 2 ms step (its wheel-speed modes need it), the same number
of steps. The time of a model is the best of ``repeats`` rounds, each model timed in turn with the
other models so that all see the same load on a shared machine, after one compiling call
(:func:`pfjax.bench.timing.interleaved`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import jax

from pfjax.bench import timing

#: a model's scenario keywords (:func:`pfjax.scenarios`) and its step, s (None: the caller's step)
MODELS: dict[str, tuple[dict, float | None]] = {
    "kinematic": ({"beta_r_deg": 5.0, "beta_f_deg": 5.0}, None),
    "st": ({"model": "st", "mu": 0.65}, None),
    "std": ({"model": "std", "vehicle_params": "vehicle2", "mu": 0.65, "speed": 10.0}, 0.002),
}


def model_costs(
    n: int,
    steps: int,
    dt: float,
    repeats: int,
    models: Sequence[str] = tuple(MODELS),
    progress: Callable[[str], None] | None = None,
) -> dict:
    """Wall time per rollout-step of each of ``models`` (module docstring), float32 and float64.

    Args:
        n: runs per batch.
        steps: steps per run.
        dt: the kinematic and ST models' step, s.
        repeats: timed rounds per model (the best is kept).
        models: names in :data:`MODELS`; ``"kinematic"`` first (the ratios' denominator).
        progress: called with a short message before each precision.

    Returns:
        ``{"runs", "steps", "controller", "path", "float32": row, "float64": row}`` with
        ``row[model] = {"wall_s", "ns_per_rollout_step"}`` and ``row["ratio_<model>_over_kinematic"]``
        for each other model.
    """
    import pfjax

    out: dict = {"runs": n, "steps": steps, "controller": "stanley", "path": "sine"}
    for dtype in ("float32", "float64"):
        if progress:
            progress(f"vehicle models {', '.join(models)}, {dtype}, B={n}")
        with jax.enable_x64(dtype == "float64"):
            calls = {}
            for model in models:
                kw, step = MODELS[model]
                h = dt if step is None else step
                runs = pfjax.scenarios("sine", n=n, lateral_offset=pfjax.uniform(-0.5, 0.5), key=0, **kw)
                cfg = {"horizon": steps * h, "dt": h}
                calls[model] = lambda runs=runs, cfg=cfg: pfjax.simulate(runs, "stanley", config=cfg)
            _, _, seconds = timing.interleaved(list(calls.values()), repeats)
            best = dict(zip(calls, seconds))
        row: dict = {m: {"wall_s": b, "ns_per_rollout_step": 1e9 * b / (n * steps)} for m, b in best.items()}
        for m in models:
            if m != "kinematic":
                row[f"ratio_{m}_over_kinematic"] = best[m] / best["kinematic"]
        out[dtype] = row
    return out


__all__ = ["MODELS", "model_costs"]
