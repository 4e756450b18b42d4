"""Run the benchmark: pfjax's simulator (as users call it, with metrics) against the references,
on the same random batch, in one process.

Measured (all wall-clock, ``time.perf_counter``; "rollout-steps" = runs x RK4 steps):

* pfjax ``simulate_batch`` (``record=False``: the running metrics) in float32 and float64 for each
  batch size: the first call (compile + run) and the best of ``repeats`` further calls; compile
  time = first call - best call;
* beside it at each batch size, the minimal JAX implementation of the same problem
  (:mod:`pfjax.bench.minimal`), timed alike, the two called in turn (pfjax, minimal, pfjax,
  minimal, ...: :func:`pfjax.bench.timing.interleaved` without its untimed calls) so that a slow
  period of the machine slows both, with its agreement with pfjax on the per-run IAE;
  ``summary["fraction_of_minimal_by_batch"]`` gives pfjax's throughput as a fraction of it at every
  size, ``fraction_of_minimal_f32`` / ``_f64`` at the largest;
* the NumPy, Numba (``prange``) and SciPy references (:mod:`pfjax.bench.references`) on the
  largest batch (NumPy and SciPy on a sample, extrapolated per step), with their agreement with
  pfjax on the per-run IAE (max absolute difference, against a stated tolerance); without Numba
  (an optional dependency, the ``bench`` extra) its reference is skipped, its rates and ratios are
  null and the result's ``summary["notes"]`` says so;
* the value and gradient of the batch-mean IAE with respect to the controller gains over the
  forward pass at the same batch size, as the tuner takes it (forward mode for the 2 gains,
  :mod:`pfjax.numerics.autodiff`, in blocks of runs sized for a value and its tangents,
  ``gradient["grad_block"]``) and in reverse mode (``jax.value_and_grad``; its loop checkpointed in
  segments of ``gradient["reverse_segment"]`` samples, :func:`pfjax.sim.loop.checkpoint_segment`): the three timed
  in turn ``grad_rounds`` times, each in a window of consecutive calls that holds the release of
  its own buffers and not the previous one's (:func:`pfjax.bench.timing.interleaved`), best of
  each, so the ratios survive a shared machine's slow periods;
* the cost per rollout-step of the dynamic vehicle models (ST, STD) against the kinematic model in
  the same loop (:mod:`pfjax.bench.models`, ``model_runs`` runs of ``model_horizon`` s, best of
  ``repeats + 1`` rounds timed by :func:`pfjax.bench.timing.interleaved`; ``model_runs = 0`` skips it);
* the process's peak resident memory (``getrusage``);
* pfjax's performance goals against these numbers (:mod:`pfjax.bench.goals`): ``summary["goals"]``.

A reference that disagrees with pfjax on the per-run IAE (beyond :data:`TOLERANCE`, or not finite)
is reported, never used: its agreement entry has ``ok`` false, ``summary["disagreeing"]`` names it,
pfjax's fractions of it or ratios over it are null (its own rates stay: they were measured) and the
goals read against it are not measured (:mod:`pfjax.bench.goals`). ``pfjax bench`` writes the
outputs and exits with code 1 (:mod:`pfjax.cli.bench`).
"""

from __future__ import annotations

import os
import platform
import resource
import time
from dataclasses import asdict, dataclass

import numpy as np

from pfjax.bench import goals, timing
from pfjax.bench import problem as P
from pfjax.models import DYNAMIC_MODELS, MODELS

#: max |IAE_ref - IAE_pfjax| (m s) accepted as agreement, per reference and dtype. float64: the
#: implementations differ only by rounding (measured ~5e-15); float32: rounding amplified over
#: 4000 steps (measured ~3e-6 on IAE ~ 1 m s); SciPy integrates each step to 1e-12 instead of RK4
#: (RK4's error at 5 ms, measured ~2e-13).
TOLERANCE = {"float32": 1e-4, "float64": 1e-10, "scipy": 1e-8}


