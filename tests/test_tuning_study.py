"""Smoke test of ``studies/tuning_ga_vs_gradient.py --quick`` (run as a subprocess: the study turns on
float64 for its whole process) and of its bad-input contract.

References: the config hash is recomputed with :func:`pfjax.provenance.config_hash` from the stored config;
every held-out success rate and Clopper-Pearson interval is recounted from ``heldout.parquet`` with
scipy's beta quantiles (1e-9); the GA's rollout count is the MATLAB formula P + G (P - E) with E = 1;
the multi-start tuner's count is recomputed from its options (screened points plus the default gains, the
halving chains, the restart chains, the compass polish); the cost history of every run is non-increasing and ends at the run's
reported cost; every number of summary.json has a unit in its ``units`` map (``tests/units_check.py``).
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pyarrow.parquet as pq
import pytest
from scipy.stats import beta
from units_check import numbers_without_units

from pfjax import controllers as C
from pfjax.provenance import STAMP_UNITS, config_hash

ROOT = Path(__file__).resolve().parents[1]
STUDY = ROOT / "studies" / "tuning_ga_vs_gradient.py"


def _run(*args, cwd=ROOT):
    env = {**os.environ, "PFJAX_CACHE_DIR": str(ROOT / ".pytest_cache" / "xla")}
    return subprocess.run(
        [sys.executable, str(STUDY), *args], cwd=cwd, capture_output=True, text=True, env=env, timeout=900
    )


@pytest.fixture(scope="module")
def out(tmp_path_factory):
    d = tmp_path_factory.mktemp("tuning") / "out"
    r = _run("--quick", "--out", str(d))
    assert r.returncode == 0, r.stderr[-3000:]
    (d.parent / "stdout.json").write_text(r.stdout)
    return d


@pytest.mark.slow
def test_quick_tuning_study_outputs_consistent(out):
    s = json.loads((out / "summary.json").read_text())
    # the config and the held-out study as read: the marker's hash too (a held-out file edited in
    # place gives another hash, so its output is not replaced as a re-run of the same config)
    assert s["config_sha256"] == config_hash({**s["config"], "heldout_config_sha256": s["heldout"]["config_sha256"]})
    assert json.loads((out / ".pfjax-output.json").read_text())["config_sha256"] == s["config_sha256"]

    def not_json(c):
        raise AssertionError(f"the script printed {c}, which is not JSON")

    text = (out.parent / "stdout.json").read_text()  # the parts' lines, then the JSON object
    printed = json.loads(text[text.rfind("\n{") + 1 :], parse_constant=not_json)  # strict JSON
    assert printed["out"] == str(out) and printed["targets"].keys() == s["targets"].keys()
    # every number of summary.json has a unit in its units map: costs IAE in m s, the held-out
    # steady error in mm, the seeds as the provenance record gives them
    units = s["units"]
    assert numbers_without_units(s) == []
    assert units["cost"].startswith("m s (") and units["steady_abs_d_p95_mm"].startswith("mm ")
    assert units["n"].startswith("runs in heldout.table") and "seeds in targets.by_problem" in units["n"]
    assert units["seed"] == STAMP_UNITS["seed"]
    for name in ("tuning_runs", "heldout", "margin"):
        meta = pq.read_schema(out / f"{name}.parquet").metadata
        assert meta[b"pfjax.config_sha256"].decode() == s["config_sha256"]
        assert json.loads(meta[b"pfjax.seed"]) == s["seed"] == list(range(s["config"]["seeds"]))  # the tuners' seeds
    assert (out / "figures" / "cost_vs_budget.png").stat().st_size > 1000
    report = (out / "report.md").read_text()
    html = (out / "report.html").read_text()
    for text in (report, html):  # the headline numbers of the summary in both renderings
        assert s["config_sha256"][:16] in text
        for name, row in s["targets"]["by_problem"].items():
            for m in ("ga", "gradient", "gradient-plain"):
                assert f"{row[m]['median']:.5f}" in text, (name, m)
        assert f"{s['table3']['cost']:.5f}" in text
        for row in s["heldout"]["table"]:
            assert f"{100 * row['success_rate']:.1f} %" in text

    # GA budget: P + G (P - E) rollouts per seed (MATLAB ga, elite count 1); plain adam's: one per step and start;
    # the multi-start tuner's: screened points + the default gains, then 1 rollout per chain and step
    P, G = s["config"]["ga"]["population"], s["config"]["ga"]["generations"]
    ms = s["config"]["multistart"]
    chains, per_round = [], [ms["steps"] // ms["rounds"]] * ms["rounds"]
    for i in range(ms["steps"] % ms["rounds"]):
        per_round[i] += 1
    n = ms["n_starts"]
    for _ in range(ms["rounds"]):
        chains.append(n)
        n = max(1, n // 2)
    multistart = ms["n_screen"] + 1 + sum(c * k for c, k in zip(chains, per_round))
    if ms["n_restarts"] and ms["restart_steps"]:  # the restarts: the incumbent and its perturbations
        multistart += (ms["n_restarts"] + 1) * ms["restart_steps"]
    expected = {
        "ga": P + G * (P - 1),
        "gradient-plain": s["config"]["gradient"]["steps"] * s["config"]["gradient"]["starts"],
        "gradient": multistart,
        "ga+gradient": P + G * (P - 1) + 30,
    }
    runs = pd.DataFrame(s["tuning_runs"])
    assert set(runs.method) == set(expected)
    for r in s["tuning_runs"]:
        # the compass polish: 2 D value-only points per iteration (D gains)
        # D tuned gains: the registry's tuning box (the gains record every gain by its scalar name)
        D = len(C.REGISTRY[r["problem"].partition(":")[0]].box[1])
        assert set(r["gains"]) == set(C.flat_gains(C.entry(r["problem"].partition(":")[0]))), r["gains"]
        polish = ms["polish_steps"] * 2 * D if r["method"] == "gradient" else 0
        assert r["n_rollouts"] == expected[r["method"]] + polish, r
        assert r["n_forward_passes"] >= r["n_rollouts"]
    hist = pd.read_parquet(out / "tuning_runs.parquet")
    for r in s["tuning_runs"]:
        h = hist[(hist.problem == r["problem"]) & (hist.method == r["method"]) & (hist.seed == r["seed"])]
        h = h.sort_values("iteration")
        assert (h.best_cost.diff().dropna() <= 1e-12).all()
        assert h.best_cost.iloc[-1] == pytest.approx(r["cost"], rel=1e-9)

    # every held-out number recounted from the run rows
    df = pd.read_parquet(out / "heldout.parquet")
    n_paths = df.path.nunique()
    for row in s["heldout"]["table"]:
        g = df[df.controller == row["controller"]]
        k, n = int(g.success.sum()), len(g)
        assert n == row["n"] == s["heldout"]["n_per_path"] * n_paths
        assert row["success_rate"] == pytest.approx(k / n, abs=1e-12)
        lo = 0.0 if k == 0 else beta.ppf(0.025, k, n - k + 1)
        hi = 1.0 if k == n else beta.ppf(0.975, k + 1, n - k)
        assert row["success_ci95"] == pytest.approx([lo, hi], abs=1e-9)
        assert row["iae_mean"] == pytest.approx(float(g.iae.mean()), rel=1e-9)
        assert f"{100 * row['success_rate']:.1f} %" in report
    assert {r["controller"] for r in s["heldout"]["table"]} >= {
        "pi-table3 (source)",
        "K-paper (source)",
        "integral (LMI)",
        "polytopic (LMI)",
        "K-gradient-robust",
    }
    # the integral design removes the slip offset (below 0.1 mm even at quick sizes)
    assert s["targets"]["integral_steady_abs_d_m"] < 1e-4


@pytest.mark.parametrize(
    "setting, message",
    [
        ("seeds=0", "seeds: must be >= 1"),
        ("ga.population=1", "ga.population: must be >= 2"),
        ("gradient.lr=-1", "gradient.lr: must be > 0"),
        ("multistart.sampler=halton", "multistart.sampler: value 'halton'"),
        ("compare.problems='pi:paper-all'", "compare.problems: must list pi:paper-line"),
        ("heldout=nope.toml", "heldout: file not found"),
        ("compare.problemz='pi:paper-line'", "compare.problemz: unknown key (did you mean 'compare.problems'?)"),
        ("robust.heldout_runs=0", "robust.heldout_runs: must be >= 1 (got 0)"),
        ("compare.ablation.adam.local='x'", "compare.ablation.adam: local: value 'x'"),
    ],
)
def test_bad_setting_one_line_exit_2_nothing_written(tmp_path, setting, message):
    d = tmp_path / "out"
    r = _run("--quick", "--set", setting, "--out", str(d))
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and message in lines[0], r.stderr
    assert not d.exists() and list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    ("override", "key", "text"),
    [
        ("sim.horizon=20.005", "sim.horizon", "must be a whole number of steps dt = 0.01 s"),
        ("sim.dt=0.0064", "sim.dt", "the integral design's 30 s runs: horizon: must be a whole number"),
    ],
)
def test_a_step_that_does_not_divide_a_horizon_is_refused_at_load(override, key, text):
    """The problems' horizon and the integral design's 30 s steady-state runs are both whole numbers
    of steps ``sim.dt``, checked when the study is read (before hours of tuning), naming the key."""
    from pfjax.config import ConfigError
    from pfjax.tuning.study_config import load

    with pytest.raises(ConfigError, match=rf"^{re.escape(key)}: .*{re.escape(text)}"):
        load(overrides=[override])
    assert load(overrides=["sim.dt=0.008"], quick=True).sim.dt == 0.008


# --------------------------------------------------------------------------- checked at load, reported as run


def _load(*overrides, path=None):
    from pfjax.tuning.study_config import load

    return load(path, overrides, quick=True)


@pytest.mark.parametrize(
    "overrides, message",
    [
        (["robust.train_runs=2000000"], "robust.train_runs: must be <= 1000000, got 2000000"),
        (["compare.cvar_runs=2000000"], "compare.cvar_runs: must be <= 1000000, got 2000000"),
        # the GA's own bounds (pfjax.tuning.ga.validate_options), as pfjax tune checks --generations
        (["ga.generations=-1"], "ga.generations: must be >= 0"),
        (["ga.generations=100000000"], "ga.generations: must be <= "),
        (["ga.population=1"], "ga.population: must be >= 2"),
        (["robust.heldout_runs=200000000"], "robust.heldout_runs: must be <= 100000000"),
        (
            ["heldout=studies/tuning_ga_vs_gradient.toml"],
            "heldout: studies/tuning_ga_vs_gradient.toml: name: required key is missing",
        ),
        (["compare.ablation.x={foo=1}"], "compare.ablation.x.foo: unknown key; expected one of n_screen, sampler, "),
        (['compare.problems="pi:paper-line, pi:paper-line"'], "compare.problems: each problem once, repeated: pi:"),
        (['compare.ablate_problems="pi:paper-line,pi:paper-line"', "compare.ablate=true"], "compare.ablate_problems: "),
    ],
)
def test_a_bad_study_is_refused_at_load_naming_the_study_key(overrides, message):
    """Before any tuning: the training sets' bound (make_problem's), the held-out study (loaded at
    the study's sizes; its errors by the study's key or under ``heldout: <path>:``), the ablation's
    keys, a problem listed twice."""
    from pfjax.config import ConfigError

    with pytest.raises(ConfigError, match="^" + re.escape(message)):
        _load(*overrides)


def test_a_training_set_beyond_the_memory_budget_is_refused_at_load(monkeypatch):
    """pfjax.resources' estimates of the tuners (tune's own), named by the training set's runs: at
    1 GiB a 6-member GA population on 200000 runs x 3 paths, and 2 chains with 2 tangents on
    20000 x 3, are too large."""
    from pfjax.config import ConfigError

    monkeypatch.setenv("PFJAX_MEMORY_BUDGET", str(1 << 30))
    with pytest.raises(
        ConfigError, match=r"^compare\.cvar_runs: a GA population of 6 x 600000 runs needs about 16\.1 "
    ):
        _load('compare.problems="pi:paper-line, pi:heldout-cvar"', "compare.cvar_runs=200000")
    with pytest.raises(ConfigError, match=r"^robust\.train_runs: 2 starts x 60000 runs with 2 tangents needs about "):
        _load("robust.train_runs=20000")
    _load('compare.problems="pi:paper-line, pi:heldout-cvar"', "compare.cvar_runs=2000", "robust.train_runs=2000")


def _heldout_toml(tmp_path, axes: str) -> Path:
    """The study's held-out set on the line alone, sweeping ``axes``."""
    text = (ROOT / "studies" / "tuning_heldout.toml").read_text().replace('axes = ["joint"]', f"axes = {axes}")
    text = text.split("[[paths]]")[0] + '[[paths]]\nkind = "line"\n\n[[controllers]]\nname = "pi-table3"\ntype = "pi"\n'
    f = tmp_path / "heldout.toml"
    f.write_text(text)
    return f


