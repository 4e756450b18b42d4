"""Monte Carlo studies: config validation, sampling, determinism, summary contract, CLI."""

import copy
import json
import math
import subprocess
import sys

import jax
import numpy as np
import pandas as pd
import pytest

import pfjax
from pfjax.config import ConfigError
from pfjax.metrics.robustness import clopper_pearson
from pfjax.montecarlo.config import load_study, study_hash
from pfjax.montecarlo.runner import run_study
from pfjax.montecarlo.sampling import ou_sequence, sample_runs
from pfjax.montecarlo.study import run
from pfjax.paths import project

BASE = {
    "name": "t",
    "n_runs": 24,
    "seed": 3,
    "chunk_size": 24,
    "sim": {"horizon": 3.0, "steady_window": 1.0},
    "success": {"from_s": 2.0, "band": 0.2},
    "slip": {
        "beta_r_deg": {"dist": "uniform", "low": -5, "high": 5},
        "beta_f_deg": {"dist": "truncnormal", "mean": 0, "std": 2, "low": -6, "high": 6},
    },
    "initial": {
        "lateral_offset": {"dist": "uniform", "low": -0.3, "high": 0.3},
        "heading_error_deg": {"dist": "uniform", "low": -20, "high": 20},
        "start_along_m": {"dist": "uniform", "low": 0, "high": 1},
    },
    "margin": {"amplitudes_deg": [0.0, 10.0], "n_per_amplitude": 6},
    "paths": [{"kind": "line"}, {"kind": "circle", "radius": {"dist": "uniform", "low": 2, "high": 3}}],
    "controllers": [{"name": "lmi", "type": "lmi"}, {"name": "stanley", "type": "stanley", "gains": {"k": 2.0}}],
}


def spec_of(*overrides, data=None):
    return load_study(data=copy.deepcopy(BASE if data is None else data), overrides=list(overrides))[0]


BAD = [
    ("n_runz=3", "n_runz: unknown key (did you mean 'n_runs'?)"),
    ("n_runs=0", "n_runs:"),
    ("n_runs='many'", "n_runs:"),
    ("seed=-1", "seed:"),
    ("dtype='float16'", "dtype:"),
    ("sim.dt=0", "sim.dt:"),
    ("sim.dt=5", "sim.dt: must be <= horizon"),
    ("sim.horizon=nan", "sim.horizon:"),
    ("sim.steady_window=9", "sim.steady_window: must be <= horizon"),
    ("success.from_s=9", "success.from_s: must be <= sim.horizon"),
    ("success.band=0", "success.band:"),
    ("vehicle.speed=-1", "vehicle.speed: must be > 0"),
    ("vehicle.L={dist='normal', mean=0.2, std=0.01}", "vehicle.L: must be > 0 over its whole range"),
    ("vehicle.delta_max_deg=90", "vehicle.delta_max_deg: must lie in (0, 90)"),
    ("vehicle.convention='other'", "vehicle.convention:"),
    ("slip.kind='random'", "slip.kind:"),
    ("slip.beta_r_deg=95", "slip.beta_r_deg: slip magnitudes must stay below 90"),
    ("slip.beta_r_deg={dist='uniform', low=5, high=1}", "slip.beta_r_deg: needs low < high"),
    ("slip.beta_r_deg={dist='uniform', low=5}", "slip.beta_r_deg: dist 'uniform' needs 'high'"),
    ("slip.beta_r_deg={dist='uniform', low=1, high=2, mean=0}", "slip.beta_r_deg: dist 'uniform' does not use 'mean'"),
    ("slip.beta_r_deg={dist='unifrm', low=1, high=2}", "slip.beta_r_deg.dist:"),
    ("slip.beta_f_deg={dist='truncnormal', mean=0, std=0, low=-1, high=1}", "slip.beta_f_deg: needs std > 0"),
    ("slip.beta_f_deg={dist='normal', mean=0, std=1}", "slip.beta_f_deg: slip magnitudes must stay below 90 deg"),
    ("slip.beta_f_deg={dist='choice', values=[]}", "slip.beta_f_deg: 'values' must be a non-empty list"),
    ("slip.ou_tau_s=0", "slip.ou_tau_s: must be > 0"),
    ("noise.sigma_d=-1", "noise.sigma_d:"),
    ("paths[0].kind='spiral'", "paths[0].kind:"),
    ("paths[1].radus=3", "paths[1].radus: unknown key (did you mean 'paths[1].radius'?)"),
    ("controllers[0].type='mpc'", "controllers[0].type:"),
    ("controllers[1].gainz={}", "controllers[1].gainz: unknown key (did you mean 'controllers[1].gains'?)"),
    ("controllers[1].name='lmi'", "controllers: names must be unique"),
    ("controllers[5].K=[1,2]", "controllers[5]: no such list element"),
    ("margin.amplitudes_deg=[5, 5]", "margin.amplitudes_deg: must be distinct"),
    ("margin.eps=1.5", "margin.eps:"),
    ("margin.axes=['up']", "margin.axes[0]:"),
    ("chunk_size=0", "chunk_size:"),
]


