"""``pfjax bench`` at tiny sizes: the output contract, the agreement of every reference with pfjax,
and bad input. Speed is not asserted (it is measured by the benchmark, never by tests).

References: the NumPy, Numba and SciPy ``solve_ivp`` implementations of :mod:`pfjax.bench.references`
solve the same batch independently of pfjax's simulator; the benchmark itself checks that their
per-run IAE agrees with pfjax's (float64 to 1e-10 m s, float32 to 1e-4 m s, SciPy to 1e-8 m s;
the reasons are in :data:`pfjax.bench.run.TOLERANCE`), and this test asserts that every check passed.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import types
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

ROOT = Path(__file__).resolve().parents[1]
KEYS = (
    "msteps_per_s_f32",
    "msteps_per_s_f64",
    "numba_msteps_per_s_f32",
    "ratio_vs_numba_f32",
    "grad_over_forward",
    "peak_rss_mib",
)


def _bench(*args):
    env = {**os.environ, "PFJAX_CACHE_DIR": str(ROOT / ".pytest_cache" / "xla")}
    return subprocess.run(
        [sys.executable, "-m", "pfjax.cli", "bench", *args],
        cwd=ROOT,
        capture_output=True,
        text=True,
        env=env,
        timeout=900,
    )


def test_the_models_paragraph_describes_only_the_models_that_ran():
    """--quick runs the kinematic and ST models: no STD clause; with STD, its vehicle and step."""
    from pfjax.bench import report

    row = lambda ns: {"wall_s": 0.1, "ns_per_rollout_step": ns}
    quick = {"runs": 64, "steps": 400, "controller": "stanley", "path": "sine"}
    for d in ("float32", "float64"):
        quick[d] = {"kinematic": row(5.0), "st": row(10.0), "ratio_st_over_kinematic": 2.0}
    text = "\n".join(report._models(quick))
    assert "STD" not in text and "metrics on):" in text and "| st | 10.0 | 10.0 | 2.00x | 2.00x |" in text
    full = {
        **quick,
        **{d: {**quick[d], "std": row(30.0), "ratio_std_over_kinematic": 6.0} for d in ("float32", "float64")},
    }
    text = "\n".join(report._models(full))
    assert (
        "metrics on; STD: vehicle 2 at 10 m/s, 2 ms step):" in text and "| std | 30.0 | 30.0 | 6.00x | 6.00x |" in text
    )


@pytest.mark.slow
def test_quick_bench_contract_and_agreement(tmp_path):
    out = tmp_path / "bench"
    r = _bench("--quick", "--sizes", "64,128", "--out", str(out), "--json")
    assert r.returncode == 0, r.stderr[-3000:]
    s = json.loads(r.stdout)
    for k in KEYS:
        assert math.isfinite(s[k]) and s[k] > 0, k
    assert s["all_agree"] and s["disagreeing"] == [], s["agreement"]
    assert set(s["agreement"]) == {
        "jax_minimal_float32",
        "jax_minimal_float64",
        "numba_float32",
        "numba_float64",
        "numpy_float32",
        "numpy_float64",
        "scipy_float64",
    }
    # pfjax's throughput as a fraction of the minimal JAX implementation's, recomputed from the rates
    for p in ("f32", "f64"):
        assert s[f"fraction_of_minimal_{p}"] == pytest.approx(
            s[f"msteps_per_s_{p}"] / s[f"minimal_msteps_per_s_{p}"], rel=1e-12
        )
    # and at every batch size, from the rows of that size
    rows = pd.read_parquet(out / "bench.parquet")
    rate = lambda impl, dtype, b: rows[(rows.impl == impl) & (rows.dtype == dtype) & (rows.batch == b)].msteps_per_s
    assert [f["batch"] for f in s["fraction_of_minimal_by_batch"]] == [64, 128]
    for f in s["fraction_of_minimal_by_batch"]:
        for p, dtype in (("f32", "float32"), ("f64", "float64")):
            want = rate("pfjax", dtype, f["batch"]).item() / rate("jax_minimal", dtype, f["batch"]).item()
            assert f[p] == pytest.approx(want, rel=1e-12)
    assert s["fraction_of_minimal_by_batch"][-1]["f32"] == s["fraction_of_minimal_f32"]
    assert s["gradient"]["grad_finite"] and s["failed_runs"] == 0
    # forward mode (2 gains) and reverse mode: one derivative, float32 rounding apart
    assert s["grad_mode"] == "forward" and s["gradient"]["modes_max_rel_diff"] < 1e-3
    assert s["grad_over_forward_reverse"] > 0
    # a small batch: reverse mode checkpoints every step, and the report says so
    assert s["gradient"]["reverse_segment"] == 0
    assert s["ratio_vs_numba_f32"] == pytest.approx(s["msteps_per_s_f32"] / s["numba_msteps_per_s_f32"], rel=1e-12)
    # the vehicle models in the same loop (--quick: kinematic and ST), the ratio recomputed from the times
    for p, dtype in (("f32", "float32"), ("f64", "float64")):
        row = s["models"][dtype]
        assert s[f"model_cost_ratio_st_{p}"] == pytest.approx(
            row["st"]["wall_s"] / row["kinematic"]["wall_s"], rel=1e-12
        )
        assert s[f"model_cost_ratio_st_{p}"] > 0 and s[f"model_cost_ratio_std_{p}"] is None
    full = json.loads((out / "bench.json").read_text())
    printed = ("out", "machine", "config_sha256", "seed", "pfjax_version", "units")
    assert full["summary"] == {k: v for k, v in s.items() if k not in printed}
    assert s["config_sha256"] == full["config_sha256"] and s["units"]["msteps_per_s_f32"] == "1e6 rollout-steps/s"
    assert full["config"]["sizes"] == [64, 128] and full["config_sha256"] and full["machine"]["cpus"] >= 1
    from test_bench_agreement import numbers_without_units

    assert numbers_without_units(full) == []  # every number of bench.json with its unit
    assert set(rows.impl) == {"pfjax", "jax_minimal", "numba", "numpy", "scipy"}
    for impl in ("pfjax", "jax_minimal"):
        assert sorted(rows[(rows.impl == impl) & (rows.dtype == "float32")].batch) == [64, 128]
    # rollout-steps / s recomputed from the rows' seconds
    n_steps = full["n_steps"]
    np.testing.assert_allclose(rows.msteps_per_s, rows.batch * n_steps / rows.seconds / 1e6, rtol=1e-12)
    assert (out / "figures" / "throughput.png").stat().st_size > 5000 and (out / "report.md").is_file()
    # the goals: every one reported, none measured by a --quick run (2 s horizon, small batches)
    from pfjax.bench.goals import GOALS

    assert [g["goal"] for g in s["goals"]] == [g.name for g in GOALS]
    assert all(g["value"] is None and g["met"] is None for g in s["goals"])
    report = (out / "report.md").read_text()
    assert "Goals on this machine (docs/performance.md, Scale targets): none measured" in report
    assert report.count("| not measured | – |") == len(GOALS)
    assert "reverse mode " in report and "x (every step checkpointed; the two gradients differ by" in report


@pytest.mark.parametrize(
    "args, flag", [(["--sizes", "10,x"], "--sizes"), (["--sizes", "0"], "--sizes"), (["--seed", "-1"], "--seed")]
)
def test_bench_bad_input_one_line_exit_2(tmp_path, args, flag, capsys):
    from pfjax.cli import main

    out = tmp_path / "b"
    assert main(["bench", "--quick", *args, "--out", str(out)]) == 2
    err = capsys.readouterr()
    assert err.out == "" and err.err.startswith(f"pfjax bench: error: {flag}") and err.err.count("\n") == 1
    assert not out.exists()


def test_bench_outputs_carry_units_and_the_config_hash(tmp_path, monkeypatch, capsys):
    """bench.parquet: each column's unit, ``failed_runs`` a whole count (null where not counted);
    bench.json: a ``units`` map; ``--json``: the summary with its units, config hash and seed. The
    benchmark itself is stubbed (its rows as it makes them)."""
    from dataclasses import asdict

    from matplotlib.figure import Figure

    from pfjax.bench import report, run
    from pfjax.cli import main
    from pfjax.tables import units

    def fake_run(cfg, progress=None):
        row = dict(impl="pfjax", dtype="float32", batch=256, seconds=0.1, compile_s=1.0, msteps_per_s=1.0)
        rows = [dict(row, failed_runs=0), dict(row, impl="numpy", failed_runs=None)]
        summary = dict(
            msteps_per_s_f32=1.0,
            ratio_vs_numpy_f32=2.0,
            peak_rss_mib=100.0,
            failed_runs=0,
            gradient={"forward_s": 0.1, "grad_s": 0.2, "mode": "forward"},
            agreement={"numpy_float32": {"max_abs_diff": 1e-7, "tolerance": 1e-4, "ok": True}},
            models={
                "float32": {"kinematic": {"wall_s": 0.1, "ns_per_rollout_step": 5.0}, "ratio_st_over_kinematic": 2.0}
            },
        )
        return dict(summary=summary, rows=rows, machine={"cpus": 2}, config=asdict(cfg), problem={"dt": 0.005})

    monkeypatch.setattr(run, "run", fake_run)
    monkeypatch.setattr(report, "markdown", lambda result: "# stub\n")
    monkeypatch.setattr(report, "throughput_figure", lambda rows, machine: Figure())
    out = tmp_path / "bench"
    assert main(["bench", "--quick", "--out", str(out), "--json"]) == 0
    printed = json.loads(capsys.readouterr().out)
    full = json.loads((out / "bench.json").read_text())
    assert printed["config_sha256"] == full["config_sha256"] and len(full["config_sha256"]) == 64
    assert printed["seed"] == full["seed"] == 0 and printed["pfjax_version"] == full["pfjax_version"]
    assert printed["units"] == {
        "msteps_per_s_f32": "1e6 rollout-steps/s",
        "ratio_vs_numpy_f32": "1",
        "peak_rss_mib": "MiB",
        "failed_runs": "runs (not status ok, over every row)",
        "seed": "1 (the random seed)",
        "gradient.forward_s": "s",
        "gradient.grad_s": "s",
        "agreement.numpy_float32.max_abs_diff": "m s",
        "agreement.numpy_float32.tolerance": "m s",
        "models.float32.kinematic.wall_s": "s",
        "models.float32.kinematic.ns_per_rollout_step": "ns",
        "models.float32.ratio_st_over_kinematic": "1",
        "machine.cpus": "CPUs",
    }
    assert {k: v for k, v in full["units"].items() if not k.startswith(("summary.", "config."))} == {
        "rows.batch": "runs",
        "rows.seconds": "s",
        "rows.compile_s": "s",
        "rows.msteps_per_s": "1e6 rollout-steps/s",
        "rows.failed_runs": "runs",
        "problem.dt": "s",
        "machine.cpus": "CPUs",
        "seed": "1 (the random seed)",
    }
    assert {k: v for k, v in full["units"].items() if k.startswith("config.")} == {
        f"config.{k}": report.CONFIG_UNITS[k]
        for k, v in full["config"].items()
        if k == "sizes" or (isinstance(v, (int, float)) and not isinstance(v, bool))
    }  # every number of the config, the batch sizes too
    assert full["units"]["summary.agreement.numpy_float32.max_abs_diff"] == "m s"
    got = units(out / "bench.parquet")
    assert got["seconds"]["unit"] == "s" and got["msteps_per_s"]["unit"] == "1e6 rollout-steps/s"
    assert set(got) == set(report.COLUMNS)
    table = pd.read_parquet(out / "bench.parquet")
    assert str(table.failed_runs.dtype) == "Int64" and table.failed_runs.tolist()[0] == 0
    assert table.failed_runs.isna().tolist() == [False, True]
    assert set(table.config_sha256) == {full["config_sha256"]}


def test_bench_sizes_help_states_what_it_governs(capsys):
    from pfjax.cli import main

    with pytest.raises(SystemExit):
        main(["bench", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "default 1000,10000,100000; --quick: 256,1024" in text
    assert "the gradient's batch (2,000; --quick: 256) and the vehicle-model comparison" in text


@pytest.mark.parametrize("key", ["horizon", "model_horizon"])
def test_bench_config_refuses_a_horizon_of_a_fraction_of_a_step(key):
    """The benchmark's 5 ms step must divide its horizons (never rounded), naming the field."""
    from pfjax.bench.run import BenchConfig
    from pfjax.errors import InputError

    with pytest.raises(InputError, match=rf"^{key}: must be a whole number of steps dt = 0.005 s"):
        BenchConfig(**{key: 2.0021})