def test_the_heldout_set_by_its_example_name_loads_from_any_directory(tmp_path, monkeypatch):
    """``heldout`` is a study TOML relative to the working directory, or a packaged example's name,
    which reads the same held-out study wherever the study runs (the schema's default)."""
    from pfjax import examples
    from pfjax.config import ConfigError
    from pfjax.tuning.study_config import heldout_file, heldout_study

    toml = ROOT / "studies" / "tuning_ga_vs_gradient.toml"
    monkeypatch.chdir(tmp_path)
    with pytest.raises(
        ConfigError,
        match=r"^heldout: file not found: studies/tuning_heldout\.toml \(a study TOML relative to the working "
        r"directory, or a packaged example's name: default, heldout, random_paths, slip_frequency, rare_events\)$",
    ):
        _load(path=toml)
    cfg = _load("heldout='heldout'", path=toml)
    assert heldout_file(cfg.heldout).read_bytes() == (ROOT / "studies" / "tuning_heldout.toml").read_bytes()
    assert heldout_study(cfg.model_dump(mode="json")).name == "tuning_heldout"
    assert _load().heldout == "heldout"  # the schema's default
    (tmp_path / "mine.toml").write_bytes(examples.path("heldout").read_bytes())
    assert heldout_file(_load("heldout='mine.toml'").heldout).resolve() == (tmp_path / "mine.toml").resolve()


