"""Search of the garage switching parameters (X_s, α₁, α₂): the source's 24-bit GA and a grid (docs/reproductions/parking.md §5).

Fitness (the source's formula was lost; **assumed**, configurable weight ``w``)::

    J = 1 / (t_e + w · (|x_e| + sqrt(y_e² + tan²θ_e)))      (w = 100)

with the end time t_e (s) and end pose of the run; J = 0 when the run fails by too many
switches (more than 10: the source's search cut-off, :data:`SEARCH_CONFIG`), by the heading
limit, by a non-finite state or stuck (a timeout keeps its J, which is then small: t_e = 200 s
plus the end error). The grid and the start map share the fitness and the cut-off. The GA (:func:`pfjax.tuning.ga.ga_bits`) minimises −J.
The grid evaluates every combination of ``n`` levels per gene chosen on the chromosome's own
lattice (ξ = round(linspace(0, 255, n))), so the GA's optimum and the grid's are comparable and
any GA result can be re-simulated exactly.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np

from pfjax.parking.defaults import CHUNK, GENERATIONS, GRID_N, POPULATION, WEIGHT
from pfjax.parking.schedules import ALPHA_MAX, GARAGE_START, XS_MAX, XS_MIN, decode_bits, three_phase
from pfjax.parking.simulate import SEARCH_MAX_SWITCHES, ParkingConfig, RunParams, Status, run_many, run_params

FAILED = (
    int(Status.TOO_MANY_SWITCHES),
    int(Status.HEADING_LIMIT),
    int(Status.NONFINITE),
    int(Status.STUCK),
    int(Status.START_OVERLAP),
)
#: The search's simulation settings: the source's cut-off at 10 switches decides what a repeatedly
#: switching candidate is, so the progress test (``stuck``) is off.
SEARCH_CONFIG = ParkingConfig(max_switches=SEARCH_MAX_SWITCHES, stuck_switches=None)


def fitness(status, time, error, weight: float = WEIGHT):
    """J = 1 / (t_e + w e_e), 0 for failed runs (NumPy or JAX arrays)."""
    xp = jnp if isinstance(status, jax.Array) else np
    failed = xp.isin(status, xp.asarray(FAILED))
    return xp.where(failed, 0.0, 1.0 / (time + weight * error))


def batch_params(base: RunParams, xs, alpha1, alpha2, pose0=None) -> RunParams:
    """``base`` broadcast to the length of ``xs`` with (X_s, α₁, α₂) (and optionally start poses) set."""
    xs = jnp.asarray(xs, float)
    n = xs.shape[0]
    p = jax.tree_util.tree_map(lambda a: jnp.broadcast_to(a, (n,) + a.shape), base)
    p = p._replace(xs=xs, use_xs=jnp.ones(n), schedule=three_phase(alpha1, alpha2))
    return p if pose0 is None else p._replace(pose0=jnp.asarray(pose0, float))


def garage_base(start=GARAGE_START, **kw) -> RunParams:
    """The garage run (start in x m, y m, θ deg; forward; α = 1 at the start)."""
    return run_params(start, 1, (1.0,), xs=-1.0, **kw)


def search_ga(
    omap,
    *,
    key,
    start=GARAGE_START,
    options=None,
    weight=WEIGHT,
    cfg=SEARCH_CONFIG,
    progress=False,
    base: RunParams | None = None,
) -> dict:
    """The source's GA: 24 bits, n = 20, N = 100 by default; returns the best decoded parameters."""
    from pfjax.tuning.ga import GAOptions, ga_bits

    options = options or GAOptions(population_size=POPULATION, generations=GENERATIONS)
    base = base if base is not None else garage_base(start)

    def cost_batch(bits):
        xs, a1, a2 = decode_bits(jnp.asarray(bits))
        r = run_many(batch_params(base, xs, a1, a2), omap, cfg, chunk=options.population_size)
        return -np.asarray(fitness(r.status, r.time, r.error, weight))

    res = ga_bits(cost_batch, 24, key=key, options=options, progress=progress)
    xs, a1, a2 = (float(v[0]) for v in decode_bits(jnp.asarray(res.x)[None]))
    best = evaluate(omap, base, [xs], [a1], [a2], cfg=cfg, weight=weight, chunk=options.population_size)
    return {
        "method": "ga",
        "xs": xs,
        "alpha1": a1,
        "alpha2": a2,
        "bits": [int(b) for b in res.x],
        "fitness": -float(res.f),
        **{k: v[0].item() for k, v in best.items() if k not in ("xs", "alpha1", "alpha2")},
        "n_simulations": int(res.n_evaluations),
        "history_best_fitness": (-np.asarray(res.history_best)).tolist(),
        "history_mean_fitness": (-np.asarray(res.history_mean)).tolist(),
    }


