"""Parts of the tuning study (:mod:`pfjax.tuning.study`) beside the GA-vs-gradient comparison: the
Table 3 check, local checks of the best answers, single vs robust tuning of K, the LMI designs, the
held-out Monte Carlo evaluation and the targets by problem. ``cfg`` is the validated
:class:`pfjax.tuning.study_config.TuningStudy` as a dict (``model_dump``)."""

from __future__ import annotations

import jax
import numpy as np
import pandas as pd

from pfjax.numerics.random import seed_key
from pfjax.tuning.multistart import MultistartOptions
from pfjax.tuning.study_config import K_TUNINGS, TABLE3_LR, problem_list


def table3(cfg, pr, progress):
    """Cost and gradient at the Table 3 gains, the local check, and where plain descent from them goes."""
    from pfjax.controllers import PAPER_PI
    from pfjax.tuning.problem import check, evaluate, reported_gains, tune

    th3 = pr.tunable.flatten(pr.tunable.base._replace(**{k: PAPER_PI[k] for k in pr.tunable.fields}))
    c3 = check(pr, th3)  # its gradient is the cost's at the Table 3 gains (per gain unit)
    r3 = tune(
        pr,
        "gradient-plain",
        key=jax.random.PRNGKey(0),
        theta0=th3,
        steps=cfg["gradient"]["table3_steps"],
        learning_rate=TABLE3_LR,
        progress=progress,
    )
    return {
        "gains": reported_gains("pi", pr, th3),
        "cost": evaluate(pr, th3),
        "gradient": c3.gradient.tolist(),
        "check_verdict": c3.verdict,
        "check_probe_decrease": float(c3.probe_decrease),
        "check_eigenvalues": c3.eigenvalues.tolist(),
        "descent_steps": cfg["gradient"]["table3_steps"],
        "descent_lr": TABLE3_LR,
        "descent_cost": r3.cost,
        "descent_gains": reported_gains("pi", pr, r3.theta),
        "relative_decrease": 1.0 - r3.cost / evaluate(pr, th3),
    }


def checks(runs, problems, name):
    """The local check at the best GA, GA+gradient and multi-start answers of problem ``name``."""
    from pfjax.tuning.problem import check

    pr, out = problems[name], {}
    for method in ("ga", "ga+gradient", "gradient"):
        rs = [r for r in runs if r["problem"] == name and r["method"] == method]
        if not rs:
            continue
        best = min(rs, key=lambda r: r["cost"])
        c = check(pr, best["gains"], controller=name.partition(":")[0])
        out[method] = {
            "seed": best["seed"],
            "cost": c.cost,
            "verdict": c.verdict,
            "probe_decrease": float(c.probe_decrease),
            "projected_gradient_norm": float(np.linalg.norm(c.projected_gradient)),
            "active": c.active.tolist(),
            "eigenvalues": c.eigenvalues.tolist(),
            "quadratic_model": c.quadratic_model,
        }
    return out


def training_problem(cfg, controller: str, n_runs: int, cost=None):
    """A problem on a training set: ``n_runs`` runs per path drawn from the held-out study's
    distribution with run indices from :data:`~pfjax.tuning.study_config.TRAINING_OFFSET` (disjoint
    from the held-out runs), at ``[sim]``'s step and horizon (as the held-out set,
    :func:`~pfjax.tuning.study_config.heldout_study`); ``cost`` default mean IAE."""
    from pfjax.tuning.cost import CostSpec
    from pfjax.tuning.problem import make_problem
    from pfjax.tuning.study_config import TRAINING_OFFSET, heldout_file

    return make_problem(
        controller,
        str(heldout_file(cfg["heldout"])),
        cost=CostSpec() if cost is None else cost,
        config={"dt": cfg["sim"]["dt"], "horizon": cfg["sim"]["horizon"]},
        n_runs=n_runs,
        run_offset=TRAINING_OFFSET,
    )