@dataclass(frozen=True)
class BenchConfig:
    sizes: tuple[int, ...] = (1000, 10000, 100000)  # batch sizes for pfjax
    ref_size: int = 10000  # batch for Numba (NumPy: ref_numpy runs of it)
    ref_numpy: int = 10000
    scipy_runs: int = 3  # runs integrated by solve_ivp (extrapolated per step)
    grad_size: int = 2000
    horizon: float = P.HORIZON  # s
    repeats: int = 2
    grad_rounds: int = 5  # interleaved rounds of forward / gradient / reverse-mode calls (best of each)
    model_runs: int = 2000  # runs per batch of the vehicle-model comparison (0: skipped)
    model_horizon: float = 10.0  # s, of the kinematic and ST runs at the benchmark's step (STD: the same steps)
    models: tuple[str, ...] = MODELS
    seed: int = 0
    quick: bool = False

    def __post_init__(self):
        """Checks the sizes and the seed before any work (:class:`~pfjax.errors.InputError` naming
        the field); the largest batch must fit the memory budget (:mod:`pfjax.resources`)."""
        from pfjax import errors, resources

        if not self.sizes:
            raise errors.InputError("sizes: expected at least one batch size")
        for name, value in (
            ("sizes", max(self.sizes, default=0)),
            ("sizes", min(self.sizes, default=1)),
            ("ref_size", self.ref_size),
            ("ref_numpy", self.ref_numpy),
            ("grad_size", self.grad_size),
            ("scipy_runs", self.scipy_runs),
            ("repeats", self.repeats),
            ("grad_rounds", self.grad_rounds),
            ("model_runs", self.model_runs),
        ):
            low = 0 if name in ("repeats", "grad_rounds", "model_runs") else 1
            errors.integer(name, value, low=low, high=100_000_000)
        errors.number("horizon", self.horizon, positive=True, unit=" s")
        errors.number("model_horizon", self.model_horizon, positive=True, unit=" s")
        from pfjax.bench.models import MODELS

        if not self.models or self.models[0] != "kinematic" or not set(self.models) <= set(MODELS):
            raise errors.InputError(f"models: expected 'kinematic' first, then any of {sorted(MODELS)}")
        errors.seed("seed", self.seed)
        n_steps = resources.check_steps(self.horizon, P.DT)
        resources.whole_steps(self.horizon, P.DT)  # the benchmark's step divides both horizons
        resources.whole_steps(self.model_horizon, P.DT, "model_horizon")
        resources.check_memory(
            "sizes",
            2 * max(self.sizes) * resources.run_bytes(n_steps),
            f"a batch of {max(self.sizes)} runs",
            "give smaller --sizes",
        )


QUICK = BenchConfig(
    sizes=(256, 1024),
    ref_size=1024,
    ref_numpy=256,
    scipy_runs=1,
    grad_size=256,
    horizon=2.0,
    repeats=1,
    grad_rounds=1,
    model_runs=64,
    model_horizon=2.0,
    models=("kinematic", "st"),
    quick=True,
)


def _pfjax(batch, dtype, cfg: BenchConfig):
    """pfjax's simulator on ``batch`` in ``dtype``, as a call that returns its result when ready."""
    import jax

    from pfjax.controllers import state_feedback
    from pfjax.sim import SimConfig, simulate_batch

    sc = P.scenarios(batch, dtype)
    sim = SimConfig(dt=P.DT, horizon=cfg.horizon, newton_iters=P.NEWTON_ITERS, record=False)
    return lambda: jax.block_until_ready(simulate_batch(sc, controller=state_feedback, config=sim))