@pytest.mark.parametrize("override,expected", BAD)
def test_bad_config_names_the_key(override, expected):
    with pytest.raises(ConfigError) as e:
        spec_of(override)
    msg = str(e.value)
    assert msg.startswith(expected.split(":")[0] + ":") or msg.startswith(expected.split(".")[0]), msg
    assert expected in msg, msg
    assert "\n" not in msg


def test_bad_controller_gain_name_is_refused_as_the_config_loads(tmp_path):
    with pytest.raises(ConfigError, match=r"^controllers\[1\]\.gains\.kk: unknown gain for controller 'stanley'"):
        spec_of("controllers[1].gains={kk=2.0}")
    assert list(tmp_path.iterdir()) == []


def test_sampled_distributions():
    """2000 runs: uniform within its bounds with the right mean, normal mean/std (5 sigma of the
    estimator), truncnormal within bounds, choice only from its values."""
    spec = spec_of(
        "initial.lateral_offset={dist='normal', mean=1.0, std=2.0}",
        "vehicle.L={dist='truncnormal', mean=0.2, std=0.05, low=0.18, high=0.25}",
        "initial.start_along_m={dist='choice', values=[0.0, 0.5]}",
    )
    s = sample_runs(spec, 0, np.arange(2000))
    c = s.columns
    n = 2000
    assert c["beta_r_deg"].min() >= -5 and c["beta_r_deg"].max() <= 5
    assert abs(c["beta_r_deg"].mean()) < 5 * (10 / math.sqrt(12)) / math.sqrt(n)
    assert abs(c["lateral_offset"].mean() - 1.0) < 5 * 2 / math.sqrt(n)
    assert abs(c["lateral_offset"].std() / 2.0 - 1) < 5 / math.sqrt(2 * n)
    assert c["L"].min() >= 0.18 and c["L"].max() <= 0.25
    assert set(np.unique(c["start_along_m"])) <= {0.0, 0.5} and len(np.unique(c["start_along_m"])) == 2


