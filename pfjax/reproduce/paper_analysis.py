"""The paper reproduction's analyses: the (beta_r, beta_f) stability grid with its simulation
cross-check, the PI's line test over a long horizon, Table 2's two GA crossover readings and the
sine test's error against the path's curvature (:mod:`pfjax.reproduce.paper_study` runs them).
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pandas as pd

from pfjax import controllers as C
from pfjax.analysis import converged_to, equilibrium, stability_map
from pfjax.models import CONVENTIONS, SlipParams
from pfjax.numerics.random import seed_key
from pfjax.paths import (
    curvature,
    global_parameter,
    shapes,
)
from pfjax.reproduce.paper_config import sim_config
from pfjax.reproduce.paper_runs import source_pi, source_scenario, source_test
from pfjax.sim import (
    STATUS_NAMES,
    constant_slip,
    simulate_batch,
    stack,
    unstack,
)
from pfjax.sim.scenario import make_scenario


def source_eigen_maxima(cfg: dict, K, params) -> dict:
    """The source's Figs. 4-5 over its whole (open) slip square: the maxima of the real parts of the
    slower (lambda_1) and faster (lambda_2) eigenvalue of its linearisation at [0, -beta_r], 1/s,
    and where they occur (deg)."""
    st = cfg["stability"]
    eg = np.linspace(-st["eig_grid_max_deg"], st["eig_grid_max_deg"], st["eig_n"])
    _, eig = stability_map(K, jnp.radians(eg), jnp.radians(eg), params)
    re = np.sort(np.asarray(eig.real), axis=-1)  # ascending: [faster, slower]
    at = lambda a: [float(eg[i]) for i in np.unravel_index(int(np.argmax(a)), a.shape)]
    return {
        "grid_max_deg": float(eg[-1]),
        "n": int(st["eig_n"]),
        "hurwitz_fraction": float((re < 0).all(-1).mean()),
        "max_re_slow": float(re[..., 1].max()),
        "max_re_slow_at": at(re[..., 1]),
        "max_re_fast": float(re[..., 0].max()),
        "max_re_fast_at": at(re[..., 0]),
        "source_max_re_slow": float(cfg["source"]["eig_max_re"][0]),
        "source_max_re_fast": float(cfg["source"]["eig_max_re"][1]),
    }


def _grid_runs(cfg: dict, BR, BF):
    """The line test with the source's K (``source.K``) at every (beta_r, beta_f) of the grid (deg),
    unrecorded."""
    st, m = cfg["stability"], cfg["model"]
    gains = C.state_feedback_params(cfg["source"]["K"])
    # The robot advances along the line at up to v / cos(beta_r): make the line long enough that
    # no run reaches its end within the horizon (the default line is 80 m).
    line = shapes.line(u_max=20.0 + 1.5 * m["v"] * st["horizon"] / math.cos(math.radians(st["grid_max_deg"])))
    test = source_test("line", m["direction"], line)
    scs = stack(
        [
            make_scenario(
                test.run_path,
                test.pose0,
                gains,
                slip=constant_slip(math.radians(br), math.radians(bf)),
                v=m["v"],
                L=m["L"],
                delta_max_deg=m["delta_max_deg"],
                convention=m["convention"],
            )
            for br, bf in zip(BR.ravel(), BF.ravel())
        ]
    )
    return simulate_batch(scs, controller=C.state_feedback, config=sim_config(cfg, horizon=st["horizon"], record=False))


def part_stability(cfg, pbar) -> tuple[pd.DataFrame, dict]:
    """The (beta_r, beta_f) grid with the source's K: its linearisation, the true equilibrium and its
    eigenvalues, and the line test simulated to check them (docs/reproductions/path-following.md §7).
    Returns one row per grid point and the summary (``grid``: the axis and shape, for the figure)."""
    st, m = cfg["stability"], cfg["model"]
    params = SlipParams(m["v"], m["L"], math.radians(m["delta_max_deg"]), CONVENTIONS[m["convention"]])
    K = jnp.asarray(cfg["source"]["K"])
    grid = np.linspace(-st["grid_max_deg"], st["grid_max_deg"], st["n"])
    eq, src_eig = stability_map(K, jnp.radians(grid), jnp.radians(grid), params)
    pbar.update(1)
    BR, BF = np.meshgrid(grid, grid, indexing="ij")
    r = _grid_runs(cfg, BR, BF)
    pbar.update(1)
    d_star, th_star = np.asarray(eq.d).ravel(), np.asarray(eq.theta_e).ravel()
    conv = converged_to(
        r.status, r.final.d, r.final.theta_e, d_star, th_star, tol_d=st["tol_d"], tol_theta_deg=st["tol_theta_deg"]
    )
    df = pd.DataFrame(
        {
            "beta_r_deg": BR.ravel(),
            "beta_f_deg": BF.ravel(),
            "source_max_re": np.asarray(src_eig.real.max(-1)).ravel(),
            "eq_exists": np.asarray(eq.exists).ravel(),
            "eq_d": d_star,
            "eq_theta_e": th_star,
            "eq_delta": np.asarray(eq.delta).ravel(),
            "eq_max_re": np.asarray(eq.eig.real.max(-1)).ravel(),
            "eq_hurwitz": np.asarray(eq.hurwitz).ravel(),
            "sim_status": [STATUS_NAMES[int(s)] for s in np.asarray(r.status)],
            "sim_final_d": np.asarray(r.final.d),
            "sim_converged": conv,
        }
    )
    e5 = equilibrium(K, math.radians(m["beta_r_deg"]), math.radians(m["beta_f_deg"]), params)
    eigen_maxima = source_eigen_maxima(cfg, K, params)
    info = {
        "grid_deg": [float(grid[0]), float(grid[-1]), int(st["n"])],
        "source_hurwitz_fraction": float((df.source_max_re < 0).mean()),
        "equilibrium_exists_fraction": float(df.eq_exists.mean()),
        "hurwitz_where_exists_fraction": float(df.eq_hurwitz[df.eq_exists].mean()),
        "sim_converged_fraction": float(df.sim_converged.mean()),
        "sim_agrees_with_analysis_fraction": float((df.sim_converged == df.eq_hurwitz).mean()),
        "paper_case": {
            "d_star": float(e5.d),
            "theta_e_star": float(e5.theta_e),
            "delta_star": float(e5.delta),
            "eig": [[float(z.real), float(z.imag)] for z in np.asarray(e5.eig)],
        },
        "eigen_maxima": eigen_maxima,
        "grid": (grid, BR.shape),
    }
    return df, info


def part_long_pi(cfg) -> dict:
    """The source's PI (:func:`pfjax.reproduce.paper_runs.source_pi`) on the line test for
    ``long_horizon`` s: its steady |d| once settled, and when it settles (|d| within 5 % of its final
    value from then on)."""
    h, m = cfg["long_horizon"], cfg["model"]
    line = shapes.line(u_max=20.0 + 1.5 * m["v"] * h)  # long enough not to end within the horizon
    sc = source_scenario(source_test("line", m["direction"], line), C.pi_params(**source_pi(cfg)), cfg)
    r = unstack(simulate_batch(stack([sc]), controller=C.pi, config=sim_config(cfg, horizon=h)), 0)
    t, d = np.asarray(r.trajectory.t), np.asarray(r.trajectory.d)
    final = float(d[-1])
    out = np.nonzero(np.abs(d - final) > 0.05 * abs(final))[0]
    settle = float(t[out[-1] + 1]) if len(out) and out[-1] + 1 < len(t) else (0.0 if not len(out) else math.inf)
    return {
        "horizon_s": h,
        "steady_abs_d_mm": 1000 * float(r.metrics.steady_abs_d),
        "final_d_mm": 1000 * final,
        "settle_time_s": settle,
        "status": STATUS_NAMES[int(r.status)],
    }


#: The assumed tuning costs of eq. 15 (``ga.cost``), as the report names them with their units.
GA_COSTS = {"iae": "mean IAE ∫|d| dt, m·s", "ise": "mean ISE ∫d² dt, m²·s", "itae": "mean ITAE ∫t|d| dt, m·s²"}


def part_ga_readings(cfg) -> dict:
    """Table 2's two readings of the GA's crossover: MATLAB's default scattered crossover with fraction
    0.8 (adopted) and no crossover (children by mutation only), the PI tuned on the same seeds
    (``seed``, ``seed + 1``, ...: ``ga.seeds`` of them). Besides each reading's best gains, each
    seed's (``seed_gains``), against which :func:`gain_change` weighs the readings' difference."""
    from pfjax.tuning.cost import CostSpec
    from pfjax.tuning.ga import GAOptions
    from pfjax.tuning.problem import make_problem, tune

    g = cfg["ga"]
    problem = make_problem("pi", g["scenario"], cost=CostSpec(metric=g["cost"]))
    out = {"scenario": g["scenario"], "cost": GA_COSTS[g["cost"]]}
    for name, fraction in (("crossover", 0.8), ("none", 0.0)):
        opts = GAOptions(population_size=g["population"], generations=g["generations"], crossover_fraction=fraction)
        seeds = range(cfg["seed"], cfg["seed"] + g["seeds"])
        runs = [tune(problem, "ga", key=seed_key(seed), ga_options=opts) for seed in seeds]
        costs = [float(r.cost) for r in runs]
        best = runs[int(np.argmin(costs))]
        out[name] = {
            "crossover_fraction": fraction,
            "costs": costs,
            "median_cost": float(np.median(costs)),
            # the source's four PI gains, by scalar name (k_aw, the anti-windup it does not have, stays 0)
            "best_gains": _pi_gains(problem, best.theta),
            "seed_gains": [_pi_gains(problem, r.theta) for r in runs],
            "n_rollouts": int(sum(r.n_rollouts for r in runs)),
        }
    out["gain_change"] = gain_change(out["crossover"], out["none"])
    return out


def _pi_gains(problem, theta) -> dict[str, float]:
    """The source's four PI gains of a tuned ``theta`` by scalar name (``k_aw``, the anti-windup the
    source does not have, stays 0 and is left out)."""
    from pfjax.tuning.problem import reported_gains

    return {k: v for k, v in reported_gains("pi", problem, theta).items() if k in C.PAPER_PI}


def gain_change(a: dict, b: dict) -> str:
    """The largest relative difference between two readings' best gains, weighed against the
    seeds: that gain's range over each reading's seeds (``seed_gains``) and the exact two-sided
    Mann-Whitney test of the two samples. With p above 0.05 the difference is no evidence that the
    reading moves the gain; where the seeds cannot give p at or below 0.05 at all (the smallest
    exact p, ``2 / C(n_a + n_b, n_a)``, is 0.1 for three seeds each), the text says so instead."""
    from math import comb

    from scipy.stats import mannwhitneyu

    x, y = a["best_gains"], b["best_gains"]
    change = {k: abs(x[k] - y[k]) / max(abs(x[k]), abs(y[k]), 1e-12) for k in x}
    k = max(change, key=lambda n: change[n])
    ra, rb = ([g[k] for g in r["seed_gains"]] for r in (a, b))
    p = float(mannwhitneyu(ra, rb, alternative="two-sided", method="exact").pvalue)
    smallest = 2 / comb(len(ra) + len(rb), len(ra))
    if smallest > 0.05:
        said = f"{len(ra)} and {len(rb)} seeds cannot show an effect at the 5 % level: the smallest p they allow is {smallest:.2g}"
    else:
        said = f"{len(ra)} and {len(rb)} seeds: " + (
            "no evidence that the reading moves it" if p > 0.05 else "the reading moves it"
        )
    return (
        f"largest: {k} {x[k]:.4g} vs {y[k]:.4g} ({100 * change[k]:.0f} %); over the seeds {k} spans "
        f"{min(ra):.4g} to {max(ra):.4g} and {min(rb):.4g} to {max(rb):.4g} (exact Mann-Whitney p = {p:.2g}; {said})"
    )


def _local_maxima(x, y, frac=0.5):
    i = np.where((y[1:-1] > y[:-2]) & (y[1:-1] >= y[2:]) & (y[1:-1] > frac * y.max()))[0] + 1
    return x[i]


def sine_error_analysis(trajs, settle_t=5.0, direction="increasing_x") -> dict:
    """Where does |d| peak on the sine after the transient: at the |kappa| maxima (the sine's extrema)
    or at the |dkappa/ds| maxima (where the curvature changes fastest)? ``trajs`` in the sine's frame
    (:func:`pfjax.reproduce.paper_runs.to_world`), travelled in ``direction``."""
    path = source_test("sine", direction).path
    tr = trajs["sine"]["mixed"]
    late = tr["t"] >= settle_t
    # each a jitted program: op by op, JAX would compile each operation of a new shape on its own
    # (about 60 small programs, 3 s)
    u = np.asarray(jax.jit(jax.vmap(lambda qx, qy: global_parameter(path, qx, qy)))(tr["x"][late], tr["y"][late]))
    ad = np.abs(tr["d"][late])
    # the path's own |kappa| and |dkappa/ds| on a dense grid of x over the same stretch
    xs = np.linspace(u.min(), u.max(), 20001)
    kap = np.asarray(jax.jit(jax.vmap(lambda uu: curvature(path, uu)))(xs))
    dk = np.asarray(jax.jit(jax.vmap(jax.grad(lambda uu: curvature(path, uu))))(xs)) / np.sqrt(1 + np.cos(xs) ** 2)
    peaks = _local_maxima(u, ad)
    k_max, dk_max = _local_maxima(xs, np.abs(kap), 0.9), _local_maxima(xs, np.abs(dk), 0.9)
    nearest = lambda p, ref: float(np.median([np.min(np.abs(ref - q)) for q in p])) if len(p) and len(ref) else math.nan
    return {
        "x": u,
        "abs_d": ad,
        "kappa_x": xs,
        "kappa": kap,
        "dkappa_ds": dk,
        "peak_x": peaks.tolist(),
        "median_peak_to_kappa_max_m": nearest(peaks, k_max),
        "median_peak_to_dkappa_max_m": nearest(peaks, dk_max),
    }
