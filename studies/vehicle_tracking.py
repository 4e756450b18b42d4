#!/usr/bin/env python
"""Vehicle tracking with a focus point: Lemma 8.1 by batched simulation and by geometry,
and a robustness Monte Carlo of pfjax's input-output linearising controller.

    python studies/vehicle_tracking.py [--config studies/vehicle_tracking.toml] [--set key=value ...] [--out DIR] [--quick]

Writes ``results/vehicle_tracking/`` (or ``--out``): ``summary.json``, ``lemma_runs.parquet``,
``lemma_table.parquet`` / ``.csv`` (the four outcomes per mode and region), ``geometry.parquet``,
``mc_runs.parquet``, ``figures/*.png|svg`` and ``report.html``. Outputs are assembled in a temporary
directory and moved into place when complete; a bad key or value stops with one line, exit code 2.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import jax
import matplotlib

import pfjax  # before JAX: one CPU device per core (pfjax.default_host_devices)
import pfjax.cache

jax.config.update("jax_enable_x64", True)
pfjax.cache.enable()
matplotlib.use("Agg")

import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from pfjax.config import ConfigError, load, parse_override, read_toml  # noqa: E402
from pfjax.errors import command_main  # noqa: E402
from pfjax.jsonio import dumps  # noqa: E402
from pfjax.metrics.robustness import metric_quantiles, success_summary  # noqa: E402
from pfjax.outputs import OutputDir, check_name  # noqa: E402
from pfjax.provenance import (  # noqa: E402
    config_hash,
    machine,
    parquet_metadata,
)
from pfjax.tables import write_parquet  # noqa: E402
from pfjax.tracking import batches as B  # noqa: E402
from pfjax.tracking import report as R  # noqa: E402
from pfjax.tracking.lemma import four_way, sample_geometry  # noqa: E402
from pfjax.tracking.simulate import TrackConfig  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_TOML = ROOT / "studies" / "vehicle_tracking.toml"
QUICK = [
    "lemma.p=[-1.0, 1.0, 4.5]",
    "lemma.l_abs=[1.0]",
    "lemma.gamma_max_deg=[30.0]",
    "lemma.offsets=[[-1.0, 1.0]]",
    "lemma.n_geometry=200",
    "mc.n_runs=24",
    "sim.horizon=15.0",
    "sim.dt=0.02",
]
GRID_AXES = ("p", "l_abs", "gamma_max_deg", "offsets")
METRICS = ["final_error_norm", "iae", "max_abs_gamma_deg", "window_max_z", "limit_fraction"]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", default=str(DEFAULT_TOML))
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    ap.add_argument("--out")
    ap.add_argument("--quick", action="store_true", help="small grid and sample (for tests)")
    ap.add_argument("--overwrite", action="store_true", help="replace a pfjax output of another config in --out")
    args = ap.parse_args(argv)
    return command_main("vehicle_tracking", lambda: run(args))


def load_config(args) -> dict:
    """The validated config (defaults <- --config <- --set); ConfigError naming the key."""
    defaults = read_toml(DEFAULT_TOML)
    for k in GRID_AXES:  # grid axes: any length (checked below)
        defaults["lemma"][k] = []
    cfg = load(defaults, args.config)
    for text in (QUICK if args.quick else []) + args.set:  # a grid axis may change length
        lem = parse_override(text).get("lemma", {})
        for k in GRID_AXES:
            if isinstance(lem, dict) and k in lem:
                cfg["lemma"][k] = []
        cfg = load(cfg, None, [text])
    for k in ("p", "l_abs", "gamma_max_deg"):
        v = cfg["lemma"][k]
        if not v or not all(isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) for x in v):
            raise ConfigError(f"lemma.{k}: expected a non-empty list of numbers, got {v!r}")
        cfg["lemma"][k] = [float(x) for x in v]
    offs = cfg["lemma"]["offsets"]
    if not offs or not all(
        isinstance(o, list) and len(o) == 2 and all(isinstance(x, (int, float)) for x in o) for o in offs
    ):
        raise ConfigError(f"lemma.offsets: expected a non-empty list of [along, left] pairs, got {offs!r}")
    cfg["lemma"]["offsets"] = [[float(x) for x in o] for o in offs]
    for key, vals in (("lemma.p", cfg["lemma"]["p"]), ("lemma.l_abs", cfg["lemma"]["l_abs"])):
        if any(v == 0 for v in vals):
            raise ConfigError(f"{key}: values must be nonzero, got {vals}")
    if not all(0 < g < 90 for g in cfg["lemma"]["gamma_max_deg"] + [cfg["mc"]["gamma_max_deg"]]):
        raise ConfigError("lemma.gamma_max_deg / mc.gamma_max_deg: expected values in (0, 90) deg")
    for k in ("dt", "horizon", "window", "tol_z", "tol_phi", "band", "k", "a"):
        if cfg["sim"][k] <= 0:
            raise ConfigError(f"sim.{k}: must be > 0, got {cfg['sim'][k]}")
    if cfg["mc"]["n_runs"] < 1:
        raise ConfigError(f"mc.n_runs: must be >= 1, got {cfg['mc']['n_runs']}")
    return cfg


def run(args) -> int:
    cfg = load_config(args)
    check_name("name", cfg["name"])
    out = Path(args.out) if args.out else ROOT / "results" / cfg["name"]
    with OutputDir(
        out,
        command="vehicle-tracking",
        config_sha256=config_hash(cfg),
        overwrite=args.overwrite,
        extra={"seed": cfg["seed"]},
    ) as output:
        return study(cfg, args, output)


def study(cfg: dict, args, output) -> int:
    t0 = time.time()
    s = cfg["sim"]
    tcfg = TrackConfig(
        dt=s["dt"], horizon=s["horizon"], window=s["window"], tol_z=s["tol_z"], tol_phi=s["tol_phi"], band=s["band"]
    )
    key = jax.random.PRNGKey(cfg["seed"])
    chunk = 512 if not args.quick else 36

    scs, rows = B.lemma_grid(cfg, jax.random.fold_in(key, 0))
    lemma_df = B.frame(rows, B.run_chunks(scs, tcfg, chunk, "lemma grid"))
    lemma_df["region"] = np.where(lemma_df["inside_bound"], "|p| < pi/(2 gamma_max)", "|p| >= pi/(2 gamma_max)")
    table = four_way(lemma_df, ["mode", "region"])

    geo = []
    for i, p in enumerate(sorted(set(cfg["lemma"]["p"]))):
        for gdeg in cfg["lemma"]["gamma_max_deg"]:
            g = sample_geometry(jax.random.fold_in(key, 100 + i), cfg["lemma"]["n_geometry"], math.radians(gdeg), p)
            geo.append(g.assign(p=p, gamma_max_deg=gdeg))
    geo = pd.concat(geo, ignore_index=True)
    on = geo[geo.kind == "on_focus"]
    inside = on.p_gamma.abs() < math.pi / 2
    geometry = {
        "n_states_z_err_0": int(len(on)),
        "max_abs_phi_minus_pgamma_when_abs_pgamma_lt_pi_2": float(on[inside].phi_minus_pgamma.abs().max()),
        "n_counterexamples_abs_pgamma_gt_pi_2": int((~inside).sum()),
        "counterexample_abs_phi_minus_pgamma_range": [
            float(on[~inside].phi_minus_pgamma.abs().min()),
            float(on[~inside].phi_minus_pgamma.abs().max()),
        ]
        if (~inside).any()
        else None,
        "counterexamples_only_outside_bound": bool(
            (on[~inside].p.abs() * np.radians(on[~inside].gamma_max_deg) > math.pi / 2).all()
        ),
        "wrong_distance_min_z_err": float(geo[geo.kind == "wrong_distance"].z_err.min()),
    }

    mc, mc_summary = [], {}
    for f in (1, -1):
        scs, rows = B.mc_sample(cfg, f, jax.random.fold_in(key, 10 + (f > 0)))
        df = B.frame(rows, B.run_chunks(scs, tcfg, chunk, f"Monte Carlo ({'forward' if f > 0 else 'backward'})"))
        mode = "forward" if f > 0 else "backward"
        ok = df[df.status == "ok"]
        mc_summary[mode] = {
            **success_summary(df["success"].astype(bool).to_numpy()),
            "status_counts": df["status"].value_counts().to_dict(),
            "quantiles": metric_quantiles(ok, METRICS),
            "by_leader": {k: success_summary(v["success"].astype(bool).to_numpy()) for k, v in df.groupby("leader")},
        }
        mc.append(df)
    mc = pd.concat(mc, ignore_index=True)

    summary = {
        "study": cfg["name"],
        "seed": cfg["seed"],
        "config": cfg,
        "config_sha256": config_hash(cfg),
        "pfjax_version": pfjax.__version__,
        "machine": machine(),
        "quick": args.quick,
        "definitions": {
            "z_to_0": f"max |z~| over the last {s['window']} s <= {s['tol_z']} m",
            "phi_minus_pgamma_to_0": f"max |phi - p gamma| over the last {s['window']} s <= {s['tol_phi']} rad",
            "success": f"status ok and max |z~| over the last {s['window']} s <= {s['band']} m",
        },
        "lemma_grid": {"n_runs": int(len(lemma_df)), "table": table.to_dict(orient="records")},
        "geometry": geometry,
        "monte_carlo": mc_summary,
    }
    tmp = output.staging
    meta = parquet_metadata(cfg, cfg["seed"])
    for name, df in (("lemma_runs", lemma_df), ("lemma_table", table), ("geometry", geo), ("mc_runs", mc)):
        write_parquet(df, tmp / f"{name}.parquet", meta)
    table.to_csv(tmp / "lemma_table.csv", index=False)
    summary["figures"] = R.write_figures(tmp / "figures", cfg, lemma_df, geo, mc)
    summary["wall_s"] = time.time() - t0
    (tmp / "summary.json").write_text(dumps(summary))
    R.write_report(tmp, summary, table, lemma_df)
    out = output.commit()
    print(
        dumps(
            {
                "out": str(out),
                "wall_s": summary["wall_s"],
                "lemma_table": summary["lemma_grid"]["table"],
                "geometry": geometry,
                "monte_carlo": {
                    k: {kk: v[kk] for kk in ("n", "success_rate", "success_ci95", "status_counts")}
                    for k, v in mc_summary.items()
                },
            }
        )
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