def test_studies_differing_only_in_their_distributions_numbers_share_one_sampler():
    """The sampler's program is keyed by the distributions' kinds, not their numbers, nor the rest
    of the study (name, controllers): a second study with other ranges, normal parameters, choice
    values and circle radii compiles nothing, and its draws follow its own numbers (the same
    uniform, normal and index draws per run, mapped to its ranges). A change of kind compiles anew."""
    from pfjax.montecarlo import sampling as S

    a = spec_of(
        "initial.lateral_offset={dist='normal', mean=0.0, std=1.0}", "vehicle.L={dist='choice', values=[0.2, 0.3]}"
    )
    b = spec_of(
        "name='other'",
        "controllers=[{name='pi', type='pi'}]",
        "slip.beta_r_deg={dist='uniform', low=-1.0, high=3.0}",
        "slip.beta_f_deg={dist='truncnormal', mean=0.0, std=4.0, low=-12.0, high=12.0}",
        "initial.lateral_offset={dist='normal', mean=0.5, std=2.0}",
        "vehicle.L={dist='choice', values=[0.4, 0.6]}",
        "paths=[{kind='line'}, {kind='circle', radius={dist='uniform', low=4.0, high=5.0}}]",
    )
    runs = np.arange(64)
    for p in range(2):
        ca = sample_runs(a, p, runs).columns
        compiled = S._draw_runs._cache_size()
        cb = sample_runs(b, p, runs).columns
        assert S._draw_runs._cache_size() == compiled
        u = lambda c, lo, hi: (c - lo) / (hi - lo)
        rtol = dict(rtol=0, atol=1e-12)  # float64 rounding of the affine maps
        np.testing.assert_allclose(u(ca["beta_r_deg"], -5, 5), u(cb["beta_r_deg"], -1, 3), **rtol)
        np.testing.assert_allclose(ca["beta_f_deg"] / 2, cb["beta_f_deg"] / 4, **rtol)  # same bounds in std units
        np.testing.assert_allclose(ca["lateral_offset"], (cb["lateral_offset"] - 0.5) / 2, **rtol)
        np.testing.assert_array_equal(ca["L"] == 0.2, cb["L"] == 0.4)
        np.testing.assert_array_equal(np.unique(cb["L"]), [0.4, 0.6])
        if p == 1:
            np.testing.assert_allclose(u(ca["radius"], 2, 3), u(cb["radius"], 4, 5), **rtol)
    c = spec_of("slip.beta_r_deg={dist='choice', values=[1.0, -2.0]}")
    sample_runs(c, 0, runs)
    assert S._draw_runs._cache_size() == compiled + 1


def test_start_pose_has_the_sampled_offset_heading_error_and_arc_position():
    """Projecting the sampled start pose back onto the path returns d = lateral_offset,
    theta_e = heading_error and s = start_along_m (the line's and circle's nominal start has s = 0)."""
    spec = spec_of()
    for p in range(2):
        s = sample_runs(spec, p, np.arange(16))
        sc = s.scenarios
        proj = jax.vmap(lambda path, x, y, th: project(path, x, y, th))(sc.path, sc.pose0.x, sc.pose0.y, sc.pose0.theta)
        np.testing.assert_allclose(proj.d, s.columns["lateral_offset"], atol=1e-9)
        np.testing.assert_allclose(np.degrees(proj.theta_e), s.columns["heading_error_deg"], atol=1e-7)
        np.testing.assert_allclose(proj.s, s.columns["start_along_m"], atol=1e-8)


def test_ou_process_statistics():
    """Exact OU discretisation: stationary std sigma and lag-1 autocorrelation exp(-dt/tau)
    (20 000 samples; tolerances 5 standard errors, with the samples' correlation time counted)."""
    sigma, tau, dt, n = 0.1, 0.5, 0.05, 20000
    x = np.asarray(ou_sequence(jax.random.PRNGKey(0), n, dt, sigma, tau))
    a = math.exp(-dt / tau)
    n_eff = n * (1 - a) / (1 + a)
    assert abs(x.std() / sigma - 1) < 5 / math.sqrt(2 * n_eff)
    r1 = np.corrcoef(x[:-1], x[1:])[0, 1]
    assert abs(r1 - a) < 5 * (1 - a * a) / math.sqrt(n)


def test_runs_are_independent_of_chunk_size_and_shared_by_controllers(tmp_path):
    """Same config and seed: identical runs.parquet; chunk sizes 24 and 7: identical sampled
    parameters and statuses, metrics equal to float32 rounding (XLA may vectorise a padded batch
    differently); every controller sees the same sampled runs (common random numbers)."""
    a = spec_of("margin.enabled=false")
    run_study(a, tmp_path / "a", progress=False)
    run_study(a, tmp_path / "a2", progress=False)
    run_study(spec_of("margin.enabled=false", "chunk_size=7"), tmp_path / "b", progress=False)
    ra, ra2, rb = (pd.read_parquet(tmp_path / d / "runs.parquet") for d in ("a", "a2", "b"))
    pd.testing.assert_frame_equal(ra, ra2)
    params = ["beta_r_deg", "beta_f_deg", "lateral_offset", "heading_error_deg", "start_along_m", "radius"]
    pd.testing.assert_frame_equal(
        ra[params + ["status", "run", "path", "controller"]], rb[params + ["status", "run", "path", "controller"]]
    )
    np.testing.assert_allclose(ra["iae"], rb["iae"], rtol=1e-5, atol=1e-7)
    g = ra.groupby("controller")
    np.testing.assert_array_equal(g.get_group("lmi")[params].to_numpy(), g.get_group("stanley")[params].to_numpy())
    assert len(ra) == 24 * 2 * 2