def _grad(batch, dtype, cfg: BenchConfig):
    """Seconds of the forward pass and of the value and gradient of the batch-mean IAE w.r.t. K
    (all jitted; after a compiling call each, the best of ``grad_rounds`` rounds of
    :func:`pfjax.bench.timing.interleaved`), on the same
    sharded batch: by :func:`pfjax.numerics.autodiff.value_and_grad` (``mode="auto"``: forward mode
    for K's 2 entries, in blocks of runs sized for a value and its 2 tangents,
    :func:`pfjax.sim.sharding.default_block`) and in reverse mode (``jax.value_and_grad``, what a
    loss of many parameters gets, unblocked as the forward pass)."""
    import jax
    import jax.numpy as jnp

    from pfjax.controllers import state_feedback
    from pfjax.numerics import autodiff, compiler
    from pfjax.sim import SimConfig, loop, sharding, simulate_batch
    from pfjax.sim.simulate import system

    sc, n = sharding.shard_batch(P.scenarios(batch, dtype))
    sim = SimConfig(dt=P.DT, horizon=cfg.horizon, newton_iters=P.NEWTON_ITERS, record=False)

    def loss(K, sc, block="auto"):
        gains = sc.gains._replace(K=jnp.broadcast_to(K, sc.gains.K.shape))
        res = simulate_batch(sc._replace(gains=gains), controller=state_feedback, config=sim, block=block)
        return jnp.mean(res.metrics.iae[:n])  # not the padding's copies of run 0

    K = jnp.asarray(P.K, dtype)
    mode = autodiff.resolve_mode("auto", K.size)
    # forward mode in blocks of runs sized for the value and its tangents (sharding.default_block);
    # the forward pass and reverse mode as a loss is written, unblocked (reverse mode is slower in blocks)
    block = sharding.default_block(sc, tangents=K.size) if mode == "forward" else "auto"
    devices = jax.device_count()
    layout = sharding.traced_layout(sc.gains.K.shape[0], block, devices) if isinstance(block, int) else None
    # reverse mode's checkpoints, as the loop decides them for the unblocked batch (pfjax.sim.loop)
    one_run = jax.tree_util.tree_map(lambda a: jax.ShapeDtypeStruct(a.shape[1:], a.dtype), sc)
    segment = loop.checkpoint_segment(
        sim.n_steps + 1,
        loop.carry_bytes(system(state_feedback, sim), one_run),
        sharding.traced_layout(sc.gains.K.shape[0], None, devices).runs,
    )
    # the simulator's compiler options (pfjax.numerics.compiler): a jit around simulate_batch
    # compiles with its own options, so the three programs take the same ones
    fwd = compiler.jit(loss)
    auto = compiler.jit(autodiff.value_and_grad(lambda K, sc: loss(K, sc, block)))
    rev = compiler.jit(jax.value_and_grad(loss))
    calls = [lambda f=f: jax.block_until_ready(f(K, sc)) for f in (fwd, auto, rev)]
    (_, (_, g), (_, g_rev)), (_, first, first_rev), (t_fwd, t_grad, t_rev) = timing.interleaved(calls, cfg.grad_rounds)
    g, g_rev = np.asarray(g, np.float64), np.asarray(g_rev, np.float64)
    return dict(
        forward_s=t_fwd,
        grad_s=t_grad,
        grad_compile_s=compile_time(first, t_grad),
        # runs per device in each block of the forward-mode gradient, and the blocks
        grad_block=(layout.size if layout.blocks > 1 else layout.runs) if layout else None,
        grad_blocks=layout.blocks if layout else None,
        grad=g.tolist(),
        mode=mode,
        reverse_s=t_rev,
        reverse_compile_s=compile_time(first_rev, t_rev),
        reverse_segment=segment,  # samples per checkpointed segment (0: every sample checkpointed)
        grad_reverse=g_rev.tolist(),
        modes_max_rel_diff=float(np.max(np.abs(g - g_rev)) / np.max(np.abs(g_rev))),
        grad_finite=bool(np.all(np.isfinite(g)) and np.all(np.isfinite(g_rev))),
    )


def machine() -> dict:
    """The machine a benchmark ran on: the CPU (vendor, family, model, vector flags), the CPUs
    this process may use, the 1-minute load average, JAX and its devices, and the CPU settings of
    the simulator programs (compiler options, bytes per batched array in a CPU block, the sharing of
    the sine-cosine pair, and where they came from: :func:`pfjax.numerics.compiler.settings_source`) and,
    on a GPU, the bytes per batched array in a GPU block (:func:`pfjax.sim.sharding.gpu_block_bytes`;
    ``None`` off a GPU and for whole batches); units in :data:`pfjax.bench.report.MACHINE_UNITS`."""
    import jax

    from pfjax.numerics import compiler
    from pfjax.numerics.cpu import VECTOR_FLAGS
    from pfjax.provenance import cpu_settings
    from pfjax.sim import sharding

    cpu = cpu_settings()  # the settings a study records: one home
    info = compiler.cpu_info()
    flags = set(info.get("flags", "").split())
    return dict(
        cpu_model=info.get("model name", ""),
        cpu_vendor=info.get("vendor_id", ""),
        cpu_family=info.get("cpu family", ""),
        cpu_model_number=info.get("model", ""),
        cpu_flags=sorted(flags & VECTOR_FLAGS),
        platform=platform.platform(),
        processor=platform.processor() or platform.machine(),
        cpus=len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count(),
        load_average_1m=os.getloadavg()[0],
        jax=jax.__version__,
        devices=[str(d) for d in jax.devices()],
        device_kinds=sorted({d.device_kind for d in jax.devices()}),
        xla_flags=os.environ.get("XLA_FLAGS", ""),
        avx512=compiler.has_avx512(),
        compiler_options=dict(compiler.OPTIONS),  # the simulator programs' (512-bit vectors on AVX-512)
        block_bytes=cpu["block_bytes"],
        sincos_sharing=cpu["sincos_sharing"],
        settings=cpu["source"],
        gpu_block_bytes=sharding.gpu_block_bytes() if sharding.block_platform() == "gpu" else None,
    )


