"""A reference that disagrees with pfjax on the per-run IAE (``pfjax bench``): the measurement is
written, but no fraction or ratio against that reference is reported, the goals read against it are
not measured, one line on stderr names it and the exit code is 1; ``studies/bench/compare.py``
stops on a round whose benchmark disagrees. Also: every number of ``bench.json`` has a unit, the
settings' label says where each setting came from, and compare alternates the revisions' order.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from dataclasses import asdict, replace
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
ERROR = "pfjax bench: error: references disagree with pfjax on the per-run IAE: "


def numbers_without_units(out: dict) -> list[str]:
    """Dotted keys of the numbers of a pfjax JSON output (booleans aside; a list by its key, a list
    of records by its fields) that its ``units`` map, keyed as :func:`pfjax.cli.records.units`
    writes it, does not name."""
    missing = set()

    def walk(value, key: str) -> None:
        if isinstance(value, dict):
            for k, v in value.items():
                walk(v, f"{key}.{k}" if key else str(k))
        elif isinstance(value, list):
            for v in value:
                walk(v, key)
        elif isinstance(value, (int, float)) and not isinstance(value, bool) and key not in out["units"]:
            missing.add(key)

    walk({k: v for k, v in out.items() if k != "units"}, "")
    return sorted(missing)


# ------------------------------------------------------------------------ the benchmark, end to end

# pfjax bench --quick with the NumPy reference's IAE 1e-2 m s off in float32 and the minimal JAX
# implementation's NaN in float64 (a fault in either, injected in the process); Numba left out (its
# compilation is not what is tested)
INJECT = """
import sys
sys.modules["numba"] = None
import numpy as np
from pfjax.bench import minimal as M, references as R
numpy_iae, minimal = R.iae_numpy, M.simulate
R.iae_numpy = lambda b, dtype, n: numpy_iae(b, dtype, n) + (1e-2 if dtype is np.float32 else 0.0)
M.simulate = lambda runs, n: (lambda out: out * np.nan if out.dtype == np.float64 else out)(minimal(runs, n))
from pfjax.cli import main
sys.exit(main(sys.argv[1:]))
"""


@pytest.mark.slow
def test_a_reference_that_disagrees_is_written_flagged_and_exits_1(tmp_path):
    out = tmp_path / "bench"
    env = {**os.environ, "PFJAX_CACHE_DIR": str(ROOT / ".pytest_cache" / "xla")}
    r = subprocess.run(
        [sys.executable, "-c", INJECT, "bench", "--quick", "--sizes", "64", "--out", str(out), "--json"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        env=env,
        timeout=900,
    )
    assert r.returncode == 1, r.stderr[-3000:]
    assert "Traceback" not in r.stderr
    (line,) = [x for x in r.stderr.splitlines() if x.startswith("pfjax bench: error:")]
    assert line == (
        f"{ERROR}jax_minimal_float64 (max |IAE difference| NaN m s, tolerance 1e-10 m s); numpy_float32 "
        f"(max |IAE difference| 1.0e-02 m s, tolerance 1e-04 m s); their fractions and ratios are not reported; "
        f"the outputs are in {out}"
    )
    s = json.loads(r.stdout)  # the summary, printed as ever
    full = json.loads((out / "bench.json").read_text())
    assert full["summary"]["disagreeing"] == s["disagreeing"] == ["jax_minimal_float64", "numpy_float32"]
    assert s["all_agree"] is False and s["agreement"]["numpy_float64"]["ok"] is True
    # the fraction and ratio against a disagreeing reference: null; the others reported
    assert s["fraction_of_minimal_f64"] is None and s["ratio_vs_numpy_f32"] is None
    assert s["fraction_of_minimal_by_batch"][0]["f64"] is None and s["fraction_of_minimal_by_batch"][0]["f32"] > 0
    assert s["fraction_of_minimal_f32"] > 0 and s["ratio_vs_numpy_f64"] > 0 and s["ratio_vs_scipy_f64"] > 0
    assert s["minimal_msteps_per_s_f64"] > 0 and s["numpy_msteps_per_s_f32"] > 0  # their rates: measured
    goals = {g["goal"]: g for g in s["goals"]}
    for batch in (10_000, 100_000):
        g = goals[f"fraction_of_minimal_f64_{batch}"]
        assert g["value"] is None and g["not_measured"] == "reference jax_minimal_float64 disagrees"
        assert goals[f"fraction_of_minimal_f32_{batch}"]["not_measured"] == "2 s horizon, the goals' is 20 s"
    report = (out / "report.md").read_text()
    assert "**Disagreement**: these references disagree with pfjax on the per-run IAE: jax_minimal_float64" in report
    assert "not reported where it disagrees with pfjax (jax_minimal_float64): at B = 64 runs" in report
    assert "% (float32) and – (float64)" in report and "pfjax at B = 64 runs at" not in report
    assert report.count("| not measured (reference jax_minimal_float64 disagrees) | – |") == 2
    assert "| numpy_float32 | 1.00e-02 | 1e-04 | False |" in report
    assert "| jax_minimal_float64 | not finite | 1e-10 | False |" in report
    from pfjax.bench.report import markdown

    assert markdown(full) == report  # from bench.json alone
    assert numbers_without_units(full) == []


# ------------------------------------------------------------------ the same, with the run stubbed


def _rows() -> list[dict]:
    from pfjax.bench.run import _row

    n = 4000
    rates = [
        ("pfjax", "float32", 10_000, 150.0),
        ("pfjax", "float32", 100_000, 160.0),
        ("pfjax", "float64", 10_000, 70.0),
        ("pfjax", "float64", 100_000, 75.0),
        ("jax_minimal", "float32", 10_000, 160.0),
        ("jax_minimal", "float32", 100_000, 170.0),
        ("jax_minimal", "float64", 10_000, 75.0),
        ("jax_minimal", "float64", 100_000, 80.0),
        ("numba", "float32", 10_000, 12.0),
        ("numba", "float64", 10_000, 9.0),
        ("numpy", "float32", 10_000, 25.0),
        ("numpy", "float64", 10_000, 5.0),
        ("scipy", "float64", 3, 0.01),
    ]
    return [
        _row(impl, dtype, b, b * n / rate / 1e6, 1.0, n, 0 if impl == "pfjax" else None)
        for impl, dtype, b, rate in rates
    ]


def _result(bad: dict) -> dict:
    """A benchmark result as :func:`pfjax.bench.run.run` assembles it, from stubbed measurements:
    the agreement entries of ``bad`` (name: max |IAE difference|, m s) beyond their tolerance."""
    from pfjax.bench import goals, run

    tolerance = {"float32": 1e-4, "float64": 1e-10, "scipy": 1e-8}
    names = [f"{impl}_{d}" for impl in ("jax_minimal", "numba", "numpy") for d in ("float32", "float64")]
    agreement = {}
    for name in [*names, "scipy_float64"]:
        tol = tolerance["scipy" if name.startswith("scipy") else name.rsplit("_", 1)[1]]
        diff = bad.get(name, tol / 100)
        agreement[name] = dict(max_abs_diff=diff, tolerance=tol, ok=diff <= tol)
    g = dict(forward_s=0.03, grad_s=0.05, grad_compile_s=1.0, grad_block=336, grad_blocks=3, grad=[0.1, -0.1])
    g.update(mode="forward", reverse_s=0.1, reverse_compile_s=2.0, reverse_segment=64, grad_reverse=[0.1, -0.1])
    g.update(modes_max_rel_diff=1e-7, grad_finite=True)
    cfg = asdict(replace(run.BenchConfig(), sizes=(10_000, 100_000)))
    machine = dict(run.machine(), load_average_1m_start=1.0)
    result = dict(
        summary=run._summary(_rows(), 100_000, g, agreement, [], {}),
        rows=_rows(),
        machine=machine,
        config=cfg,
        n_steps=4000,
        problem=dict(path="sine", controller="K", dt=0.005, newton_iters=3, slip_deg="U(-10, 10)"),
    )
    result["summary"]["goals"] = goals.check(result)
    return result


def _bench(monkeypatch, tmp_path, capsys, bad: dict):
    from matplotlib.figure import Figure

    from pfjax.bench import report, run
    from pfjax.cli import main

    monkeypatch.setattr(run, "run", lambda cfg, progress=None: _result(bad))
    monkeypatch.setattr(report, "throughput_figure", lambda rows, machine: Figure())
    out = tmp_path / "bench"
    code = main(["bench", "--sizes", "10000,100000", "--out", str(out), "--json"])  # returned, not raised
    got = capsys.readouterr()
    return code, got, out


def test_every_reference_agreeing_reports_every_fraction_and_exits_0(monkeypatch, tmp_path, capsys):
    code, got, out = _bench(monkeypatch, tmp_path, capsys, {})
    assert code == 0 and got.err == ""
    s = json.loads(got.out)
    assert s["all_agree"] is True and s["disagreeing"] == []
    assert s["fraction_of_minimal_f32"] == pytest.approx(160 / 170)
    report = (out / "report.md").read_text()
    assert "pfjax at B = 100000 runs at 94 % (float32) and 94 % (float64)" in report and "Disagreement" not in report
    assert "; 13.3x / 8.33x Numba." in report
    assert {g["goal"]: g["met"] for g in s["goals"]}["numba_f32"] is True
    full = json.loads((out / "bench.json").read_text())
    assert numbers_without_units(full) == []


def test_a_disagreeing_reference_is_flagged_nulled_and_exits_1(monkeypatch, tmp_path, capsys):
    """The minimal implementation off in float32, Numba NaN in float64: their fraction and ratio
    null, the goals read against them not measured, the report naming them, one line on stderr."""
    code, got, out = _bench(monkeypatch, tmp_path, capsys, {"jax_minimal_float32": 0.5, "numba_float64": math.nan})
    assert code == 1
    assert got.err.splitlines() == [
        f"{ERROR}jax_minimal_float32 (max |IAE difference| 5.0e-01 m s, tolerance 1e-04 m s); numba_float64 "
        f"(max |IAE difference| NaN m s, tolerance 1e-10 m s); their fractions and ratios are not reported; "
        f"the outputs are in {out}"
    ]
    s = json.loads(got.out)
    full = json.loads((out / "bench.json").read_text())
    assert full["summary"] == {
        k: v for k, v in s.items() if k not in ("out", "machine", "config_sha256", "seed", "pfjax_version", "units")
    }
    assert s["all_agree"] is False and s["disagreeing"] == ["jax_minimal_float32", "numba_float64"]
    assert s["fraction_of_minimal_f32"] is None and s["fraction_of_minimal_f64"] == pytest.approx(75 / 80)
    assert [f["f32"] for f in s["fraction_of_minimal_by_batch"]] == [None, None]
    assert s["ratio_vs_numba_f64"] is None and s["ratio_vs_numba_f32"] == pytest.approx(160 / 12)
    assert s["minimal_msteps_per_s_f32"] == pytest.approx(170.0)  # the reference's own rate: measured
    goals = {g["goal"]: (g["value"], g["met"], g["not_measured"]) for g in s["goals"]}
    for batch in (10_000, 100_000):
        assert goals[f"fraction_of_minimal_f32_{batch}"] == (None, None, "reference jax_minimal_float32 disagrees")
        assert goals[f"fraction_of_minimal_f64_{batch}"][1] is True
    assert goals["numba_f64"] == (None, None, "reference numba_float64 disagrees")
    assert goals["numba_f32"][:2] == (pytest.approx(160 / 12), True)
    report = (out / "report.md").read_text()
    assert (
        "**Disagreement**: these references disagree with pfjax on the per-run IAE: jax_minimal_float32 "
        "(max |IAE difference| 5.0e-01 m s, tolerance 1e-04 m s); numba_float64 (max |IAE difference| NaN m s, "
        "tolerance 1e-10 m s)." in report
    )
    assert "pfjax at B" not in report and "at B = 100000 runs – (float32) and 94 % (float64)" in report
    assert "; at B = 10000: – / 93 %" in report
    assert "; 13.3x / – Numba (numba_float64 disagrees with pfjax: not reported)." in report
    assert report.count("| not measured (reference jax_minimal_float32 disagrees) | – |") == 2
    assert "| not measured (reference numba_float64 disagrees) | – |" in report
    assert "against a reference that agrees with pfjax" in report
    assert numbers_without_units(full) == []


def test_goals_against_a_disagreeing_reference_are_not_measured():
    from pfjax.bench.goals import GOALS, check

    result = _result({"numpy_float32": 1.0})  # NumPy reads no goal
    assert all(g["not_measured"] is None for g in check(result))
    assert {g.reference for g in GOALS} == {
        None,
        "jax_minimal_float32",
        "jax_minimal_float64",
        "numba_float32",
        "numba_float64",
    }
    for name in ("jax_minimal_float64", "numba_float32"):
        got = {g["goal"]: g["not_measured"] for g in check(_result({name: 1.0}))}
        assert {k for k, v in got.items() if v} == {g.name for g in GOALS if g.reference == name}


def test_the_bench_help_states_the_exit_codes_and_what_quick_runs(capsys):
    from pfjax.cli import main

    with pytest.raises(SystemExit):
        main(["bench", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "Exit codes: 0, every reference agrees with pfjax on the per-run IAE; 1, a reference disagrees" in text
    assert "batches of 256 and 1,024 runs of 2 s (400 steps)" in text and "minute" not in text


# ------------------------------------------------------------------------------ the settings' label


def test_the_settings_label_says_where_the_vector_width_came_from(monkeypatch):
    from pfjax.numerics import calibration
    from pfjax.numerics.compiler import settings_source

    for calibrated, base in ((True, "calibrated"), (False, "rules")):
        monkeypatch.setattr(calibration, "vector_width", lambda c=calibrated: (c, 256 if c else None))
        monkeypatch.setattr(calibration, "sincos_sharing", lambda name, c=calibrated: "real" if c else None)
        assert settings_source({}) == base
        assert settings_source({"PFJAX_VECTOR_WIDTH": "0"}) == f"{base}; vector width from PFJAX_VECTOR_WIDTH"
        assert settings_source({"PFJAX_VECTOR_WIDTH": " 512 "}) == f"{base}; vector width from PFJAX_VECTOR_WIDTH"
        assert settings_source({"PFJAX_VECTOR_WIDTH": "wide"}) == base  # ignored (with a warning) by the compiler
        assert (
            settings_source({"PFJAX_SINCOS_SHARING": "Real"})
            == f"{base}; sine-cosine sharing from PFJAX_SINCOS_SHARING"
        )
        assert settings_source({"PFJAX_SINCOS_SHARING": "fast"}) == base  # ignored (with a warning) when traced


def test_the_settings_label_says_when_an_older_calibration_leaves_the_sharing_to_the_rule(monkeypatch):
    """A calibration written before the sharing was measured has no ``sincos_sharing``: the label
    says the sharing comes from the rules (unless PFJAX_SINCOS_SHARING sets it)."""
    from pfjax.numerics import calibration
    from pfjax.numerics.compiler import settings_source

    monkeypatch.setattr(calibration, "vector_width", lambda: (True, 512))
    monkeypatch.setattr(calibration, "sincos_sharing", lambda name: None)
    assert settings_source({}) == "calibrated; sine-cosine sharing from the rules"
    assert (
        settings_source({"PFJAX_SINCOS_SHARING": "none"}) == "calibrated; sine-cosine sharing from PFJAX_SINCOS_SHARING"
    )
    monkeypatch.setattr(calibration, "sincos_sharing", lambda name: "real")
    assert settings_source({}) == "calibrated"
    monkeypatch.setattr(calibration, "vector_width", lambda: (False, None))
    monkeypatch.setattr(calibration, "sincos_sharing", lambda name: None)
    assert settings_source({}) == "rules"


# --------------------------------------------------------------------------- studies/bench/compare.py


def _compare_module():
    import importlib.util

    spec = importlib.util.spec_from_file_location("bench_compare", ROOT / "studies" / "bench" / "compare.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _summary(rate: float, agree: bool = True) -> dict:
    ok = {"max_abs_diff": 1e-6, "tolerance": 1e-4, "ok": True}
    bad = {"max_abs_diff": 1e-2, "tolerance": 1e-4, "ok": False}
    return {
        "msteps_per_s_f32": rate,
        "msteps_per_s_f64": rate / 2,
        "grad_over_forward": 2.0,
        "agreement": {"jax_minimal_float32": ok, "numpy_float32": ok if agree else bad},
    }


def _children(cmp, monkeypatch, answer):
    """pfjax bench's runs answered by ``answer(name, i)`` -> (exit code, summary); the runs' names
    (``base``/``new``) and rounds in the order they ran."""
    ran, real = [], subprocess.run

    def fake(cmd, **kw):
        if "pfjax.cli" not in cmd:
            return real(cmd, **kw)
        name, i = Path(cmd[cmd.index("--out") + 1]).name.split("-")[1:]
        ran.append((name, int(i)))
        code, summary = answer(name, int(i))
        return subprocess.CompletedProcess(cmd, code, json.dumps(summary), "")

    monkeypatch.setattr(cmp.subprocess, "run", fake)
    return ran


def test_compare_alternates_which_revision_runs_first_and_records_it(tmp_path, monkeypatch, capsys):
    cmp = _compare_module()
    ran = _children(cmp, monkeypatch, lambda name, i: (0, _summary(100.0 if name == "base" else 110.0)))
    out = tmp_path / "cmp"
    assert cmp.main([".", ".", "--quick", "--rounds", "3", "--out", str(out)]) == 0
    capsys.readouterr()
    assert ran == [("base", 0), ("new", 0), ("new", 1), ("base", 1), ("base", 2), ("new", 2)]
    written = json.loads((out / "compare.json").read_text())
    assert written["order"] == [["base", "new"], ["new", "base"], ["base", "new"]]
    assert all(list(r) == ["base", "new"] for r in written["bench_summaries"])
    assert written["comparison"]["msteps_per_s_f32"]["ratio"]["median"] == pytest.approx(1.1)
    assert "BASE first in odd rounds and NEW first in even ones" in (out / "report.md").read_text()
    assert numbers_without_units(written) == []


@pytest.mark.parametrize("code", [0, 1])  # a revision's pfjax bench may exit 0 on a disagreement
def test_compare_stops_on_a_round_whose_benchmark_disagrees(tmp_path, monkeypatch, capsys, code):
    cmp = _compare_module()
    bad = lambda name, i: name == "new" and i == 1
    _children(cmp, monkeypatch, lambda name, i: (code if bad(name, i) else 0, _summary(100.0, agree=not bad(name, i))))
    out = tmp_path / "cmp"
    assert cmp.main([".", ".", "--quick", "--rounds", "3", "--out", str(out)]) == 1
    (line,) = [x for x in capsys.readouterr().err.splitlines() if x.startswith("bench-compare: error:")]
    assert line.startswith(
        "bench-compare: error: round 2/3: pfjax bench of the working tree: references disagree with pfjax: "
        "numpy_float32 (max |IAE difference| 1.0e-02 m s, tolerance 1e-04 m s); the 1 complete round(s) are written"
    )
    written = json.loads((out / "compare.json").read_text())
    assert written["rounds"] == 1 and written["order"] == [["base", "new"]] and "round 2/3" in written["incomplete"]


def test_compare_writes_nothing_when_the_first_round_disagrees(tmp_path, monkeypatch, capsys):
    cmp = _compare_module()
    _children(cmp, monkeypatch, lambda name, i: (1, _summary(100.0, agree=False)))
    out = tmp_path / "cmp"
    assert cmp.main([".", ".", "--quick", "--rounds", "2", "--out", str(out)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [
        "bench-compare: error: round 1/2: pfjax bench of the working tree: references disagree with pfjax: "
        "numpy_float32 (max |IAE difference| 1.0e-02 m s, tolerance 1e-04 m s); nothing was measured or written"
    ]
    assert not out.exists() or not any(out.iterdir())


def test_the_report_names_the_devices_kind_and_the_gpu_blocks():
    """The report's machine line names the devices' kind (a GPU's card) and, on a GPU, its blocks."""
    from pfjax.bench.report import markdown

    result = _result({})
    assert result["machine"]["gpu_block_bytes"] is None and result["machine"]["device_kinds"] == ["cpu"]
    text = markdown(result)
    assert " device(s) (cpu); " in text and "GPU blocks" not in text
    result["machine"].update(devices=["CudaDevice(id=0)"], device_kinds=["NVIDIA H200"], gpu_block_bytes=1_000_000)
    text = markdown(result)
    assert "with 1 device(s) (NVIDIA H200); " in text and "; GPU blocks of 1000000 bytes per array." in text