# ------------------------------------------------------------------------- without Numba (optional)

NUMBA_MISSING = "numba not installed: pip install 'pfjax[bench]'"


def test_numba_reference_reports_a_missing_numba(monkeypatch):
    from pfjax.bench import problem as P
    from pfjax.bench import references as R

    monkeypatch.setitem(sys.modules, "numba", None)  # `import numba` raises ImportError
    monkeypatch.delitem(sys.modules, "pfjax.bench.numba_ref", raising=False)
    assert R.NUMBA_MISSING == NUMBA_MISSING and not R.numba_available()
    with pytest.raises(ImportError, match=r"^numba not installed: pip install 'pfjax\[bench\]'$"):
        R.iae_numba(P.random_batch(2, 0), np.float64, 10)


@pytest.mark.slow
def test_quick_bench_without_numba_skips_its_reference_with_a_note(tmp_path):
    """Also the human output (no --json): the report's tables and where the outputs are."""
    out = tmp_path / "bench"
    env = {**os.environ, "PFJAX_CACHE_DIR": str(ROOT / ".pytest_cache" / "xla")}
    no_numba = (
        "import sys; sys.modules['numba'] = None; from pfjax.cli import main; "
        "rc = main(sys.argv[1:]); assert sys.modules['numba'] is None; sys.exit(rc)"
    )
    r = subprocess.run(
        [sys.executable, "-c", no_numba, "bench", "--quick", "--sizes", "64", "--out", str(out)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        env=env,
        timeout=900,
    )
    assert r.returncode == 0, r.stderr[-3000:]
    assert NUMBA_MISSING in r.stderr and "Traceback" not in r.stderr
    report = (out / "report.md").read_text()
    assert (
        r.stdout
        == f"{report.rstrip()}\n\nWritten to {out}: bench.json, bench.parquet, report.md, figures/throughput.png|svg\n"
    )
    assert "| implementation | dtype | batch | M rollout-steps/s | compile s |" in r.stdout
    s = json.loads((out / "bench.json").read_text())["summary"]
    assert s["notes"] == [NUMBA_MISSING]
    # the other references still run and agree; Numba's rates and ratios are null (strict JSON)
    assert (
        set(s["agreement"])
        == {
            "jax_minimal_float32",
            "jax_minimal_float64",
            "numpy_float32",
            "numpy_float64",
            "scipy_float64",
        }
        and s["all_agree"]
    )
    for k in ("numba_msteps_per_s_f32", "numba_msteps_per_s_f64", "ratio_vs_numba_f32", "ratio_vs_numba_f64"):
        assert s[k] is None, k
    assert math.isfinite(s["msteps_per_s_f32"]) and math.isfinite(s["ratio_vs_numpy_f64"])
    assert set(pd.read_parquet(out / "bench.parquet").impl) == {"pfjax", "jax_minimal", "numpy", "scipy"}
    assert f"Note: {NUMBA_MISSING}" in report
    assert "; Numba not run." in report and "nanx" not in report
    from pfjax.bench.report import markdown

    assert markdown(json.loads((out / "bench.json").read_text())) == report  # from bench.json alone
    assert (out / "figures" / "throughput.png").is_file()


@pytest.mark.parametrize("dtype, x64, tol", [(np.float32, False, 1e-5), (np.float64, True, 1e-12)])
def test_minimal_jax_reference_agrees_with_numpy(dtype, x64, tol):
    """The minimal JAX implementation (the benchmark's limit) solves the same runs as the NumPy
    reference: per-run IAE over 1 s of 24 runs, float64 to rounding (measured ~4e-16 m s), float32
    to 1e-5 m s (rounding over 200 steps, measured ~1e-7)."""
    import jax

    from pfjax.bench import minimal as M
    from pfjax.bench import problem as P
    from pfjax.bench import references as R

    batch = P.random_batch(24, 3)
    n = P.n_steps(1.0)
    with jax.enable_x64(x64):
        got, want = M.iae(batch, dtype, n), R.iae_numpy(batch, dtype, n)
    assert got.shape == (24,) and np.all(want > 0)
    np.testing.assert_allclose(got, want, rtol=0, atol=tol)


# ----------------------------------------------------------- studies/bench/compare.py (two revisions)


def _compare_module():
    import importlib.util

    spec = importlib.util.spec_from_file_location("bench_compare", ROOT / "studies" / "bench" / "compare.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_compare_ratios_median_and_spread():
    cmp = _compare_module()
    rounds = [
        {"base": {"msteps_per_s_f32": 100.0, "msteps_per_s_f64": 40.0, "grad_over_forward": 2.0},
         "new": {"msteps_per_s_f32": 110.0, "msteps_per_s_f64": 40.0, "grad_over_forward": 1.0}},
        {"base": {"msteps_per_s_f32": 100.0, "msteps_per_s_f64": 50.0, "grad_over_forward": 2.0},
         "new": {"msteps_per_s_f32": 90.0, "msteps_per_s_f64": 60.0, "grad_over_forward": 3.0}},
        {"base": {"msteps_per_s_f32": 50.0, "msteps_per_s_f64": 50.0, "grad_over_forward": 2.0},
         "new": {"msteps_per_s_f32": 60.0, "msteps_per_s_f64": 50.0, "grad_over_forward": 2.0}},
    ]  # fmt: skip
    c = cmp.compare(rounds)
    assert c["msteps_per_s_f32"]["ratio_new_over_base"] == pytest.approx([1.1, 0.9, 1.2])
    assert c["msteps_per_s_f32"]["ratio"] == pytest.approx({"median": 1.1, "min": 0.9, "max": 1.2})
    assert c["msteps_per_s_f64"]["ratio"] == pytest.approx({"median": 1.0, "min": 1.0, "max": 1.2})
    assert c["grad_over_forward"]["ratio"] == pytest.approx({"median": 1.0, "min": 0.5, "max": 1.5})
    assert "| msteps_per_s_f32 | 100 / 100 / 50 | 110 / 90 / 60 | 1.100 | 0.900-1.200 |" in cmp.markdown(
        {"comparison": c, "base": {"rev": "a", "commit": "0" * 40}, "new": {"rev": ".", "commit": "working tree"},
         "rounds": 3, "bench_args": ["--quick"], "machine": {"cpu_model": "cpu", "cpus": 2}}
    )  # fmt: skip


@pytest.mark.parametrize(
    "args, flag",
    [(["no-such-revision"], "base"), (["HEAD", "no-such-revision"], "new"), (["--rounds", "0"], "--rounds")],
)
def test_compare_bad_input_one_line_exit_2(tmp_path, args, flag):
    out = tmp_path / "cmp"
    r = subprocess.run(
        [sys.executable, str(ROOT / "studies" / "bench" / "compare.py"), *args, "--out", str(out)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert r.returncode == 2 and r.stdout == ""
    assert r.stderr.startswith(f"bench-compare: error: {flag}") and r.stderr.count("\n") == 1
    assert not out.exists()


def _no_worktree(self, commit, parent):
    pytest.fail("work started before the input was checked")


@pytest.mark.parametrize(
    "sizes, message",
    [("x", "--sizes: value 'x'"), ("0", "--sizes: must be >= 1"), ("5000000", "--sizes: a batch of 5000000 runs")],
)
def test_compare_refuses_bad_sizes_as_pfjax_bench_does_before_any_work(tmp_path, monkeypatch, capsys, sizes, message):
    cmp = _compare_module()
    monkeypatch.setattr(cmp._Tree, "__init__", _no_worktree)
    monkeypatch.setenv("PFJAX_MEMORY_BUDGET", str(2**30))  # 5,000,000 runs need far more, on any machine
    out = tmp_path / "cmp"
    assert cmp.main(["HEAD", ".", "--sizes", sizes, "--out", str(out)]) == 2
    err = capsys.readouterr()
    assert err.out == "" and err.err.startswith(f"bench-compare: error: {message}") and err.err.count("\n") == 1
    assert not out.exists()


def _summary(rate: float) -> dict:
    return {"msteps_per_s_f32": rate, "msteps_per_s_f64": rate / 2, "grad_over_forward": 2.0}


def test_compare_passes_sizes_only_where_given_and_keeps_the_rounds_before_a_failure(tmp_path, monkeypatch, capsys):
    """--quick alone: pfjax bench --quick's own sizes; a bench refusing its arguments: one line, exit 2;
    a bench failing in round 2: one line, exit 1, round 1 written and marked incomplete."""
    cmp = _compare_module()
    calls, real = [], subprocess.run

    def child(returncode, stderr="", stdout=""):
        def fake(cmd, **kw):  # pfjax bench's runs answered here, anything else (uname) run
            if "pfjax.cli" not in cmd:
                return real(cmd, **kw)
            calls.append(cmd)
            return subprocess.CompletedProcess(
                cmd, returncode() if callable(returncode) else returncode, stdout, stderr
            )

        return fake

    ok = json.dumps(_summary(100.0))
    monkeypatch.setattr(cmp.subprocess, "run", child(0, stdout=ok))
    assert cmp.main([".", ".", "--quick", "--rounds", "1", "--out", str(tmp_path / "a")]) == 0
    assert calls and all("--sizes" not in c and "--quick" in c for c in calls)
    import pfjax
    from pfjax.bench.report import MACHINE_UNITS
    from pfjax.cli.records import units as records_units

    written = json.loads((tmp_path / "a" / "compare.json").read_text())  # units and provenance, as bench.json's
    assert written["seed"] == 0 and written["pfjax_version"] == pfjax.__version__
    assert written["units"] == {
        **{f"comparison.msteps_per_s_{p}.{k}": "1e6 rollout-steps/s" for p in ("f32", "f64") for k in ("base", "new")},
        **{f"comparison.msteps_per_s_{p}.ratio_new_over_base": "1" for p in ("f32", "f64")},
        **{f"comparison.{k}.ratio.{s}": "1" for k in cmp.RATES + cmp.COSTS for s in ("median", "min", "max")},
        **{f"comparison.grad_over_forward.{k}": "1" for k in ("base", "new", "ratio_new_over_base")},
        **{
            f"bench_summaries.{n}.msteps_per_s_{p}": "1e6 rollout-steps/s"
            for n in ("base", "new")
            for p in ("f32", "f64")
        },
        **{f"bench_summaries.{n}.grad_over_forward": "1" for n in ("base", "new")},
        **records_units({"machine": written["machine"]}, MACHINE_UNITS),
        "rounds": "rounds",
        "rounds_requested": "rounds",
        "seed": "1 (the random seed)",
    }
    assert {"machine.cpus", "machine.load_average_1m"} <= set(written["units"])
    calls.clear()
    assert cmp.main([".", ".", "--rounds", "1", "--out", str(tmp_path / "b")]) == 0
    assert all(c[c.index("--sizes") + 1] == cmp.SIZES for c in calls)
    capsys.readouterr()

    monkeypatch.setattr(cmp.subprocess, "run", child(2, stderr="pfjax bench: error: --quick: unknown flag\n"))
    assert cmp.main([".", ".", "--quick", "--rounds", "1", "--out", str(tmp_path / "c")]) == 2
    err = capsys.readouterr().err
    assert err == "bench-compare: error: --quick: unknown flag (pfjax bench of the working tree)\n"
    assert not (tmp_path / "c").exists()

    codes = iter([0, 0, 1])
    monkeypatch.setattr(cmp.subprocess, "run", child(lambda: next(codes), "Traceback ...\nMemoryError\n", ok))
    out = tmp_path / "d"
    assert cmp.main([".", ".", "--quick", "--rounds", "3", "--out", str(out)]) == 1
    got = capsys.readouterr()
    (line,) = [x for x in got.err.splitlines() if x.startswith("bench-compare: error:")]
    assert "round 2/3" in line and "MemoryError" in line and "1 complete round(s) are written" in line
    written = json.loads((out / "compare.json").read_text())
    assert written["rounds"] == 1 and written["rounds_requested"] == 3 and "round 2/3" in written["incomplete"]
    assert written["comparison"]["msteps_per_s_f32"]["ratio"]["median"] == 1.0
    assert "**Incomplete**: 1 of 3 rounds" in (out / "report.md").read_text()


# ------------------------------------------------------------------ studies/bench/memory.py (peak memory)


def _memory_module():
    import importlib.util

    spec = importlib.util.spec_from_file_location("bench_memory", ROOT / "studies" / "bench" / "memory.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.mark.parametrize(
    "args, message",
    [
        (["--horizon", "nan"], "--horizon: expected a finite number"),
        (["--horizon", "0.0123"], "--horizon: must be a whole number of steps dt = 0.005 s"),
        (["--horizon", "1e9"], "--horizon: horizon / dt"),
        (["--runs", "5"], "--runs: must be >= 9"),
        (["--runs", "100000000000"], "--runs: 100000000000 runs give n_runs = 11111111111"),
        (["--chunk", "0"], "--chunk: must be >= 1"),
    ],
)
def test_memory_refuses_each_bad_flag_by_name_before_the_study(tmp_path, monkeypatch, capsys, args, message):
    mem = _memory_module()
    monkeypatch.setattr(mem.subprocess, "Popen", lambda *a, **kw: pytest.fail("the study started"))
    monkeypatch.chdir(tmp_path)  # the study is found from any directory
    out = tmp_path / "mem"
    assert mem.main([*args, "--out", str(out)]) == 2
    err = capsys.readouterr()
    assert err.out == "" and err.err.startswith(f"memory.py: error: {message}") and err.err.count("\n") == 1
    assert not out.exists()


def test_memory_ctrl_c_stops_the_study_and_waits_for_it(tmp_path, monkeypatch, capsys):
    """Ctrl-C: one SIGINT to the study, which is waited for (its clean-up done) before the output is
    removed; its offer to resume is not passed on (this script starts afresh)."""
    import time

    mem = _memory_module()
    ready, done = tmp_path / "ready", tmp_path / "done"
    child = (
        "import pathlib, signal, sys, time\n"
        "def stop(*_):\n"
        "    sys.stderr.write('\\npfjax study: interrupted; re-run the same command to resume\\n')\n"
        "    sys.stderr.flush(); time.sleep(0.3)\n"
        f"    pathlib.Path({str(done)!r}).write_text('cleaned up'); sys.exit(130)\n"
        "signal.signal(signal.SIGINT, stop)\n"
        "sys.stderr.write('study running\\n'); sys.stderr.flush()\n"
        f"pathlib.Path({str(ready)!r}).touch()\n"
        "time.sleep(60)\n"
    )
    monkeypatch.setattr(mem, "study_command", lambda sets, study_out: [sys.executable, "-c", child])

    def ctrl_c(pid):
        for _ in range(200):
            if ready.exists():
                raise KeyboardInterrupt
            time.sleep(0.05)
        pytest.fail("the child did not start")

    monkeypatch.setattr(mem, "rss_mib", ctrl_c)
    out = tmp_path / "mem"
    assert mem.main(["--runs", "9", "--horizon", "0.05", "--out", str(out)]) == 130
    err = capsys.readouterr().err
    assert done.read_text() == "cleaned up"  # waited for
    assert "study running" in err and "resume" not in err and "memory.py: interrupted; nothing was written" in err
    assert not out.exists() or not any(out.iterdir())
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []  # no staging left


def _result(**summary):
    """A benchmark result with pfjax and minimal-implementation rows at 10^4 and 10^5 runs."""
    rows = [
        {"impl": impl, "dtype": f"float{bits}", "batch": b, "msteps_per_s": rate}
        for impl, bits, b, rate in (
            ("pfjax", 32, 10_000, 140.0),
            ("pfjax", 32, 100_000, 150.0),
            ("pfjax", 64, 10_000, 60.0),
            ("pfjax", 64, 100_000, 69.9),
            ("jax_minimal", 32, 100_000, 170.0),
            ("numba", 32, 10_000, 12.5),  # the reference runs once, at its own batch (Numba float64 skipped)
        )
    ]
    base = dict(
        batch=100_000,
        fraction_of_minimal_by_batch=[
            {"batch": 10_000, "f32": 0.9, "f64": 0.849},
            {"batch": 100_000, "f32": 0.95, "f64": 0.86},
        ],
        ratio_vs_numba_f32=12.0,
        ratio_vs_numba_f64=float("nan"),  # Numba skipped
        grad_mode="forward",
        grad_over_forward=2.0,
        grad_over_forward_reverse=3.01,
    )
    return {"rows": rows, "summary": {**base, **summary}, "config": {"horizon": 20.0, "grad_size": 2000}}


def test_goals_read_each_number_where_it_is_stated_and_a_target_reached_is_met():
    from pfjax.bench.goals import check

    got = {g["goal"]: (g["value"], g["met"]) for g in check(_result())}
    assert got == {
        "throughput_f32": (150.0, True),  # exactly the target: met
        "throughput_f64": (69.9, False),
        "fraction_of_minimal_f32_10000": (0.9, True),
        "fraction_of_minimal_f32_100000": (0.95, True),
        "fraction_of_minimal_f64_10000": (0.849, False),
        "fraction_of_minimal_f64_100000": (0.86, True),
        "numba_f32": (12.0, True),  # pfjax at 10^5 (150) over Numba (12.5)
        "numba_f64": (None, None),  # no Numba row: not measured, neither met nor missed
        "gradient_forward_mode": (2.0, True),  # at most the target: met
        "gradient_reverse_mode": (3.01, False),
    }
    # a larger batch added to the run (as on a GPU) leaves every goal read at its own batch
    bigger = _result(batch=1_000_000)
    bigger["rows"].append({"impl": "pfjax", "dtype": "float32", "batch": 1_000_000, "msteps_per_s": 900.0})
    assert {g["goal"]: (g["value"], g["met"]) for g in check(bigger)} == got


def test_goals_not_measured_when_the_run_lacks_their_batch_horizon_or_mode():
    from pfjax.bench.goals import check

    result = _result(
        batch=1024, fraction_of_minimal_by_batch=[{"batch": 1024, "f32": 0.99, "f64": 0.99}], grad_mode="reverse"
    )
    result["rows"] = [r for r in result["rows"] if r["batch"] == 10_000]
    got = {g["goal"]: (g["value"], g["met"]) for g in check(result)}
    assert all(got[n] == (None, None) for n in got if n != "gradient_reverse_mode"), got
    assert got["gradient_reverse_mode"] == (3.01, False)
    # the gradient at another batch, or any number at another horizon: not the goals' measurement
    measured = lambda config: {g["goal"] for g in check({**_result(), "config": config}) if g["value"] is not None}
    assert measured({"horizon": 20.0, "grad_size": 256}) == {
        "throughput_f32",
        "throughput_f64",
        "fraction_of_minimal_f32_10000",
        "fraction_of_minimal_f32_100000",
        "fraction_of_minimal_f64_10000",
        "fraction_of_minimal_f64_100000",
        "numba_f32",
    }
    assert measured({"horizon": 2.0, "grad_size": 2000}) == set()


def test_a_compile_time_is_never_negative():
    """The first call's excess over the best repeat: 0 when the first was not the slowest."""
    from pfjax.bench.run import compile_time

    assert compile_time(2.5, 0.5) == 2.0 and compile_time(0.4, 0.5) == 0.0


class _Clock:
    """A virtual clock for :mod:`pfjax.bench.timing`: calls advance it instead of sleeping."""

    def __init__(self):
        self.now = 0.0
        self.debt = 0.0  # what the last call left behind, paid by the next one

    def perf_counter(self):
        return self.now

    def call(self, work: float, release: float):
        """A compiled call that runs ``work`` seconds and leaves ``release`` seconds behind (XLA
        frees its buffers after the result is ready)."""

        def f():
            self.now += self.debt + work
            self.debt = release
            return work

        return f


def test_interleaved_timing_charges_each_function_its_own_release_and_not_the_previous_one(monkeypatch):
    from pfjax.bench import timing

    clock = _Clock()
    monkeypatch.setattr(timing, "time", types.SimpleNamespace(perf_counter=clock.perf_counter))
    forward, reverse = clock.call(1.0, 0.0), clock.call(3.0, 0.5)
    outs, firsts, bests = timing.interleaved([forward, reverse], rounds=3)
    # the steady state of a loop over each alone: forward 1.0 s, reverse 3.0 + its 0.5 s release
    assert bests == [1.0, 3.5]
    assert outs == [1.0, 3.0] and firsts == [1.0, 3.0]
    # a window of one call holds the function's own release too: the untimed call absorbs the other's
    clock.debt = 0.0
    _, _, one_each = timing.interleaved([forward, reverse], rounds=3, window=1)
    assert one_each == [1.0, 3.5]
    for bad in ({"rounds": -1}, {"window": 0}):
        with pytest.raises(ValueError):
            timing.interleaved([forward], **{"rounds": 1, **bad})
    _, _, alone = timing.best_of(reverse, 2)
    assert alone == 3.5  # consecutive calls of one function: each pays the previous one's release
    # in turn without the untimed calls: each call pays what the one before it left (the other's)
    clock.debt = 0.0
    calls = clock.now
    _, firsts, in_turn = timing.interleaved([forward, reverse], rounds=3, window=1, settle=False)
    assert firsts == [1.0, 3.0] and in_turn == [1.5, 3.0]
    assert clock.now - calls == 4 * (1.0 + 3.0) + 3 * 0.5  # four calls each: no untimed ones


def test_calls_in_turn_share_a_slow_period_of_the_machine(monkeypatch):
    """pfjax and the minimal implementation are timed in turn: a slow period of the machine (here
    calls 4-7 take twice as long) falls on both, and the best of each comes from the same fast
    round, so the ratio stays that of the calls. Timed one after the other, the same period falls
    on every timed call of the second and none of the first's, and the ratio is off by 2x."""
    from pfjax.bench import timing

    now, count = [0.0], [0]

    def call(work):
        def f():
            now[0] += work * (2.0 if 4 <= count[0] <= 7 else 1.0)
            count[0] += 1
            return work

        return f

    monkeypatch.setattr(timing, "time", types.SimpleNamespace(perf_counter=lambda: now[0]))
    _, _, bests = timing.interleaved([call(3.0), call(4.0)], rounds=3, window=1, settle=False)
    assert bests == [3.0, 4.0]  # calls: p m (the first, untimed) | p m | p m (slow) | p m
    count[0] = 0
    best_p, best_m = timing.best_of(call(3.0), 3)[2], timing.best_of(call(4.0), 3)[2]  # p p p p | m m m m (slow)
    assert (best_p, best_m) == (3.0, 8.0)
