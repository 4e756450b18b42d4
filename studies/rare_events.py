#!/usr/bin/env python
"""Rare failures, verified and measured (docs/rare-events.md): the estimators of pfjax.rare against
a failure probability known independently, against plain Monte Carlo, their interval coverage, and
the certification study ``studies/rare_events.toml``.

    python studies/rare_events.py [--out DIR] [--quick] [--overwrite]

Parts (each entry records estimate, 95 % interval, relative error, rollouts and wall time, s):

* ``known``: state feedback on a straight line under constant Gaussian slip of standard
  deviation ``s`` from zero initial error (8 s horizon, 10 ms steps, float64): the reference is the
  Gaussian measure of the slips whose equilibrium offset leaves the 5 cm band
  (:func:`pfjax.rare.reference.line_offset_failure_probability`), at ``p`` about 1e-4, 1e-6 and
  1e-8, by importance sampling and subset simulation; plain Monte Carlo at 1e-4.
* ``coverage``: repeated independent estimates at ``p`` about 1e-4 on the known case: the share of
  95 % intervals that hold the reference (subset simulation: also the runs' observed spread
  against the levels-uncorrelated and fully-correlated errors of Au and Beck's bounds).
* ``starts``: importance sampling at ``p`` about 1e-6 on the known case from the falsifier's
  failure points, from failure points of a widened law and from ``N(0, I)``: rollouts used.
* ``study``: every controller of ``studies/rare_events.toml`` by importance sampling and subset
  simulation, for its failure (leaving the path, ``path``) and for leaving the 5 cm band
  (``band``), there also by plain Monte Carlo with ``mc_study`` runs, which resolves it.
* ``sine_check``: ``pi-table3`` leaving the path on the sine alone (``p`` about 1e-5), by plain
  Monte Carlo with ``mc_sine`` runs, importance sampling and subset simulation.

The study's importance-sampling estimates carry the reliability check of ``[rare_event] check =
"subset"`` (:mod:`pfjax.rare.check`: ``status``, ``warning`` and each stratum's ``check``).

Writes ``results/rare_events/verification.json`` (or ``--out``).
"""

from __future__ import annotations

import time
from pathlib import Path

import jax

import pfjax  # before JAX: one CPU device per core
import pfjax.cache
from pfjax.cli.study import default_out, script_parser

jax.config.update("jax_enable_x64", True)
pfjax.cache.enable()

from pfjax.errors import command_main  # noqa: E402
from pfjax.jsonio import dumps  # noqa: E402
from pfjax.outputs import OutputDir  # noqa: E402
from pfjax.provenance import config_hash, machine  # noqa: E402
from pfjax.rare.reference import line_offset_failure_probability  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
K = [-2.7381, -2.0772]  # rad/m, rad/rad: the default state feedback
#: slip standard deviations (deg) putting the known case's p near 1e-4, 1e-6 and 1e-8
KNOWN_STD = {"1e-4": 1.372, "1e-6": 1.091, "1e-8": 0.931}
FULL = {
    "coverage_repeats": 50,
    "subset_repeats": 50,
    "mc_known": 1_000_000,
    "mc_study": 600_000,
    "start_seeds": 3,
    "mc_sine": 1_000_000,
}
QUICK = {
    "coverage_repeats": 4,
    "subset_repeats": 2,
    "mc_known": 20_000,
    "mc_study": 6_000,
    "start_seeds": 1,
    "mc_sine": 6_000,
}
#: the band (m) of the study's second failure definition, beside its own threshold (leaving the path)
BAND = 0.05


def known_case(std_deg: float) -> dict:
    """The known case's study config (a dict)."""
    slip = {"dist": "truncnormal", "mean": 0.0, "std": std_deg, "low": -30.0, "high": 30.0}
    return {
        "name": "rare-line",
        "n_runs": 1,
        "seed": 0,
        "dtype": "float64",
        "sim": {"horizon": 8.0, "dt": 0.01, "steady_window": 2.0},
        "success": {"band": 0.05, "from_s": 6.0},
        "slip": {"beta_r_deg": slip, "beta_f_deg": slip},
        "margin": {"enabled": False},
        "paths": [{"kind": "line"}],
        "controllers": [{"name": "state-feedback", "type": "state_feedback", "K": K}],
        "rare_event": {"enabled": True, "n_per_level": 2000, "batch": 2000, "max_rollouts": 400_000},
    }


def estimate(config, name: str, **kw) -> dict:
    t0 = time.time()
    r = pfjax.rare_event(config, controller=name, progress=False, **kw)["controllers"][name]
    keep = ("p_fail", "ci95", "rel_error", "n_rollouts", "method", "status", "warning", "strata", "failure_points")
    r = {k: r[k] for k in keep}
    r["wall_s"] = time.time() - t0
    return r


def holds(r: dict, p: float) -> bool:
    return r["ci95"][0] <= p <= r["ci95"][1]


