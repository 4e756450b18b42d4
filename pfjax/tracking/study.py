"""The vehicle-tracking study (``studies/vehicle_tracking.py``): Lemma 8.1 by a batched grid of
simulations and by geometry, and a robustness Monte Carlo of the focus-point controller.

:func:`run` takes a validated :class:`~pfjax.tracking.study_config.TrackingStudy` and an
:class:`pfjax.outputs.OutputDir`; each part is a function of the config and the key.
"""

from __future__ import annotations

import itertools
import math
import time

import jax
import numpy as np
import pandas as pd

import pfjax
from pfjax.jsonio import dumps
from pfjax.metrics.robustness import metric_quantiles, success_summary
from pfjax.montecarlo.summary import UNITS as MONTE_CARLO_UNITS
from pfjax.numerics.random import seed_key
from pfjax.provenance import STAMP_UNITS, config_hash, machine, parquet_metadata
from pfjax.report import document
from pfjax.reproduce.tracking import verdicts as tracking_verdicts
from pfjax.tables import write_parquet
from pfjax.tracking import batches as B
from pfjax.tracking import report as R
from pfjax.tracking.api import UNITS
from pfjax.tracking.lemma import four_way, sample_geometry
from pfjax.tracking.simulate import TrackConfig
from pfjax.tracking.study_config import TrackingStudy

#: per-run metrics summarised by quantiles in the Monte Carlo summary
METRICS = ["final_error_norm", "iae", "max_abs_gamma_deg", "window_max_z", "limit_fraction"]

#: column -> (unit, description) of every column of the study's Parquet tables (``lemma_runs``,
#: ``mc_runs``, ``lemma_table``, ``geometry``), written as field metadata
#: (:func:`pfjax.tables.write_parquet`). A quantity ``pfjax track --json`` also prints takes its unit
#: from :data:`pfjax.tracking.api.UNITS`. Units: "1" dimensionless, "" text, flag or code.
COLUMNS: dict[str, tuple[str, str]] = {
    # a run's settings
    "mode": ("", "forward (f = +1, reference point P_f) or backward (f = -1, P_b, the follower reverses)"),
    "run": ("", "Monte Carlo run index (its random stream)"),
    "leader": ("", "the leader's motion"),
    "p": (UNITS["p"], "focus turning ratio p"),
    "l": (UNITS["l"], "focus distance l, signed (l = f |l|)"),
    "gamma_max_deg": (UNITS["gamma_max_deg"], "steering limit gamma_max"),
    "speed": ("m/s", "leader speed V0"),
    "offset_along": ("m", "the follower's initial displacement along the leader's direction of travel"),
    "offset_left": ("m", "the follower's initial displacement left of the leader's direction of travel"),
    "heading_error_deg": ("deg", "initial heading error"),
    "beta_r_deg": ("deg", "constant rear-wheel slip angle"),
    "beta_f_deg": ("deg", "constant front-wheel slip angle"),
    "inside_bound": ("", "|p| < pi / (2 gamma_max) (Lemma 8.1's bound)"),
    "invertible": ("", "the input matrix M is invertible for every |gamma| <= gamma_max"),
    "region": ("", "which side of Lemma 8.1's bound p lies on"),
    # a run's metrics (pfjax.tracking.simulate.TrackMetrics)
    "iae": (UNITS["iae"], "integral of |z~| over the run (inf: the run failed)"),
    "window_max_z": (UNITS["window_max_z"], "largest |z~| over the final window (NaN: the run failed)"),
    "window_max_phi_err": (
        UNITS["window_max_phi_err"],
        "largest |phi - p gamma| over the final window (NaN: the run failed)",
    ),
    "final_error_norm": (
        UNITS["final_error_norm"],
        "|z~| at the end of the run (a failed run: at its last step before the failure)",
    ),
    "final_phi_minus_pgamma": (UNITS["final_phi_minus_pgamma"], "phi - p gamma at the end of the run"),
    "final_d": (UNITS["final_d"], "signed length d of the virtual connection at the end of the run"),
    "min_abs_factor": (UNITS["min_abs_factor"], "smallest |det M / (l p)| met"),
    "limit_fraction": (UNITS["limit_fraction"], "fraction of the steps with a speed or steering limit active"),
    "max_abs_gamma_deg": (UNITS["max_abs_gamma_deg"], "largest |gamma|"),
    "converged": ("", "z~ -> 0: status ok and max |z~| over the final window <= tol_z"),
    "phi_converged": ("", "phi - p gamma -> 0: status ok and max |phi - p gamma| over the final window <= tol_phi"),
    "success": ("", "status ok and max |z~| over the final window <= band"),
    "status_code": ("", "run status code (pfjax.tracking.TrackStatus)"),
    "status": ("", "run status name: ok, nonfinite, diverged, singular"),
    "fail_time": (UNITS["fail_time"], "time of the first failure (inf: none)"),
    # the four-outcome table (pfjax.tracking.lemma.four_way)
    "n": ("runs", "runs in the group"),
    "both": ("runs", "finished runs with z~ -> 0 and phi - p gamma -> 0"),
    "z_only": ("runs", "finished runs with z~ -> 0 only"),
    "phi_only": ("runs", "finished runs with phi - p gamma -> 0 only"),
    "neither": ("runs", "finished runs with neither limit"),
    "failed": ("runs", "runs that did not finish (status other than ok)"),
    "equivalence_holds": (
        "",
        "z_only == phi_only == 0, as observed (Lemma 8.1 claims it inside the bound only; outside, a row tells what ran)",
    ),
    # the geometric check (pfjax.tracking.lemma.sample_geometry)
    "kind": ("", "on_focus (z_d the focus point) or wrong_distance (z_d on the focus direction, farther)"),
    "gamma": (UNITS["final.*"]["gamma"], "steering angle gamma of the random state"),
    "p_gamma": ("rad", "p gamma"),
    "phi": ("rad", "connection angle phi, in (-pi/2, pi/2]"),
    "phi_minus_pgamma": ("rad", "phi - p gamma"),
    "z_err": (UNITS["final_error_norm"], "|z~| of the state"),
}