def compile_time(first: float, best: float) -> float:
    """The compile time of a call, s: its first run's excess over its best repeat, never below 0
    (a first call that was not the slowest, its program from the compilation cache on a busy
    machine, compiled nothing worth measuring)."""
    return max(0.0, first - best)


def _row(impl: str, dtype: str, batch: int, seconds: float, compile_s: float, n_steps: int, failed=None) -> dict:
    """One row of ``bench.json``'s ``rows``: an implementation's best time and its rate."""
    return dict(
        impl=impl,
        dtype=dtype,
        batch=batch,
        seconds=seconds,
        compile_s=compile_s,
        msteps_per_s=batch * n_steps / seconds / 1e6,
        failed_runs=failed,
    )


def _max_diff(a, b) -> float:
    return float(np.max(np.abs(np.asarray(a, np.float64) - np.asarray(b, np.float64))))


def _jax_rows(cfg: BenchConfig, n_steps: int, say) -> tuple[list[dict], dict, dict]:
    """pfjax and the minimal JAX reference at every batch size, in both precisions, each size's two
    in turn: ``(rows, pfjax's per-run IAE by dtype at the largest batch, the largest per-run IAE
    difference of the minimal reference from pfjax over every size)``."""
    import jax

    from pfjax.bench import minimal as M

    rows, iae = [], {}
    diffs: dict[str, list[float]] = {}
    top = max(cfg.sizes)
    for name, dtype, x64 in (("float32", np.float32, False), ("float64", np.float64, True)):
        with jax.enable_x64(x64):
            for b in cfg.sizes:
                batch = P.random_batch(b, cfg.seed)
                say(f"pfjax and minimal JAX {name} B={b}")
                runs = M.runs(batch, dtype)
                minimal = lambda: jax.block_until_ready(M.simulate(runs, n_steps))
                (res, out), firsts, bests = timing.interleaved(
                    [_pfjax(batch, dtype, cfg), minimal], cfg.repeats, window=1, settle=False
                )
                failed = int(np.sum(np.asarray(res.status) != 0))
                rows.append(_row("pfjax", name, b, bests[0], compile_time(firsts[0], bests[0]), n_steps, failed))
                if b == top:
                    iae[name] = np.asarray(res.metrics.iae, np.float64)
                rows.append(_row("jax_minimal", name, b, bests[1], compile_time(firsts[1], bests[1]), n_steps))
                diffs.setdefault(f"jax_minimal_{name}", []).append(_max_diff(out, res.metrics.iae))
    return rows, iae, {k: float(np.max(v)) for k, v in diffs.items()}  # NaN if any difference is NaN