def tune_K(cfg, spec, progress):
    """K of state feedback tuned by the multi-start tuner, for each of
    :data:`~pfjax.tuning.study_config.K_TUNINGS` (the paper line and the training sample), which
    the study's check of sizes at load reads too."""
    from pfjax.sim import SimConfig
    from pfjax.tuning.problem import make_problem, reported_gains, tune

    sim = SimConfig(dt=cfg["sim"]["dt"], horizon=cfg["sim"]["horizon"], record=False)
    out = {}
    for name, (scenario, runs_key) in K_TUNINGS.items():
        section, _, field = (runs_key or "").partition(".")
        pr = (
            make_problem("state_feedback", scenario, config=sim)
            if runs_key is None
            else training_problem(cfg, "state_feedback", cfg[section][field])
        )
        r = tune(
            pr,
            "gradient",
            key=jax.random.PRNGKey(0),
            theta0=np.array([-2.78, -2.08]),
            multistart=MultistartOptions(**cfg["multistart"]),
            progress=progress,
        )
        out[name] = {
            "K": r.theta.tolist(),
            "gains": reported_gains("state_feedback", pr, r.theta),  # by scalar name, as pfjax tune reports
            "train_cost": r.cost,
            "n_rollouts": r.n_rollouts,
            "wall_s": r.wall_s,
            "rollouts_per_eval": pr.n_per_eval,
        }
        print(
            f"  {name}: K = {np.round(r.theta, 4).tolist()}, train cost {r.cost:.4f} ({r.n_rollouts} rollouts)",
            flush=True,
        )
    return out


def heldout(cfg, spec, controllers, progress):
    """Every controller on the held-out runs and the margin sweep: (run frame, sweep, table); the
    slip margin is the :data:`~pfjax.tuning.study_config.MARGIN_AXIS` sweep's, which the held-out
    study sweeps (checked at load)."""
    from pfjax.montecarlo.runner import margin_sweep, simulate_runs
    from pfjax.montecarlo.summary import margins, run_statistics
    from pfjax.tuning.study_config import MARGIN_AXIS

    runs = np.arange(cfg["robust"]["heldout_runs"])
    frames = []
    for p in range(len(spec.paths)):
        for _, _, df in simulate_runs(spec, p, runs, controllers):
            frames.append(df)
    df = pd.concat(frames, ignore_index=True)
    sweep = margin_sweep(spec, controllers, progress=progress)
    table = []
    for name in controllers:
        st = run_statistics(df[df.controller == name])  # as a study's summary states them
        m = margins(sweep, name, spec.margin.eps)[MARGIN_AXIS]
        table.append(
            {
                "controller": name,
                "success_rate": st["success_rate"],
                "success_ci95": [float(x) for x in st["success_ci95"]],
                "n": st["n"],
                "iae_mean": st["iae_mean"],
                "iae_p95": st["iae_p95"],
                "steady_abs_d_p95_mm": 1e3 * st["steady_abs_d_p95"],
                "slip_margin_deg": None if m.get("fails_at_smallest") else m.get("margin"),
                "margin_fails_at_smallest": m.get("fails_at_smallest"),
            }
        )
    return df, sweep, table


def designs(cfg):
    from pfjax.synthesis import integral_mixed, mixed_h2_hinf, polytopic_mixed, slip_design_plant

    rb = cfg["robust"]
    pol = dict(v_range=(rb["v_lo"], rb["v_hi"]), beta_r_max_deg=rb["beta_r_max_deg"])
    return {
        "lmi-mixed": mixed_h2_hinf(slip_design_plant()).to_dict(),
        "integral": integral_mixed().to_dict(),
        "polytopic": polytopic_mixed(**pol).to_dict(),
        "polytopic-integral": polytopic_mixed(**pol, integral=True).to_dict(),
    }