#: ``summary.json``'s units by field name (a field has one meaning wherever it occurs; "1":
#: dimensionless), written as ``summary["units"]``: the four-outcome table's counts as in
#: :data:`COLUMNS`; the success statistics as in ``pfjax study``'s summary
#: (:data:`pfjax.montecarlo.summary.UNITS`); ``quantiles``, each metric's unit (:data:`COLUMNS`),
#: which its ``mean``, ``std`` and quantiles over the runs with status ok take.
SUMMARY_UNITS: dict[str, object] = {
    **STAMP_UNITS,
    "wall_s": "s",
    # the Lemma 8.1 grid
    "n_runs": "runs",
    **{c: COLUMNS[c][0] for c in ("n", "both", "z_only", "phi_only", "neither", "failed")},
    # the geometric check
    "n_states_z_err_0": "states (random states with z~ = 0)",
    "n_counterexamples_abs_pgamma_gt_pi_2": "states (with z~ = 0 and |p gamma| >= pi/2)",
    "max_abs_phi_minus_pgamma_when_abs_pgamma_lt_pi_2": COLUMNS["phi_minus_pgamma"][0],
    "counterexample_abs_phi_minus_pgamma_range": f"{COLUMNS['phi_minus_pgamma'][0]} "
    "([smallest, largest] |phi - p gamma| of the states with |p gamma| >= pi/2)",
    "wrong_distance_min_z_err": COLUMNS["z_err"][0],
    # the Monte Carlo, per mode and per leader motion
    **{k: MONTE_CARLO_UNITS[k] for k in ("k", "success_rate", "success_ci95", "status_counts", "n_finite")},
    "quantiles": {m: COLUMNS[m][0] for m in METRICS},
}