@pytest.mark.parametrize("dtype", ["float32", "float64"])
def test_run_table_inputs_are_in_the_precision_they_ran_in(tmp_path, dtype):
    """runs.parquet holds every sampled input in the study's precision, as the simulator got it: a
    float32 study's 1.3 m/s is float32's 1.3, not that number widened to 1.2999999523...; a column a
    path lacks (the line's radius) is NaN in the same type. pfjax.scenarios' table likewise."""
    spec = spec_of("margin.enabled=false", f"dtype='{dtype}'", "n_runs=8", "chunk_size=8", "vehicle.speed=1.3")
    run_study(spec, tmp_path / "s", progress=False)
    runs = pd.read_parquet(tmp_path / "s" / "runs.parquet")
    inputs = ["speed", "L", "beta_r_deg", "beta_f_deg", "lateral_offset", "heading_error_deg", "radius"]
    assert {c: runs[c].dtype for c in inputs} == {c: np.dtype(dtype) for c in inputs}
    assert (runs.speed == np.asarray(1.3, dtype)).all() and runs.speed.astype(str).eq("1.3").all()
    assert runs[runs.path == "line"].radius.isna().all() and runs[runs.path != "line"].radius.between(2, 3).all()
    with jax.enable_x64(dtype == "float64"):
        t = pfjax.scenarios("sine", 4, speed=1.3, lateral_offset=pfjax.uniform(-0.1, 0.1)).table
    assert (t.drop(columns="run").dtypes == np.dtype(dtype)).all() and t.speed.astype(str).eq("1.3").all()


def test_summary_contract_and_numbers(tmp_path):
    spec = spec_of()
    summary = run(spec, tmp_path / "s", progress=False, report=False)
    on_disk = json.loads((tmp_path / "s" / "summary.json").read_text())
    assert on_disk["config_sha256"] == study_hash(spec) == summary["config_sha256"]
    assert on_disk["study"] == "t" and on_disk["seed"] == 3 and on_disk["n_runs_total"] == 96
    t = on_disk["timings_s"]  # wall clock per phase, and the side jobs' compute time
    side = t.pop("side_jobs")
    assert list(t) == ["runs", "margin", "worst_case", "float64_check", "summary"] and min(t.values()) >= 0
    assert side["overlapped"] is True and side["worst_case"] == 0 and side["float64_check"] > 0  # no falsifier here
    runs = pd.read_parquet(tmp_path / "s" / "runs.parquet")
    sweep = pd.read_parquet(tmp_path / "s" / "margin.parquet")
    assert len(sweep) == 2 * 6 * 3 * 2 * 2  # amplitudes x runs x axes x paths x controllers
    for name, c in on_disk["controllers"].items():
        df = runs[runs.controller == name]
        k, n = int(df.success.sum()), len(df)
        assert c["success_rate"] == pytest.approx(k / n)
        assert c["success_ci95"] == pytest.approx(list(clopper_pearson(k, n)))
        assert c["iae_mean"] == pytest.approx(float(df.iae.mean()), rel=1e-6)
        assert c["iae_p95"] == pytest.approx(float(np.quantile(df.iae, 0.95)), rel=1e-6)
        assert set(c["slip_margin"]) == {"rear", "front", "joint"}
        joint = c["slip_margin"]["joint"]
        if joint["fails_at_smallest"]:  # no margin: null, and the amplitude where it already fails
            assert c["slip_margin_deg"] is None and c["slip_margin_fails_at_deg"] == joint["table"][0]["amplitude"]
        else:
            assert c["slip_margin_deg"] == joint["margin"] and c["slip_margin_fails_at_deg"] is None
        # every sampled parameter ranked (and the magnitude of the four signed ones): 10 rows, not 6
        ranked = [d["parameter"] for d in c["failure_drivers"]]
        signed = ["beta_r_deg", "beta_f_deg", "lateral_offset", "heading_error_deg"]
        assert sorted(ranked) == sorted([*signed, *(f"abs_{p}" for p in signed), "start_along_m", "radius"])
    # the sweep's slip is exactly the amplitude on the swept axis
    rear = sweep[sweep.axis == "rear"]
    assert set(rear.amplitude_deg) == {0.0, 10.0}