def integral_steady(cfg) -> float:
    from pfjax import controllers as C
    from pfjax.sim import SimConfig, simulate_batch, stack
    from pfjax.sim.scenario import paper_scenario
    from pfjax.synthesis import integral_mixed
    from pfjax.tuning.study_config import INTEGRAL_STEADY_HORIZON

    g = C.integral_params(integral_mixed().K.ravel())
    sc = stack([paper_scenario("line", g, beta_r_deg=br, beta_f_deg=bf) for br, bf in ((5, 5), (-8, 4), (10, -10))])
    config = SimConfig(dt=cfg["sim"]["dt"], horizon=INTEGRAL_STEADY_HORIZON, record=False)
    r = simulate_batch(sc, controller=C.integral, config=config)
    return float(np.max(np.asarray(r.metrics.steady_abs_d)))


def cli_settings(cfg) -> dict:
    """The study's ``[ga]`` and ``[multistart]`` settings that differ from ``pfjax tune``'s defaults
    (:class:`~pfjax.tuning.GAOptions`, :class:`~pfjax.tuning.MultistartOptions`), by study key;
    empty at the published sizes."""
    from pfjax.tuning.ga import GAOptions

    ga = GAOptions()
    pairs = (("population", ga.population_size), ("generations", ga.generations))
    out = {f"ga.{k}": cfg["ga"][k] for k, d in pairs if cfg["ga"][k] != d}
    default = MultistartOptions().check()._asdict()  # the rounds resolved
    out.update({f"multistart.{k}": v for k, v in cfg["multistart"].items() if v != default[k]})
    return out


def cli_check(cfg, progress):
    """``pfjax tune --method {ga,gradient} --controller pi --scenario paper-line --seed S`` for S <
    cli_seeds: the command line's problem (its 5 ms step, 20 s) with the study's ``[ga]`` and
    ``[multistart]`` settings, the command line's defaults unless ``changed`` (:func:`cli_settings`)
    lists some."""
    from pfjax.tuning.problem import make_problem, tune
    from pfjax.tuning.study_config import ga_options

    pr = make_problem("pi", "paper-line")
    seeds = range(cfg["cli_seeds"])
    opts = ga_options(cfg)
    ms = MultistartOptions(**cfg["multistart"])
    ga = [tune(pr, "ga", key=seed_key(s), ga_options=opts, progress=progress).cost for s in seeds]
    gr = [tune(pr, "gradient", key=seed_key(s), multistart=ms, progress=progress).cost for s in seeds]
    best = min(ga) if ga else float("nan")
    return {
        "dt": pr.config.dt,
        "horizon": pr.config.horizon,
        "changed": cli_settings(cfg),
        "ga_costs": ga,
        "gradient_costs": gr,
        "ga_best": best,
        "gradient_over_ga_best": [c / best - 1.0 for c in gr],
        "met": bool(gr) and all(c <= 1.005 * best for c in gr),
    }


def robust_vs_source(table):
    """Each robust design against each source controller in the held-out ``table``: (verdict lines,
    comparisons of success and margin)."""
    by = {r["controller"]: r for r in table}
    src = [by["pi-table3 (source)"], by["K-paper (source)"]]
    margin = lambda r: (
        -1.0 if (r["slip_margin_deg"] is None or r.get("margin_fails_at_smallest")) else r["slip_margin_deg"]
    )
    # Each robust design against each source controller, success and margin separately. A success
    # rate can only tie a source at 100 % (the ceiling of the held-out sample), so "beats" means:
    # success higher, or both 100 %; and margin strictly larger.
    cmp = lambda a, b: "higher" if a > b else "equal" if a == b else "lower"
    verdicts, comparisons = [], {}
    for name in ("K-gradient-robust", "integral (LMI)", "polytopic (LMI)", "polytopic-integral (LMI)"):
        r = by[name]
        comparisons[name] = {
            s["controller"]: {"success": cmp(r["success_rate"], s["success_rate"]), "margin": cmp(margin(r), margin(s))}
            for s in src
        }
        beats = all(
            c["margin"] == "higher"
            and (c["success"] == "higher" or (c["success"] == "equal" and r["success_rate"] == 1.0))
            for c in comparisons[name].values()
        )
        detail = ", ".join(
            f"success {c['success']} / margin {c['margin']} than {k}" for k, c in comparisons[name].items()
        )
        verdicts.append(f"{name}: {'beats' if beats else 'does not beat'} both ({detail})")
    return verdicts, comparisons