def test_a_heldout_study_without_a_joint_sweep_is_refused(tmp_path):
    """The held-out table's margins and the robust-vs-source verdict read the joint sweep."""
    from pfjax.config import ConfigError

    f = _heldout_toml(tmp_path, '["rear"]')
    with pytest.raises(ConfigError, match=rf"^heldout: {re.escape(str(f))}: .*margin\.axes must include 'joint'"):
        _load(f'heldout="{f}"')


def _summary(cfg: dict, heldout: dict, cli: dict) -> dict:
    """A summary with every field the report reads (made-up numbers: the report's words are tested)."""
    from pfjax.tuning.study_parts import wins_needed

    g = {"median": 0.3, "min": 0.29, "max": 0.31, "wins": 1, "n": 2, "rollouts": 10, "rollout_fraction": 0.1}
    g.update(forward_passes=30, forward_pass_fraction=0.3, wall_s_median=1.0, met=True)
    row = {"ga_median": 0.3, **{m: g for m in ("ga", "gradient", "gradient-plain")}}
    runs = [
        {"problem": "pi:paper-line", "method": m, "seed": 0, "cost": 0.3, "n_rollouts": 10, "n_forward_passes": 30}
        for m in ("ga", "gradient", "gradient-plain")
    ]
    h = {"controller": "pi-table3 (source)", "gains": {"kp_d": 1.0}, "success_rate": 1.0, "success_ci95": [0.9, 1.0]}
    h.update(n=3, iae_mean=0.4, iae_p95=0.5, steady_abs_d_p95_mm=20.0, slip_margin_deg=7.5)
    t3 = {
        "cost": 0.7,
        "gradient": [0.0],
        "check_verdict": "-",
        "descent_steps": 1,
        "descent_lr": 0.01,
        "descent_cost": 0.5,
    }
    t3.update(relative_decrease=0.3, descent_gains={})
    return {
        "pfjax_version": "0",
        "config": cfg,
        "config_sha256": "0" * 64,
        "machine": "-",
        "wall_s": 1.0,
        "tuning_runs": runs,
        "checks": {},
        "table3": t3,
        "designs": {},
        "heldout": {**heldout, "table": [h]},
        "targets": {
            "wins_needed": wins_needed(cfg["seeds"]),
            "by_problem": {"pi:paper-line": row},
            "cli": cli,
            "robust_vs_source": "-",
            "integral_steady_abs_d_m": 1e-7,
        },
    }


