"""A study's worst-case search: pfjax.falsification.falsify per controller against random search at equal budget."""

from __future__ import annotations

import math

import jax
import numpy as np

from pfjax import paths
from pfjax.falsification import falsify, random_search, worst_trajectory
from pfjax.montecarlo.config import StudySpec
from pfjax.montecarlo.runner import sample_few, sim_config
from pfjax.numerics.random import seed_key
from pfjax.sim.simulate import unstack
from pfjax.sim.status import STATUS_NAMES

#: Random search's batch (runs per simulator call).
SEARCH_BATCH = 64

#: The path's points for the figure, one jitted program (op by op: one compile per operation).
_points = jax.jit(lambda path, u: path.point(u))


def worst_cases(spec: StudySpec, controllers) -> tuple[dict, dict]:
    """Per controller: the falsifier's and random search's worst objective (same rollouts) and the
    falsifier's worst trajectory. Returns ``(summary blocks, trajectories)``; call inside ``precision(spec)``."""
    blocks, trajs = {}, {}
    for i, name in enumerate(controllers):
        blocks[name], trajs[name] = worst_case(spec, controllers, i)
    return blocks, trajs


def worst_case(spec: StudySpec, controllers, i: int, devices=None) -> tuple[dict, dict]:
    """:func:`worst_cases` for controller ``i`` alone (its own PRNG stream, so the controllers can
    be searched in any order or concurrently): ``(summary block, trajectory)``. Call inside
    ``precision(spec)``. ``devices``: where the batched simulations run (default: all devices);
    the gradient steps run on JAX's default device."""
    f = spec.falsifier
    labels = [p.label for p in spec.paths]
    p = labels.index(f.path) if f.path is not None else 0
    run0 = unstack(sample_few(spec, p, np.arange(1)).scenarios, 0)
    cfg = sim_config(spec)
    bounds = dict(
        slip_bound_deg=f.slip_bound_deg,
        f_max_hz=f.f_max_hz,
        objective=f.objective,
        ic_bounds={
            "d": (-f.lateral_offset, f.lateral_offset) if f.lateral_offset > 0 else 0.0,
            "theta_e_deg": (-f.heading_error_deg, f.heading_error_deg) if f.heading_error_deg > 0 else 0.0,
            "u": paths.entry(spec.paths[p].kind).start_u,
        },
        params=run0.params,
    )
    key = jax.random.fold_in(seed_key(spec.seed), 0xFA15)
    name, (controller, gains, _) = list(controllers.items())[i]
    k1, k2 = jax.random.split(jax.random.fold_in(key, i))
    fr = falsify(controller, gains, run0.path, n_restarts=f.n_restarts, steps=f.steps, key=k1, config=cfg, **bounds)
    # Random search does not record, and the replay records one run: recording 64 runs (12 MB of
    # trajectory) takes XLA's CPU loop out of its one-function form (the loop state passes the small
    # loop threshold), 0.6 s per call instead of 15 ms (measured); one recorded run takes 6 ms.
    rr = random_search(
        controller,
        gains,
        run0.path,
        n_samples=int(fr.n_rollouts),
        key=k2,
        batch_size=SEARCH_BATCH,
        config=cfg,
        devices=devices,
        **bounds,
    )
    tr = jax.device_get(worst_trajectory(controller, fr, cfg, devices=devices).trajectory)
    slip = np.degrees(np.asarray(fr.slip))
    block = {
        "path": labels[p],
        "objective": f.objective,
        "falsifier": float(fr.objective),
        "falsifier_status": STATUS_NAMES[int(fr.status)],
        "random": float(rr.objective),
        "random_status": STATUS_NAMES[int(rr.status)],
        "n_rollouts": int(fr.n_rollouts),
        "n_gradients": int(fr.n_gradients),
        "ratio": float(fr.objective) / float(rr.objective) if float(rr.objective) > 0 else math.nan,
        "worst_ic": {"d0": float(fr.ic[0]), "theta_e0_deg": math.degrees(float(fr.ic[1]))},
        "worst_slip_peak_deg": [float(np.abs(slip[:, 0]).max()), float(np.abs(slip[:, 1]).max())],
        "history": np.asarray(fr.history).tolist(),
        "history_rollouts": np.asarray(fr.history_rollouts).tolist(),
        "history_random": np.asarray(rr.history).tolist(),
        "history_random_rollouts": np.asarray(rr.history_rollouts).tolist(),
    }
    px, py = _points(run0.path, np.linspace(float(run0.path.u_min), float(run0.path.u_max), 4000))
    traj = {
        "t": np.asarray(tr.t),
        "x": np.asarray(tr.x),
        "y": np.asarray(tr.y),
        "d": np.asarray(tr.d),
        "beta_r": np.asarray(tr.beta_r),
        "beta_f": np.asarray(tr.beta_f),
        "path_x": np.asarray(px),
        "path_y": np.asarray(py),
    }
    return block, traj