def _reference_rows(cfg: BenchConfig, n_steps: int, iae: dict, have_numba: bool, say) -> tuple[list[dict], dict]:
    """Numba (if installed) and NumPy in both precisions and SciPy in float64, on the largest batch's
    first runs: ``(rows, agreement with pfjax's per-run IAE)``."""
    from pfjax.bench import references as R

    rows, agree = [], {}
    top = max(cfg.sizes)
    batch = P.random_batch(top, cfg.seed)
    nr, k = min(cfg.ref_size, top), min(cfg.ref_numpy, top)
    sub = lambda n: P.Batch(*(a[:n] for a in batch))
    for name, dtype in (("float32", np.float32), ("float64", np.float64)):
        if have_numba:
            say(f"numba {name} B={nr}")
            out, first, best = timing.best_of(lambda: R.iae_numba(sub(nr), dtype, n_steps), cfg.repeats)
            rows.append(_row("numba", name, nr, best, compile_time(first, best), n_steps))
            agree[f"numba_{name}"] = _max_diff(out, iae[name][:nr])
        say(f"numpy {name} B={k}")
        out, _, best = timing.best_of(lambda: R.iae_numpy(sub(k), dtype, n_steps), 0)
        rows.append(_row("numpy", name, k, best, 0.0, n_steps))
        agree[f"numpy_{name}"] = _max_diff(out, iae[name][:k])
    say(f"scipy solve_ivp, {cfg.scipy_runs} run(s)")
    t0 = time.perf_counter()
    sc_iae = np.array([R.iae_scipy(batch, i, n_steps) for i in range(cfg.scipy_runs)])
    rows.append(_row("scipy", "float64", cfg.scipy_runs, time.perf_counter() - t0, 0.0, n_steps))
    agree["scipy_float64"] = _max_diff(sc_iae, iae["float64"][: cfg.scipy_runs])
    return rows, agree


def disagreeing(summary: dict) -> list[str]:
    """The agreement entries (``"<impl>_<dtype>"``, e.g. ``"numpy_float32"``) of a benchmark
    ``summary`` whose reference disagrees with pfjax on the per-run IAE (``ok`` false: beyond the
    tolerance, or not finite), in the summary's order; ``[]`` when every reference agrees."""
    return [name for name, a in (summary.get("agreement") or {}).items() if a.get("ok") is False]


def disagreement(summary: dict) -> str:
    """The references of :func:`disagreeing`, each with its largest IAE difference and tolerance
    (m s), in one line: ``"numpy_float32 (max |IAE difference| 1.0e-02 m s, tolerance 1e-04 m s)"``;
    ``""`` when every reference agrees. A difference that is not finite (null in ``bench.json``)
    reads ``NaN``."""

    def diff(x) -> str:
        return "NaN" if x is None or x != x else f"{x:.1e}"

    agreement = summary.get("agreement") or {}
    return "; ".join(
        f"{name} (max |IAE difference| {diff(agreement[name].get('max_abs_diff'))} m s, "
        f"tolerance {agreement[name]['tolerance']:.0e} m s)"
        for name in disagreeing(summary)
    )


def _summary(rows: list[dict], top: int, g: dict, agreement: dict, notes: list[str], models: dict) -> dict:
    """The headline rates and ratios (pfjax at the largest batch over each reference); a fraction
    or ratio against a reference that disagrees with pfjax (``agreement[...]["ok"]`` false) is None."""
    bad = {name for name, a in agreement.items() if not a["ok"]}

    def over(impl: str, dtype: str, value: float) -> float | None:
        """pfjax's ``value`` (a fraction of, or ratio over, ``impl`` in ``dtype``), None where
        ``impl`` disagrees with pfjax."""
        return None if f"{impl}_{dtype}" in bad else value

    def rate(impl, dtype, batch=None):
        c = [r for r in rows if r["impl"] == impl and r["dtype"] == dtype and (batch is None or r["batch"] == batch)]
        return max(c, key=lambda r: r["batch"])["msteps_per_s"] if c else float("nan")

    def compile_s(dtype):
        return next(r["compile_s"] for r in rows if r["impl"] == "pfjax" and r["dtype"] == dtype and r["batch"] == top)

    head = {"f32": rate("pfjax", "float32", top), "f64": rate("pfjax", "float64", top)}
    out: dict = dict(msteps_per_s_f32=head["f32"], msteps_per_s_f64=head["f64"], batch=top)
    for impl in ("numba", "numpy"):
        for p, dtype in (("f32", "float32"), ("f64", "float64")):
            out[f"{impl}_msteps_per_s_{p}"] = rate(impl, dtype)
    out["scipy_msteps_per_s_f64"] = rate("scipy", "float64")
    for impl in ("numba", "numpy"):
        for p, dtype in (("f32", "float32"), ("f64", "float64")):
            out[f"ratio_vs_{impl}_{p}"] = over(impl, dtype, head[p] / rate(impl, dtype))
    out["ratio_vs_scipy_f64"] = over("scipy", "float64", head["f64"] / rate("scipy", "float64"))
    for p, dtype in (("f32", "float32"), ("f64", "float64")):
        out[f"minimal_msteps_per_s_{p}"] = rate("jax_minimal", dtype)
    for p, dtype in (("f32", "float32"), ("f64", "float64")):
        out[f"fraction_of_minimal_{p}"] = over("jax_minimal", dtype, head[p] / rate("jax_minimal", dtype))
    # the same fraction at every batch size
    out["fraction_of_minimal_by_batch"] = [
        {
            "batch": b,
            **{
                f"f{bits}": over(
                    "jax_minimal",
                    f"float{bits}",
                    rate("pfjax", f"float{bits}", b) / rate("jax_minimal", f"float{bits}", b),
                )
                for bits in (32, 64)
            },
        }
        for b in sorted({r["batch"] for r in rows if r["impl"] == "jax_minimal"})
    ]
    out.update(
        compile_s_f32=compile_s("float32"),
        compile_s_f64=compile_s("float64"),
        grad_over_forward=g["grad_s"] / g["forward_s"],
        grad_mode=g["mode"],
        grad_over_forward_reverse=g["reverse_s"] / g["forward_s"],
        gradient=g,
        **_model_ratios(models),
        models=models,
        peak_rss_mib=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
        agreement=agreement,
        all_agree=not bad,
        disagreeing=[name for name in agreement if name in bad],
        failed_runs=sum(r["failed_runs"] or 0 for r in rows),
        notes=notes,
    )
    return out


