"""Checks of a study that are not errors: feasibility warnings before it runs, precision after.

:func:`study_warnings` flags paths that the robot cannot follow with its steering limit: the
slip model (eq. 2) turns with curvature at most ``kappa_max = tan(delta_max) / L``, so a path
whose curvature exceeds it (for the most restrictive vehicle of the distributions: smallest
``delta_max``, largest ``L``) cannot be followed even without slip. Such a study still runs
(failures are data); the warning goes to stderr and into ``summary.json``.

:func:`float64_check` re-simulates a sample of a float32 study's runs in float64 (the same
sampled scenarios and gains, cast up) and reports how far the metrics and statuses move.
"""

from __future__ import annotations

import math
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import pandas as pd

from pfjax.montecarlo.config import PathSpec, StudySpec
from pfjax.sim.status import STATUS_NAMES


def path_max_curvature(p: PathSpec) -> float:
    """Largest |curvature| (1/m) the path can have over the support of its distributions."""
    from pfjax import paths

    bound = paths.entry(p.kind).max_curvature  # the registry's, for a fixed path
    if bound is not None:
        return bound
    if p.kind == "circle":
        return 1.0 / p.radius.bounds()[0]
    if p.kind == "spline":
        from pfjax.paths import shapes
        from pfjax.paths.geometry import curvature

        with jax.enable_x64(True):
            path = shapes.spline_through(np.asarray(p.points, float))
            u = jnp.linspace(path.u_min, path.u_max, 4001)
            return float(jnp.max(jnp.abs(curvature(path, u))))
    return math.nan  # random paths are built below the followable curvature by construction


def path_length(p: PathSpec) -> float:
    """Length (m) of a user-defined spline path (inf for the built-in shapes, long enough by design)."""
    if p.kind != "spline":
        return math.inf
    return float(np.linalg.norm(np.diff(np.asarray(p.points, float), axis=0), axis=1).sum())


def run_counts(spec: StudySpec) -> dict[str, int]:
    """The runs a study simulates, before it runs: ``per_controller_and_path`` (``n_runs``),
    ``per_controller`` (over its paths), ``study`` (every controller), ``margin_per_axis_and_path``
    (amplitudes x ``n_per_amplitude``) and ``margin`` (the sweep, every axis, path and controller;
    0 when it is off). The summary's ``n_runs_total`` and ``n_margin_runs`` count what ran."""
    n_ctrl, n_path, m = len(spec.controllers), len(spec.paths), spec.margin
    per_axis = m.n_per_amplitude * len(m.amplitudes_deg)
    return {
        "per_controller_and_path": spec.n_runs,
        "per_controller": spec.n_runs * n_path,
        "study": spec.n_runs * n_path * n_ctrl,
        "margin_per_axis_and_path": per_axis,
        "margin": per_axis * len(m.axes) * n_path * n_ctrl if m.enabled else 0,
    }


def check_resources(spec: StudySpec, *, report: bool = True, no_report: str = "pfjax study --no-report") -> None:
    """Refuse a study whose memory need exceeds :func:`pfjax.resources.memory_budget`, before it
    starts (:class:`~pfjax.errors.InputError` naming the key). The runs stream chunk by chunk, so
    a chunk bounds the simulation's memory (its batch of scenarios, slip sequences and paths, the
    simulator's state and the chunk's table); the report loads the whole run table; the slip-margin
    sweep holds its run indices. ``no_report``: how the caller leaves the report out, in the advice
    (``report=False`` for :func:`pfjax.run_study`)."""
    from pfjax.resources import check_memory, run_bytes

    s = spec.sim
    n_steps = int(round(s.horizon / s.dt))
    seq = int(math.ceil(s.horizon / spec.slip.seq_dt)) + 2 if spec.slip.kind == "ou" else 0
    path_numbers = max((16 * p.n_waypoints if p.kind == "random" else 16 * len(p.points or ())) for p in spec.paths)
    chunk = min(spec.chunk_size, spec.n_runs)
    # a chunk: sampled scenarios (kept for the next controller), the simulator's batch, its table:
    # 8 runs' worth per run (measured: 10^7 runs in chunks of 65,536 peaked at 1.8 GiB, 18 kB per run
    # of a chunk above the process's 0.6 GiB)
    check_memory(
        "chunk_size",
        8 * chunk * run_bytes(n_steps, seq_len=seq, path_numbers=path_numbers),
        f"a chunk of {chunk} runs",
        "lower chunk_size (the runs stream chunk by chunk)",
    )
    counts = run_counts(spec)
    if report:
        rows = counts["study"]
        check_memory(
            "n_runs",
            8 * 64 * rows,
            f"the report's run table ({rows:.3g} rows)",
            f"run without the report ({no_report}), or lower n_runs",
        )
    if spec.margin.enabled:
        per_axis = counts["margin_per_axis_and_path"]
        check_memory(
            "margin.n_per_amplitude",
            8 * 6 * per_axis,
            f"a slip-margin sweep of {per_axis:.3g} runs per axis",
            "lower margin.n_per_amplitude",
        )