def track_config(cfg: dict) -> TrackConfig:
    """The simulation settings of one run from the ``sim`` section."""
    s = cfg["sim"]
    return TrackConfig(
        dt=s["dt"], horizon=s["horizon"], window=s["window"], tol_z=s["tol_z"], tol_phi=s["tol_phi"], band=s["band"]
    )


def lemma_part(
    cfg: dict, key, chunk: int, config: TrackConfig | None = None
) -> tuple[pd.DataFrame, pd.DataFrame, pd.DataFrame]:
    """The Lemma 8.1 grid: per-run rows, the four outcomes per mode and region, and the runs
    outside the bound where exactly one limit holds (by mode, gamma_max and p).

    ``cfg`` is a validated study config as a dict (``study_config.load(...).model_dump(mode="json")``),
    ``key`` the study's key (:func:`pfjax.numerics.random.seed_key`), ``chunk`` the runs per jitted batch;
    ``config`` the settings of the runs, :func:`track_config` of ``cfg`` unless given (one with
    ``record=True`` and the same numbers gives the same rows and reuses a recording program)."""
    scs, rows = B.lemma_grid(cfg, jax.random.fold_in(key, 0))
    lemma_df = B.frame(rows, B.run_chunks(scs, config or track_config(cfg), chunk, "lemma grid"))
    lemma_df["region"] = np.where(lemma_df["inside_bound"], "|p| < pi/(2 gamma_max)", "|p| >= pi/(2 gamma_max)")
    table = four_way(lemma_df, ["mode", "region"])
    outside = lemma_df[~lemma_df.inside_bound & (lemma_df.status == "ok")]
    out_tab = four_way(outside, ["mode", "gamma_max_deg", "p"])[
        ["mode", "gamma_max_deg", "p", "n", "z_only", "phi_only"]
    ]
    out_tab = out_tab.rename(columns={"n": "n_ok"})[(out_tab.z_only + out_tab.phi_only) > 0]
    return lemma_df, table, out_tab


def geometry_part(cfg: dict, key) -> tuple[pd.DataFrame, dict]:
    """Lemma 8.1 as geometry on random states, for every ``p``, ``gamma_max``, mode and ``|l|`` of the
    grid (``l = f |l|``, the grid's wheelbase): per-state rows and their summary."""
    geo, lem = [], cfg["lemma"]
    for i, p in enumerate(sorted(set(lem["p"]))):
        for j, (f, la) in enumerate(itertools.product((1, -1), lem["l_abs"])):
            k = jax.random.fold_in(jax.random.fold_in(key, 100 + i), j)
            for gdeg in lem["gamma_max_deg"]:
                g = sample_geometry(k, lem["n_geometry"], math.radians(gdeg), p, l=f * la, f=f, a=cfg["sim"]["a"])
                geo.append(g.assign(p=p, gamma_max_deg=gdeg, mode="forward" if f > 0 else "backward", l=f * la))
    geo_df = pd.concat(geo, ignore_index=True)
    on = geo_df[geo_df.kind == "on_focus"]
    inside = on.p_gamma.abs() < math.pi / 2
    summary = {
        "n_states_z_err_0": int(len(on)),
        "max_abs_phi_minus_pgamma_when_abs_pgamma_lt_pi_2": float(on[inside].phi_minus_pgamma.abs().max()),
        "n_counterexamples_abs_pgamma_gt_pi_2": int((~inside).sum()),
        "counterexample_abs_phi_minus_pgamma_range": [
            float(on[~inside].phi_minus_pgamma.abs().min()),
            float(on[~inside].phi_minus_pgamma.abs().max()),
        ]
        if (~inside).any()
        else None,
        "wrong_distance_min_z_err": float(geo_df[geo_df.kind == "wrong_distance"].z_err.min()),
    }
    return geo_df, summary