def _model_ratios(models: dict) -> dict:
    """``model_cost_ratio_<model>_<f32|f64>``: a dynamic model's cost per rollout-step over the
    kinematic model's (None where it was not run)."""
    out = {}
    for m in DYNAMIC_MODELS:
        for p, dtype in (("f32", "float32"), ("f64", "float64")):
            out[f"model_cost_ratio_{m}_{p}"] = models.get(dtype, {}).get(f"ratio_{m}_over_kinematic")
    return out


def run(cfg: BenchConfig, progress=None) -> dict:
    """Run the benchmark; returns the result dict (``bench.json``'s content)."""
    import jax

    from pfjax.bench import references as R

    say = progress or (lambda msg: None)
    have_numba = R.numba_available()
    notes = [] if have_numba else [R.NUMBA_MISSING]
    if not have_numba:
        say(f"{R.NUMBA_MISSING} (the Numba reference is skipped)")
    n_steps = P.n_steps(cfg.horizon)
    load0 = os.getloadavg()[0]
    rows, iae, agree = _jax_rows(cfg, n_steps, say)
    ref_rows, ref_agree = _reference_rows(cfg, n_steps, iae, have_numba, say)
    say(f"gradient B={cfg.grad_size}")
    with jax.enable_x64(False):
        g = _grad(P.random_batch(cfg.grad_size, cfg.seed), np.float32, cfg)
    models: dict = {}
    if cfg.model_runs:
        from pfjax.bench.models import model_costs

        steps = P.n_steps(cfg.model_horizon)
        models = model_costs(cfg.model_runs, steps, P.DT, cfg.repeats + 1, cfg.models, progress=say)
    agreement = {
        k: dict(max_abs_diff=v, tolerance=TOLERANCE["scipy" if k.startswith("scipy") else k.rsplit("_", 1)[1]])
        for k, v in {**agree, **ref_agree}.items()
    }
    for a in agreement.values():
        a["ok"] = a["max_abs_diff"] <= a["tolerance"]  # False for NaN: a reference that is not finite
    m = machine()
    m["load_average_1m_start"] = load0
    result: dict = dict(
        summary=_summary(rows + ref_rows, max(cfg.sizes), g, agreement, notes, models),
        rows=rows + ref_rows,
        machine=m,
        config=asdict(cfg),
        n_steps=n_steps,
        problem=dict(
            path="sine y = sin x",
            controller=f"state feedback K = {P.K}",
            dt=P.DT,
            newton_iters=P.NEWTON_ITERS,
            slip_deg="U(-10, 10) per axle, constant",
        ),
    )
    result["summary"]["goals"] = goals.check(result)  # pfjax's performance goals on this machine
    return result