def test_state_feedback_and_pi_run_as_one_controller():
    """A study's state-feedback (LMI) and PI controllers are both ``pfjax.controllers.linear`` with
    gains of one pytree structure, so they share every compiled simulator program; the summary
    keeps each controller's own gain names."""
    from pfjax import controllers as C
    from pfjax.montecarlo.runner import controllers_of

    data = copy.deepcopy(BASE)
    data["controllers"] = [
        {"name": "lmi", "type": "lmi"},
        {"name": "pi", "type": "pi"},
        {"name": "stanley", "type": "stanley", "gains": {"k": 2.0}},
    ]
    ctrls = controllers_of(spec_of(data=data))
    assert ctrls["lmi"][0] is C.linear and ctrls["pi"][0] is C.linear and ctrls["stanley"][0] is C.stanley
    assert jax.tree_util.tree_structure(ctrls["lmi"][1]) == jax.tree_util.tree_structure(ctrls["pi"][1])
    assert set(ctrls["lmi"][2]) == {"k_d", "k_theta"} and set(ctrls["pi"][2]) == {
        "kp_d",
        "ki_d",
        "kp_theta",
        "ki_theta",
        "k_aw",
    }
    assert np.asarray(ctrls["pi"][1].K).tolist() == pytest.approx([-C.PAPER_PI["kp_d"], -C.PAPER_PI["kp_theta"]])


def test_sampler_scratch_memory_is_bounded_for_large_chunks():
    """The jitted sampler computes start poses in blocks (``SAMPLE_BLOCK`` runs; each start pose
    integrates arc length on 512 nodes per Newton step), so its scratch memory does not grow with
    the chunk: XLA's memory analysis of the program for a 65,536-run chunk in float64 says 78 MiB
    (all runs at once: 2.3 GiB, which took a 10^7-run study over its 2 GiB budget)."""
    import jax.numpy as jnp

    from pfjax.montecarlo import sampling as S

    spec, n = spec_of(), 65536
    keys = S.run_keys(spec.seed, 0, np.arange(n))
    z = jnp.zeros(n)
    design, numbers, _ = S._design(spec, spec.paths[0])
    compiled = S._draw_runs.lower(
        keys,
        {},
        S._fixed_path(spec.paths[0]),
        jnp.asarray(0.0),
        (z, z),
        False,
        jax.tree_util.tree_map(jnp.asarray, numbers),
        design=S._Static(design),
        circle=None,
        batched_path=False,
    ).compile()
    assert compiled.memory_analysis().temp_size_in_bytes < 256 * 2**20