def heldout_controllers(tuning_runs, ks, des) -> dict:
    """The controllers evaluated on the held-out set: name -> (controller, params, gains shown)."""
    from pfjax import controllers as C

    best = lambda m: min(
        (r for r in tuning_runs if r["method"] == m and r["problem"] == "pi:paper-line"), key=lambda r: r["cost"]
    )["gains"]
    # the gains shown by scalar name, as a tuning reports them (pfjax.controllers.flat_gains)
    shown = lambda name, params: (C.entry(name).controller, params, C.flat_gains(C.entry(name), params))
    pi = lambda flat: shown("pi", C.params_from_flat(C.entry("pi"), flat))
    sf = lambda K: shown("state_feedback", C.state_feedback_params(K))
    integ = lambda K: shown("integral", C.integral_params(K))
    controllers = {
        "pi-table3 (source)": pi({}),
        "pi-ga": pi(best("ga")),
        "pi-gradient": pi(best("gradient")),
        "K-paper (source)": sf(C.PAPER_K),
        "K-lmi-mixed": sf(des["lmi-mixed"]["K"]),
        "K-gradient-single": sf(ks["K-gradient-single"]["K"]),
        "K-gradient-robust": sf(ks["K-gradient-robust"]["K"]),
        "integral (LMI)": integ(des["integral"]["K"]),
        "polytopic (LMI)": sf(des["polytopic"]["K"]),
        "polytopic-integral (LMI)": integ(des["polytopic-integral"]["K"]),
    }
    return controllers


def wins_needed(seeds: int) -> int:
    """Seeds a tuner must win of ``seeds`` to meet the target: at least 95 % of them, rounded up
    (19 of 20, 38 of 40; every seed of fewer than 20, so that one seed is never a target of 0)."""
    return (19 * seeds + 19) // 20


def targets_by_problem(cfg, runs):
    """Per problem: the multi-start tuner (and plain adam) against the GA's median on the same seeds."""
    out = {}
    need = wins_needed(cfg["seeds"])
    for name in problem_list(cfg["compare"]["problems"]):
        by = lambda m, name=name: [r for r in runs if r["problem"] == name and r["method"] == m]
        ga = by("ga")
        med = float(np.median([r["cost"] for r in ga]))
        row = {"ga_median": med, "ga_best": min(r["cost"] for r in ga), "ga_rollouts": ga[0]["n_rollouts"]}
        for m in ("ga", "gradient", "gradient-plain"):
            rs = by(m)
            c = np.asarray([r["cost"] for r in rs])
            wins = int(np.sum(c <= med))
            row[m] = {
                "median": float(np.median(c)),
                "min": float(c.min()),
                "max": float(c.max()),
                "wins": wins,
                "n": len(c),
                "rollouts": rs[0]["n_rollouts"],
                "forward_passes": rs[0]["n_forward_passes"],
                "rollout_fraction": rs[0]["n_rollouts"] / ga[0]["n_rollouts"],
                "forward_pass_fraction": rs[0]["n_forward_passes"] / ga[0]["n_forward_passes"],
                "wall_s_median": float(np.median([r["wall_s"] for r in rs])),
                "met": bool(wins >= need and rs[0]["n_rollouts"] * 10 <= ga[0]["n_rollouts"]),
                "met_forward_passes": bool(
                    wins >= need and rs[0]["n_forward_passes"] * 10 <= ga[0]["n_forward_passes"]
                ),
            }
        row["ga_wall_s_median"] = float(np.median([r["wall_s"] for r in ga]))
        out[name] = row
    return out
