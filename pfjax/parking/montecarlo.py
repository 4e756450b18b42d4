"""Robustness Monte Carlo of a parking schedule: start-pose scatter, scanner period, speed, yaw-rate lag.

Run ``i`` draws every quantity from ``fold_in(fold_in(key, i), quantity)``, so the sample does not
depend on the chunk size and two schedules compared on the same key see the same runs (common
random numbers). Distributions (all uniform; ``lag_probability`` a Bernoulli):

    x₀, y₀ ± pos_scatter (m),  θ₀ ± theta_scatter_deg,  T_s ∈ [scan_lo, scan_hi] s,
    |v₁| ∈ [speed_lo, speed_hi] m/s,  yaw-rate PI loop on with probability lag_probability.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pandas as pd

from pfjax.metrics.robustness import metric_quantiles, success_summary
from pfjax.parking.defaults import CHUNK, Scatter
from pfjax.parking.simulate import STATUS_NAMES, ParkingConfig, RunParams, Status, run_many

QUANTITIES = ("x0", "y0", "theta0", "scan", "speed", "lag")


def sample(key, n: int, base: RunParams, s: Scatter) -> RunParams:
    """(n,) batched parameters around ``base`` (one run's parameters)."""

    def draw(i):
        k = jax.random.fold_in(key, i)
        u = [jax.random.uniform(jax.random.fold_in(k, q)) for q in range(len(QUANTITIES))]
        dth = math.radians(s.theta_scatter_deg)
        pose = base.pose0 + jnp.stack(
            [(2 * u[0] - 1) * s.pos_scatter, (2 * u[1] - 1) * s.pos_scatter, (2 * u[2] - 1) * dth]
        )
        scan = s.scan_lo + (s.scan_hi - s.scan_lo) * u[3]
        speed = s.speed_lo + (s.speed_hi - s.speed_lo) * u[4]
        lag = (u[5] < s.lag_probability).astype(pose.dtype)
        return pose, scan, speed, lag

    pose, scan, speed, lag = jax.vmap(draw)(jnp.arange(n))
    p = jax.tree_util.tree_map(lambda a: jnp.broadcast_to(a, (n,) + a.shape), base)
    return p._replace(pose0=pose, scan_period=scan, control=p.control._replace(speed=speed, lag=lag))


def monte_carlo(
    omap, base: RunParams, *, key, n: int, scatter=Scatter(), cfg=ParkingConfig(), chunk=CHUNK, progress=False, label=""
) -> pd.DataFrame:
    """One row per run: sampled quantities, status, parking time, switches."""
    p = sample(key, n, base, scatter)
    r = run_many(p, omap, cfg, chunk=chunk, progress=progress, desc=f"monte carlo {label}".strip())
    pose = np.asarray(p.pose0)
    return pd.DataFrame(
        {
            "schedule": label,
            "run": np.arange(n),
            "x0": pose[:, 0],
            "y0": pose[:, 1],
            "theta0_deg": np.degrees(pose[:, 2]),
            "scan_period_s": np.asarray(p.scan_period),
            "speed": np.asarray(p.control.speed),
            "lag": np.asarray(p.control.lag) > 0.5,
            "status": [STATUS_NAMES[int(c)] for c in r.status],
            "status_code": r.status.astype(int),
            "converged": r.status == int(Status.CONVERGED),
            "time_s": r.time,
            "switches": r.n_switches.astype(int),
            "error": r.error,
        }
    )


def summarise(df: pd.DataFrame) -> dict:
    """Success rate with its Clopper-Pearson 95 % interval, status counts, parking-time quantiles (converged runs)."""
    out = success_summary(df["converged"].to_numpy())
    out["status_counts"] = {name: int((df["status"] == name).sum()) for name in STATUS_NAMES.values()}
    conv = df[df["converged"]]
    out["time_s"] = metric_quantiles(conv, ["time_s"])["time_s"]
    out["switches"] = metric_quantiles(conv, ["switches"])["switches"]
    by_lag = {}
    for lag, g in df.groupby("lag"):
        by_lag["lag_on" if lag else "lag_off"] = success_summary(g["converged"].to_numpy())
    out["by_lag"] = by_lag
    return out