def study_warnings(spec: StudySpec) -> list[str]:
    """One-line warnings: paths sharper than the steering limit allows, spline paths shorter than
    the distance a run travels (each names the path, ``paths[i]``, and the numbers), and start
    offsets beyond the failure band (``initial.lateral_offset`` against ``sim.d_fail``: such runs
    end as diverged at t = 0)."""
    v = spec.vehicle
    dmax_lo, L_hi = v.delta_max_deg.bounds()[0], v.L.bounds()[1]
    kappa_follow = math.tan(math.radians(dmax_lo)) / L_hi
    travel = v.speed.bounds()[1] * spec.sim.horizon + spec.initial.start_along_m.bounds()[1]
    out = []
    lo, hi = spec.initial.lateral_offset.bounds()
    reach = max(abs(lo), abs(hi))
    if math.isfinite(reach) and reach > spec.sim.d_fail:  # a bounded law; a normal one reaches any offset
        out.append(
            f"initial.lateral_offset: starts up to {reach:.4g} m from the path, beyond sim.d_fail = "
            f"{spec.sim.d_fail:g} m: runs that start beyond it end as diverged at t = 0"
        )
    for i, p in enumerate(spec.paths):
        k = path_max_curvature(p)
        if math.isfinite(k) and k > kappa_follow:
            out.append(
                f"paths[{i}] ({p.label}): max curvature {k:.4g} 1/m exceeds tan(delta_max)/L = "
                f"tan({dmax_lo:g} deg)/{L_hi:g} m = {kappa_follow:.4g} 1/m: the robot cannot follow it "
                f"with its steering limit, even without slip"
            )
        length = path_length(p)
        if travel > length:
            out.append(
                f"paths[{i}] ({p.label}): {length:.4g} m long, but a run may travel {travel:.4g} m "
                f"(speed x horizon + start_along_m): runs that reach its end stop with status path_end"
            )
    return out


def _cast64(tree):
    return jax.tree_util.tree_map(
        lambda a: jnp.asarray(np.asarray(a), jnp.float64) if jnp.issubdtype(jnp.asarray(a).dtype, jnp.floating) else a,
        tree,
    )


def sample_indices(spec: StudySpec, n_sample: int) -> np.ndarray:
    """Run indices checked per path: ``ceil(n_sample / n_paths)`` spread evenly over the study's runs."""
    k = min(spec.n_runs, max(1, math.ceil(n_sample / len(spec.paths))))
    return np.unique(np.linspace(0, spec.n_runs - 1, k).round().astype(np.int64))


def float64_runs(spec: StudySpec, controllers: dict, n_sample: int, path_index: int, devices=None) -> dict:
    """The float64 half of :func:`float64_check` for one path: ``{controller name: SimResult}`` (NumPy,
    the :func:`sample_indices` runs only). Independent of the float32 study, so it can run before
    or while the study does. ``devices``: as :func:`~pfjax.sim.simulate_batch`."""
    from pfjax.montecarlo.runner import sample_few, sim_config, simulate_scenarios, with_gains

    idx = sample_indices(spec, n_sample)
    with jax.enable_x64(False):
        sampled = sample_few(spec, path_index, idx)
    m = jax.tree_util.tree_leaves(sampled.scenarios)[0].shape[0]
    out = {}
    for name, (ctrl, gains, _) in controllers.items():
        with jax.enable_x64(True):
            sc = _cast64(sampled.scenarios)
            res = jax.device_get(
                simulate_scenarios(
                    with_gains(sc, _cast64(gains), m), controller=ctrl, config=sim_config(spec), devices=devices
                )
            )
            out[name] = jax.tree_util.tree_map(lambda a: np.asarray(a)[: len(idx)], res)
    return out