def test_the_report_says_what_was_run(tmp_path, monkeypatch):
    """Part 1b says "the command line's defaults" only when it ran them (the published config) and
    names the study's settings otherwise (--quick); the target is the computed wins of the seeds
    run; the held-out text names the held-out study's paths and sweeps; costs carry m·s."""
    from pfjax.report.document import to_markdown
    from pfjax.tuning import study_parts
    from pfjax.tuning.study import heldout_spec, heldout_summary
    from pfjax.tuning.study_config import load
    from pfjax.tuning.study_report import report

    published = load(STUDY.with_suffix(".toml")).model_dump(mode="json")
    assert study_parts.cli_settings(published) == {}  # the published [ga], [multistart]: the command line's defaults

    # part 1b runs the tuners at the study's [ga] and [multistart] and records what differs
    seen = []

    def fake_tune(pr, method, *, key, ga_options=None, multistart=None, progress=False):
        seen.append((pr.config.dt, pr.config.horizon, method, ga_options, multistart))
        return type("R", (), {"cost": 0.3})()

    monkeypatch.setattr("pfjax.tuning.problem.tune", fake_tune)
    f = _heldout_toml(tmp_path, '["rear", "joint"]')
    cfg = _load("cli_seeds=1", f'heldout="{f}"').model_dump(mode="json")
    cli = study_parts.cli_check(cfg, progress=False)  # quick: 6 x 2 GA, 2-step multi-start
    assert [s[:3] for s in seen] == [(0.005, 20.0, "ga"), (0.005, 20.0, "gradient")]
    assert seen[0][3].population_size == 6 and seen[1][4].steps == 2
    assert cli["changed"]["ga.population"] == 6 and cli["changed"]["multistart.steps"] == 2

    heldout = heldout_summary(cfg, heldout_spec(cfg), [])
    assert heldout["paths"] == ["line"] and heldout["margin_axes"] == ["rear", "joint"]
    text = to_markdown(report(_summary(cfg, heldout, cli)))
    assert "command line's defaults (" not in text
    assert "with the study's settings where they differ from its defaults (ga.population = 6, " in text
    assert "the target is 2 of 2 seeds" in text and "19 of 20" not in text
    assert "3 runs per path (line), " in text and "parabola" not in text
    assert "slip margin from the joint sweep" in text and "also holds the rear sweep" in text
    assert "iae_mean [m·s]" in text and "Costs in m·s" in text

    cli["changed"] = {}
    text = to_markdown(report(_summary(published, heldout, cli)))
    assert "`pfjax tune --method gradient` at the command line's defaults (dt 0.005 s, horizon 20 s)" in text
    assert "the target is 19 of 20 seeds" in text