@pytest.mark.parametrize("dtype", ["float32", "float64"])
def test_a_shared_start_arc_length_is_solved_once_to_the_per_run_start_poses(dtype):
    """With one fixed path and a constant ``start_along_m`` the sampler solves the start point's
    arc-length Newton once for all runs; the start poses and parameters are those of the per-run
    solve (forced here by giving the same constant run by run): to the bit at the nominal start,
    within 4 ulp 0.7 m along it."""
    from pfjax.montecarlo.chunk_runs import precision
    from pfjax.montecarlo.sampling import sample_runs

    for kind in ("line", "parabola", "sine"):
        for along in (0.0, 0.7):
            spec = spec_of(f"dtype='{dtype}'", f"initial.start_along_m={along}", f"paths=[{{kind='{kind}'}}]")
            runs = np.arange(64)
            with precision(spec):
                once = sample_runs(spec, 0, runs).scenarios
                per_run = sample_runs(spec, 0, runs, given={"start_along_m": np.full(64, along)}).scenarios
            got = [np.asarray(a) for a in (*once.pose0, once.u0)]
            want = [np.asarray(a) for a in (*per_run.pose0, per_run.u0)]
            assert got[0].dtype == np.dtype(dtype)
            for g, w in zip(got, want):
                if along == 0.0:
                    np.testing.assert_array_equal(g, w)
                else:
                    np.testing.assert_allclose(g, w, rtol=4 * np.finfo(dtype).eps, atol=4 * np.finfo(dtype).eps)


def test_a_shared_start_arc_length_is_integrated_once_not_per_run():
    """XLA's cost analysis of the sampler for 256 runs on the sine path: with a constant
    ``start_along_m`` the arc-length quadrature (512 nodes per Newton step) is not in the runs'
    work, so the program has far fewer floating-point operations than with the arc length given
    run by run (measured 0.36 M against 61 M)."""
    import jax.numpy as jnp

    from pfjax.montecarlo import sampling as S

    spec, n = spec_of("initial.start_along_m=0.5", "paths=[{kind='sine'}]"), 256
    keys, z = S.run_keys(spec.seed, 0, np.arange(n)), jnp.zeros(n)
    design, numbers, _ = S._design(spec, spec.paths[0])

    def flops(given):
        args = (keys, given, S._fixed_path(spec.paths[0]), jnp.asarray(0.0), (z, z), False)
        static = dict(design=S._Static(design), circle=None, batched_path=False)
        compiled = S._draw_runs.lower(*args, jax.tree_util.tree_map(jnp.asarray, numbers), **static).compile()
        analysis = compiled.cost_analysis()
        return (analysis if isinstance(analysis, dict) else analysis[0])["flops"]

    assert flops({}) * 20 < flops({"start_along_m": jnp.full(n, 0.5)})


def test_side_jobs_alongside_the_runs_change_nothing(tmp_path):
    """The worst-case search and the float64 check run in a background thread alongside the runs
    (on one device) or after them in the main thread: the same summary, runs and sweep."""
    spec = spec_of("falsifier.enabled=true", "falsifier.n_restarts=2", "falsifier.steps=2", "n_runs=8", "chunk_size=8")
    both = [run(spec, tmp_path / str(o), progress=False, report=False, overlap=o) for o in (True, False)]
    for s in both:
        side = s.pop("timings_s").pop("side_jobs")
        assert side["worst_case"] > 0 and side["float64_check"] > 0
        s.pop("wall_s")
    assert json.dumps(both[0], sort_keys=True) == json.dumps(both[1], sort_keys=True)
    for f in ("runs.parquet", "margin.parquet"):
        pd.testing.assert_frame_equal(pd.read_parquet(tmp_path / "True" / f), pd.read_parquet(tmp_path / "False" / f))


def test_main_thread_takes_over_side_jobs_not_started():
    """A side job the background thread has not started when its result is asked for is computed
    by the asking thread (once: asking again returns it); one it has started is waited for."""
    import threading
    from concurrent.futures import ThreadPoolExecutor

    from pfjax.background import Stealable

    pool, gate, ran = ThreadPoolExecutor(1), threading.Event(), []

    def job(name):
        def fn():
            if name == "first":
                gate.wait(10)
            ran.append((name, threading.current_thread() is threading.main_thread()))
            return name

        return Stealable(pool.submit(fn), fn)

    first, second, third = job("first"), job("second"), job("third")
    third.take_over()  # the background thread is busy with the first: the main thread computes the third
    assert ran == [("third", True)]
    third.take_over()  # already computed: not again
    assert third.result() == "third" and ran == [("third", True)]
    gate.set()
    assert first.result() == "first" and second.result() == "second"
    assert ("first", False) in ran and len(ran) == 3
    pool.shutdown()


