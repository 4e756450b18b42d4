"""Smoke test of ``studies/tuning_ga_vs_gradient.py --quick`` (run as a subprocess: the study turns on
float64 for its whole process) and of its bad-input contract.

References: the config hash is recomputed with :func:`pfjax.provenance.config_hash` from the stored config;
every held-out success rate and Clopper-Pearson interval is recounted from ``heldout.parquet`` with
scipy's beta quantiles (1e-9); the GA's rollout count is the MATLAB formula P + G (P - E) with E = 1;
the multi-start tuner's count is recomputed from its options (screened points plus the default gains, the
halving chains, the restart chains, the compass polish); the cost history of every run is non-increasing and ends at the run's
reported cost.
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

from pfjax.provenance import config_hash

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
    return d


@pytest.mark.slow
def test_quick_tuning_study_outputs_consistent(out):
    s = json.loads((out / "summary.json").read_text())
    assert s["config_sha256"] == config_hash(s["config"])
    for name in ("tuning_runs", "heldout", "margin"):
        assert pq.read_schema(out / f"{name}.parquet").metadata[b"pfjax.config_sha256"].decode() == s["config_sha256"]
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
        D = sum(len(v) if isinstance(v, list) else 1 for v in r["gains"].values())
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