def evaluate(
    omap,
    base: RunParams,
    xs,
    alpha1,
    alpha2,
    *,
    cfg=SEARCH_CONFIG,
    weight=WEIGHT,
    pose0=None,
    chunk=CHUNK,
    progress=False,
) -> dict:
    """Batched runs at the given parameters -> NumPy columns (status, time_s, switches, fitness, ...)."""
    r = run_many(batch_params(base, xs, alpha1, alpha2, pose0), omap, cfg, chunk=chunk, progress=progress, desc="grid")
    return {
        "xs": np.asarray(xs, float),
        "alpha1": np.asarray(alpha1, float),
        "alpha2": np.asarray(alpha2, float),
        "status": r.status.astype(int),
        "time_s": r.time,
        "switches": r.n_switches.astype(int),
        "error": r.error,
        "fitness": fitness(r.status, r.time, r.error, weight),
    }


def lattice(n: int) -> tuple[np.ndarray, np.ndarray]:
    """n levels per gene on the chromosome lattice: (X_s levels, α levels)."""
    xi = np.round(np.linspace(0, 255, n))
    return XS_MIN + (XS_MAX - XS_MIN) * xi / 255.0, ALPHA_MAX * (xi + 1) / 256.0


def search_grid(
    omap,
    *,
    n=GRID_N,
    start=GARAGE_START,
    weight=WEIGHT,
    cfg=SEARCH_CONFIG,
    chunk=CHUNK,
    progress=False,
    base: RunParams | None = None,
) -> dict:
    """Exhaustive n × n × n grid over (X_s, α₁, α₂); returns the best and every evaluation."""
    base = base if base is not None else garage_base(start)
    xl, al = lattice(n)
    X, A1, A2 = (g.ravel() for g in np.meshgrid(xl, al, al, indexing="ij"))
    table = evaluate(omap, base, X, A1, A2, cfg=cfg, weight=weight, chunk=chunk, progress=progress)
    i = int(np.argmax(table["fitness"]))
    return {
        "method": "grid",
        "n": n,
        "xs": float(X[i]),
        "alpha1": float(A1[i]),
        "alpha2": float(A2[i]),
        "fitness": float(table["fitness"][i]),
        "time_s": float(table["time_s"][i]),
        "status": int(table["status"][i]),
        "switches": int(table["switches"][i]),
        "error": float(table["error"][i]),
        "n_simulations": int(X.size),
        "table": table,
    }


def start_map(
    omap,
    x0s,
    theta0s_deg,
    *,
    y0=GARAGE_START[1],
    n=12,
    weight=WEIGHT,
    cfg=SEARCH_CONFIG,
    chunk=CHUNK,
    progress=False,
    base: RunParams | None = None,
) -> list[dict]:
    """For each start (x₀, θ₀): the best (X_s, α₁, α₂) on an n³ grid, its parking time, the best
    run's status and switches, and the fraction of the grid's runs that converge. ``base``: the run
    settings other than the start pose and the schedule (controller, reach a_f, scanner period;
    default :func:`garage_base`)."""
    base = base if base is not None else garage_base()
    xl, al = lattice(n)
    X, A1, A2 = (g.ravel() for g in np.meshgrid(xl, al, al, indexing="ij"))
    starts = [(x0, th) for x0 in x0s for th in theta0s_deg]
    m = X.size
    poses = np.concatenate([np.tile([[x0, y0, math.radians(th)]], (m, 1)) for x0, th in starts])
    table = evaluate(
        omap,
        base,
        np.tile(X, len(starts)),
        np.tile(A1, len(starts)),
        np.tile(A2, len(starts)),
        cfg=cfg,
        weight=weight,
        pose0=poses,
        chunk=chunk,
        progress=progress,
    )
    rows = []
    for k, (x0, th) in enumerate(starts):
        sl = slice(k * m, (k + 1) * m)
        f = table["fitness"][sl]
        i = int(np.argmax(f))
        ok = table["status"][sl] == int(Status.CONVERGED)
        rows.append(
            {
                "x0": x0,
                "theta0_deg": th,
                "y0": y0,
                "xs": float(X[i]),
                "alpha1": float(A1[i]),
                "alpha2": float(A2[i]),
                "fitness": float(f[i]),
                "time_s": float(table["time_s"][sl][i]),
                "status": int(table["status"][sl][i]),
                "switches": int(table["switches"][sl][i]),
                "converged_fraction": float(ok.mean()),
            }
        )
    return rows