def float64_check(
    spec: StudySpec, controllers: dict, runs: pd.DataFrame, n_sample: int, sims: list | None = None
) -> dict:
    """Re-simulate ``n_sample`` runs per controller (spread over the paths) in float64 and compare
    with the float32 rows of ``runs``: max |dIAE| (m s), max relative dIAE, max |d late max|, and the
    runs whose status or success differs. The scenarios are sampled in float32 (exactly those the
    study ran) and cast up, so only the arithmetic precision differs, except measurement noise,
    which the simulator draws at the run's precision (a different realisation in float64).
    ``sims``: :func:`float64_runs` per path if already computed."""
    if spec.dtype == "float64" or n_sample <= 0:
        return {
            "checked": False,
            "reason": "the study runs in float64" if spec.dtype == "float64" else "disabled (f64_check_runs = 0)",
        }
    idx = sample_indices(spec, n_sample)
    per: dict[str, Any] = {}
    for p, pspec in enumerate(spec.paths):
        sim = sims[p] if sims is not None else float64_runs(spec, controllers, n_sample, p)
        for name in controllers:
            res = sim[name]
            f32 = runs[(runs.path == pspec.label) & (runs.controller == name)].set_index("run").loc[idx]
            block = per.setdefault(
                name, {"n": 0, "iae_abs": [], "iae_rel": [], "late": [], "status_mismatch": [], "success_mismatch": 0}
            )
            iae64 = np.asarray(res.metrics.iae, float)
            iae32 = f32["iae"].to_numpy(float)
            st64 = np.asarray(res.status).astype(int)
            # metrics compare only where both precisions end the same way (a run that fails at another
            # time has metrics over another interval; the status change itself is reported below)
            both = np.isfinite(iae64) & np.isfinite(iae32) & (st64 == f32["status_code"].to_numpy(int))
            block["n"] += len(idx)
            block["iae_abs"] += list(np.abs(iae64 - iae32)[both])
            block["iae_rel"] += list((np.abs(iae64 - iae32) / np.maximum(np.abs(iae64), 1e-12))[both])
            block["late"] += list(
                np.abs(np.asarray(res.metrics.late_max_abs_d, float) - f32["late_max_abs_d"].to_numpy(float))[both]
            )
            for r, a, b in zip(idx, f32["status_code"].to_numpy(int), st64):
                if a != b:
                    block["status_mismatch"].append(
                        {
                            "path": pspec.label,
                            "run": int(r),
                            "float32": STATUS_NAMES[a],
                            "float64": STATUS_NAMES[int(b)],
                        }
                    )
            block["success_mismatch"] += int(
                (np.asarray(res.metrics.success, bool) != f32["success"].to_numpy(bool)).sum()
            )
    out = {
        "checked": True,
        "n_per_controller": int(len(idx) * len(spec.paths)),
        "run_indices": idx.tolist(),
        "noise_realisation_differs": bool(spec.noise.sigma_d > 0 or spec.noise.sigma_theta_e_deg > 0),
        "controllers": {},
    }
    for name, b in per.items():
        mx = lambda xs: float(max(xs)) if xs else None
        out["controllers"][name] = {
            "n": b["n"],
            "max_abs_diff_iae": mx(b["iae_abs"]),
            "max_rel_diff_iae": mx(b["iae_rel"]),
            "max_abs_diff_late_max_abs_d": mx(b["late"]),
            "status_agreement": 1 - len(b["status_mismatch"]) / b["n"],
            "success_agreement": 1 - b["success_mismatch"] / b["n"],
            "status_mismatches": b["status_mismatch"][:20],
        }
    return out