def test_few_runs_are_sampled_by_the_chunk_program_exactly():
    """The float64 check and the worst-case search sample a few runs through the program of the
    study's chunks (padded, then cut to an aligned batch): the same scenarios as a batch of their own."""
    from pfjax.montecarlo.runner import batch_size, sample_aligned, sample_few

    spec = spec_of("n_runs=200", "chunk_size=100")  # chunks padded to 128 runs, the few to 32
    idx = np.array([3, 170, 5])
    few, own = sample_few(spec, 0, idx), sample_aligned(spec, 0, idx)
    leaves = jax.tree_util.tree_leaves(few.scenarios)
    assert all(np.shape(x)[0] == batch_size(len(idx)) for x in leaves)
    for a, b in zip(leaves, jax.tree_util.tree_leaves(own.scenarios)):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    assert few.columns.keys() == own.columns.keys()
    for k in few.columns:
        np.testing.assert_array_equal(few.columns[k], own.columns[k])


def test_cli_study_and_bad_input(tmp_path, capsys):
    """``pfjax study`` as a process: its JSON on stdout and its outputs. Bad input through the same
    entry point (:func:`pfjax.cli.main`, whose return value is the process's exit code): exit code 2,
    one line on stderr naming the key or flag, nothing on stdout, nothing written."""
    from pfjax.cli import main

    cfg = tmp_path / "s.toml"
    cfg.write_text(
        'name = "cli"\nn_runs = 4\nseed = 1\nchunk_size = 4\n[sim]\nhorizon = 2.0\nsteady_window = 1.0\n'
        '[success]\nfrom_s = 1.0\n[margin]\nenabled = false\n[[paths]]\nkind = "line"\n'
        '[[controllers]]\nname = "st"\ntype = "stanley"\n'
    )
    exe = [sys.executable, "-m", "pfjax.cli"]
    out = tmp_path / "o"
    r = subprocess.run(
        exe + ["study", str(cfg), "--out", str(out), "--no-report", "--quiet", "--json"], capture_output=True, text=True
    )
    assert r.returncode == 0, r.stderr
    head = json.loads(r.stdout)
    assert head["n_runs_total"] == 4 and "st" in head["controllers"]
    assert head["units"]["iae_mean"].startswith("m s") and head["units"]["slip_margin_deg"] == "deg"
    assert (out / "runs.parquet").is_file() and (out / "summary.json").is_file()
    units = json.loads((out / "summary.json").read_text())["units"]
    assert units["gains"] == {"st": {"k": "1/s", "k_soft": "m/s"}}  # each controller's gains' units
    capsys.readouterr()
    for args, flag in (
        (["--set", "n_runs=0"], "n_runs"),
        (["--set", "sim.dtt=0.1"], "sim.dtt"),
        (["--set", "nokey"], "--set"),
    ):
        o2 = tmp_path / "bad"
        code = main(["study", str(cfg), "--out", str(o2), "--quiet"] + args)
        std = capsys.readouterr()
        assert code == 2 and std.out == "" and len(std.err.strip().splitlines()) == 1 and flag in std.err, std.err
        assert not o2.exists()
    assert main(["study", str(tmp_path / "missing.toml")]) == 2 and "not found" in capsys.readouterr().err
    assert main(["report", str(cfg), "--out", str(out), "--set", "seed=2"]) == 2
    assert "config hash differs" in capsys.readouterr().err
    # the report of the finished study, with the config hash it matched
    assert main(["report", str(cfg), "--out", str(out), "--json"]) == 0
    again = json.loads(capsys.readouterr().out)
    assert again["config_sha256"] == head["config_sha256"] and again["report"] == str(out / "report.html")
    # built from the study's files only, with no clock in it (the marker records when pfjax wrote
    # it): a second rebuild gives the same bytes
    first = (out / "report.md").read_bytes()
    assert main(["report", str(cfg), "--out", str(out), "--json"]) == 0
    capsys.readouterr()
    assert (out / "report.md").read_bytes() == first and "| written |" not in first.decode()