def run_spread(rs: list[dict]) -> dict:
    """Every independent subset-simulation run inside the repeats: the observed coefficient of
    variation of the runs' estimates beside the root-mean-square of each run's levels-uncorrelated
    error ``sqrt(Σ δ_j²)`` and of its fully-correlated bound ``Σ δ_j`` (one stratum)."""
    import numpy as np

    ps: list[float] = []
    lo: list[float] = []
    hi: list[float] = []
    for r in rs:
        for run in r["strata"][0]["run_estimates"]:
            ps.append(run["p"])
            lo.append(run["delta_uncorrelated"])
            hi.append(run["delta_correlated"])
    ps_a = np.asarray(ps)
    return {
        "n": len(ps),
        "observed_cov": float(ps_a.std(ddof=1) / ps_a.mean()),
        "delta_uncorrelated_rms": float(np.sqrt(np.mean(np.square(lo)))),
        "delta_correlated_rms": float(np.sqrt(np.mean(np.square(hi)))),
    }


def starts_comparison(n_seeds: int) -> dict:
    """Importance sampling on the known case at 1e-6 started from the falsifier's failure points,
    from failure points of a widened law, and from ``N(0, I)``: rollouts to 10 % (seeds 0...)."""
    std = KNOWN_STD["1e-6"]
    p = line_offset_failure_probability(K, std)
    out: dict = {"reference": p}
    for how in ("falsifier", "explore", "none"):
        rs = [
            estimate(known_case(std), "state-feedback", method="is", seed=s, rare_event__starts=how)
            for s in range(n_seeds)
        ]
        out[how] = {
            "n_rollouts": [r["n_rollouts"] for r in rs],
            "p_fail": [r["p_fail"] for r in rs],
            "rel_error": [r["rel_error"] for r in rs],
            "wall_s": [r["wall_s"] for r in rs],
            "holds_reference": [holds(r, p) for r in rs],
        }
        print(f"starts {how}: {out[how]['n_rollouts']}")
    return out


def run(args) -> int:
    sizes = QUICK if args.quick else FULL
    out = default_out(args.out, "rare_events")
    result = {"machine": machine(), "sizes": sizes, "known": {}, "coverage": {}, "study": {}}
    with OutputDir(out, command="rare-events", config_sha256=config_hash(sizes), overwrite=args.overwrite) as output:
        for label, std in KNOWN_STD.items():
            p = line_offset_failure_probability(K, std)
            entry = {"std_deg": std, "reference": p}
            for method in ("is", "subset"):
                entry[method] = r = estimate(known_case(std), "state-feedback", method=method, target_rel_error=0.1)
                r["holds_reference"] = holds(r, p)
                print(f"known {label} {method}: {r['p_fail']:.3g} vs {p:.3g} ({r['n_rollouts']} rollouts)")
            if label == "1e-4":
                entry["mc"] = r = estimate(
                    known_case(std), "state-feedback", method="mc", max_rollouts=sizes["mc_known"]
                )
                r["holds_reference"] = holds(r, p)
            result["known"][label] = entry
        result["starts"] = starts_comparison(sizes["start_seeds"])
        std = KNOWN_STD["1e-4"]
        p = result["known"]["1e-4"]["reference"]
        for method, n in (("is", sizes["coverage_repeats"]), ("subset", sizes["subset_repeats"])):
            rs = [
                estimate(known_case(std), "state-feedback", method=method, seed=1000 + i, target_rel_error=0.1)
                for i in range(n)
            ]
            hits = [holds(r, p) for r in rs]
            result["coverage"][method] = {
                "repeats": n,
                "coverage": sum(hits) / n,
                "mean_estimate_over_reference": sum(r["p_fail"] for r in rs) / n / p,
                "mean_rel_error": sum(r["rel_error"] for r in rs) / n,
                "mean_rollouts": sum(r["n_rollouts"] for r in rs) / n,
                "estimates": [r["p_fail"] for r in rs],
            }
            if method == "subset":
                result["coverage"][method]["runs"] = run_spread(rs)
            print(f"coverage {method}: {sum(hits)}/{n}")
        study = ROOT / "studies" / "rare_events.toml"
        names = [c.name for c in pfjax.montecarlo.config.load_study(study)[0].controllers]
        for name in names:
            entry = {m: estimate(study, name, method=m) for m in ("is", "subset")}
            band = {m: estimate(study, name, method=m, rare_event__threshold=BAND) for m in ("is", "subset")}
            band["mc"] = estimate(study, name, method="mc", max_rollouts=sizes["mc_study"], rare_event__threshold=BAND)
            result["study"][name] = {"path": entry, "band": band}
            print(name, {m: f"{entry[m]['p_fail']:.3g}" for m in entry}, {m: f"{band[m]['p_fail']:.3g}" for m in band})
        result["sine_check"] = {
            m: estimate(study, "pi-table3", method=m, paths=[{"kind": "sine"}], **kw)
            for m, kw in (("mc", {"max_rollouts": sizes["mc_sine"]}), ("is", {}), ("subset", {}))
        }
        print("sine check", {m: f"{r['p_fail']:.3g}" for m, r in result["sine_check"].items()})
        (output.staging / "verification.json").write_text(dumps(result, indent=1) + "\n")
        output.commit()
    print(f"wrote {out}")
    return 0


def main(argv=None) -> int:
    ap = script_parser(__doc__, config=None, out_default="results/rare_events", quick="small sizes (tests)")
    args = ap.parse_args(argv)
    return command_main("rare-events", lambda: run(args))


if __name__ == "__main__":
    raise SystemExit(main())