def monte_carlo_part(cfg: dict, key, chunk: int, config: TrackConfig | None = None) -> tuple[pd.DataFrame, dict]:
    """The robustness Monte Carlo, forward then backward: per-run rows and per-mode summaries
    (arguments as :func:`lemma_part`'s)."""
    mc, summary = [], {}
    for f in (1, -1):
        mode = "forward" if f > 0 else "backward"
        scs, rows = B.mc_sample(cfg, f, jax.random.fold_in(key, 10 + (f > 0)))
        df = B.frame(rows, B.run_chunks(scs, config or track_config(cfg), chunk, f"Monte Carlo ({mode})"))
        ok = df[df.status == "ok"]
        summary[mode] = {
            **success_summary(df["success"].astype(bool).to_numpy()),
            "status_counts": df["status"].value_counts().to_dict(),
            "quantiles": metric_quantiles(ok, METRICS),
            "by_leader": {k: success_summary(v["success"].astype(bool).to_numpy()) for k, v in df.groupby("leader")},
        }
        mc.append(df)
    return pd.concat(mc, ignore_index=True), summary


def definitions(cfg: dict) -> dict:
    """The limits and the success criterion in words, with the configured tolerances."""
    s = cfg["sim"]
    return {
        "z_to_0": f"max |z~| over the last {s['window']} s <= {s['tol_z']} m",
        "phi_minus_pgamma_to_0": f"max |phi - p gamma| over the last {s['window']} s <= {s['tol_phi']} rad",
        "success": f"status ok and max |z~| over the last {s['window']} s <= {s['band']} m",
    }


def run(config: TrackingStudy, output, quick: bool = False) -> dict:
    """Run the study into ``output`` (an open :class:`pfjax.outputs.OutputDir`): ``summary.json``
    (units: its ``units`` map, :data:`SUMMARY_UNITS`), ``lemma_runs``/``lemma_table``/``geometry``/``mc_runs``
    Parquet (units: :data:`COLUMNS`), ``lemma_table.csv`` (``config_sha256`` first), ``figures/`` and
    ``report.md`` + ``report.html``. Returns the summary."""
    t0 = time.time()
    cfg = config.model_dump(mode="json")
    key = seed_key(cfg["seed"])
    chunk = 512 if not quick else 36
    lemma_df, table, out_tab = lemma_part(cfg, key, chunk)
    geo, geometry = geometry_part(cfg, key)
    mc, mc_summary = monte_carlo_part(cfg, key, chunk)
    summary = {
        "study": cfg["name"],
        "seed": cfg["seed"],
        "config": cfg,
        "config_sha256": config_hash(cfg),
        "pfjax_version": pfjax.__version__,
        "machine": machine(),
        "quick": quick,
        "definitions": definitions(cfg),
        "lemma_grid": {"n_runs": int(len(lemma_df)), "table": table.to_dict(orient="records")},
        "geometry": geometry,
        "monte_carlo": mc_summary,
        "verdicts": [v._asdict() for v in tracking_verdicts(cfg, geometry, lemma_df)],
        "units": SUMMARY_UNITS,
    }
    tmp = output.staging
    meta = parquet_metadata(cfg, cfg["seed"])
    for name, df in (("lemma_runs", lemma_df), ("lemma_table", table), ("geometry", geo), ("mc_runs", mc)):
        write_parquet(df, tmp / f"{name}.parquet", meta, units=COLUMNS)
    table.assign(config_sha256=summary["config_sha256"])[["config_sha256", *table.columns]].to_csv(
        tmp / "lemma_table.csv", index=False
    )
    summary["figures"] = R.write_figures(tmp / "figures", cfg, lemma_df, geo, mc)
    summary["wall_s"] = time.time() - t0
    (tmp / "summary.json").write_text(dumps(summary))
    document.write(R.report(summary, {"lemma_table": table, "outside": out_tab}), tmp)
    return summary


__all__ = [
    "COLUMNS",
    "METRICS",
    "SUMMARY_UNITS",
    "definitions",
    "geometry_part",
    "lemma_part",
    "monte_carlo_part",
    "run",
    "track_config",
]