def test_sim_sets_the_training_sets_as_the_heldout_set(monkeypatch):
    """``[sim]`` is the step and horizon of the held-out set and of the training sets drawn from its
    distribution (heldout-cvar, the robust K); at the published defaults these are the held-out
    study's own (10 ms, 20 s), so the published numbers stand."""
    from types import SimpleNamespace

    import numpy as np

    from pfjax.tuning import study_parts
    from pfjax.tuning.cost import CostSpec
    from pfjax.tuning.problem import make_problem
    from pfjax.tuning.study import heldout_spec, make_study_problem
    from pfjax.tuning.study_config import load

    cfg = _load("sim.horizon=30", "sim.dt=0.005", 'compare.problems="pi:paper-line, pi:heldout-cvar"')
    cfg = cfg.model_dump(mode="json")
    spec = heldout_spec(cfg)
    assert (spec.sim.dt, spec.sim.horizon) == (0.005, 30.0)
    pr = make_study_problem(cfg, "pi:heldout-cvar")
    assert (pr.config.dt, pr.config.horizon) == (0.005, 30.0)
    seen = []

    def fake_tune(pr, method, **kw):
        seen.append((pr.config.dt, pr.config.horizon))
        return SimpleNamespace(theta=np.zeros(2), cost=0.0, n_rollouts=0, wall_s=0.0)

    monkeypatch.setattr("pfjax.tuning.problem.tune", fake_tune)
    study_parts.tune_K(cfg, spec, progress=False)
    assert seen == [(0.005, 30.0), (0.005, 30.0)]  # K on the paper line, K on the training set

    published = load(STUDY.with_suffix(".toml")).model_dump(mode="json")
    own = make_problem("pi", published["heldout"], cost=CostSpec(aggregate="cvar"), n_runs=3, run_offset=1 << 20)
    assert make_study_problem(published, "pi:heldout-cvar").config == own.config


def test_tuning_runs_and_the_figure_carry_the_cost_unit(tmp_path, monkeypatch):
    """Every problem's cost is an IAE (mean, or CVaR over the runs): m s in tuning_runs.parquet,
    m·s on the figure's cost axis."""
    import matplotlib.axes

    from pfjax.tables import units
    from pfjax.tuning.study import write_tables
    from pfjax.tuning.study_report import figures

    hist = pd.DataFrame(
        {"problem": "pi:paper-line", "method": "ga", "seed": 0, "iteration": [0, 1]}
        | {"best_cost": [0.5, 0.4], "rollouts": [6, 11], "wall_s": [0.1, 0.2]}
    )
    write_tables({"tuning_runs": hist}, tmp_path, {})
    u = units(tmp_path / "tuning_runs.parquet")
    assert set(u) == set(hist.columns)
    assert (u["best_cost"]["unit"], u["wall_s"]["unit"], u["rollouts"]["unit"]) == ("m s", "s", "")
    labels = []
    monkeypatch.setattr(matplotlib.axes.Axes, "set_ylabel", lambda self, text, *a, **k: labels.append(text))
    figures(hist, "pi:paper-line", tmp_path)
    assert labels == ["best cost so far [m·s]"] * 2


def test_the_win_target_is_95_percent_of_the_seeds_rounded_up():
    from pfjax.tuning.study_parts import wins_needed

    assert [wins_needed(n) for n in (1, 2, 10, 19, 20, 21, 40)] == [1, 2, 10, 19, 19, 20, 38]
