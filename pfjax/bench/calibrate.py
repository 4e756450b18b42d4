"""Measure this CPU's best block size and vector width (``pfjax calibrate``).

The benchmark problem (:mod:`pfjax.bench.problem`: the slip model on the sine path, state feedback,
metrics on) is simulated with pfjax's own simulator program, compiled for each candidate vector
width (XLA's default, and 512 bits where the CPU has AVX-512) and run over each candidate block
size, in float32 and float64, on every device. The candidates are timed in turn ``rounds`` times
after a compiling call each, each timed call after an untimed one (best time of each;
:func:`pfjax.bench.timing.interleaved`), so a slow period of a shared machine slows them alike. The choice:

* per precision, the block (bytes per batched array) with the highest rate at the chosen width;
* one width for both precisions (XLA's option is per program, pfjax sets one for all): the width
  whose best rates have the largest product over the two precisions.

Only a candidate whose per-run IAE agrees with the first candidate's (XLA's default width, the
first block) within :data:`TOLERANCE` is chosen: the settings change the results only by rounding,
so a larger difference (or one that is not finite) is a fault of that program, not a faster setting.
The tolerance is the benchmark's for pfjax against its references (:data:`pfjax.bench.run.TOLERANCE`:
float32 1e-4 m s, rounding amplified over 4,000 steps, measured ~3e-6; float64 1e-10 m s, measured
~5e-15), which also bounds the shorter runs calibrated here. Each row records ``agrees``; when no
candidate of a width agrees in both precisions that width is not chosen, and when none agrees at
all nothing is chosen (``failed`` says why, and ``pfjax calibrate`` keeps nothing).

:func:`calibrate` returns every measurement and the choice; :func:`pfjax.numerics.calibration.save`
writes it where every later process on this CPU reads it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from pfjax.bench import problem as P
from pfjax.bench import timing
from pfjax.bench.run import TOLERANCE

#: Candidate bytes per batched array in one CPU block (float32 runs = bytes / 4, float64 / 8).
BLOCK_BYTES = (2_500, 5_000, 10_000, 20_000)
_OPTION = "xla_cpu_prefer_vector_width"


def widths() -> tuple[int | None, ...]:
    """Candidate vector widths on this CPU (None: XLA's default)."""
    from pfjax.numerics.cpu import has_avx512

    return (None, 512) if has_avx512() else (None,)


def _program(width: int | None):
    """pfjax's batched slip-model program compiled for ``width``: a new function each call, so nothing
    of the process's own settings leaks in and it is traced under the sharing in force at its first
    call (:func:`pfjax.numerics.elementary.sharing_mode`)."""
    import importlib

    import jax

    inner = importlib.import_module("pfjax.sim.simulate")._simulate_vmapped.__wrapped__

    def fun(*args, **kwargs):  # a new function object: JAX keeps one trace per function, whatever the jit
        return inner(*args, **kwargs)

    options = None if width is None else {_OPTION: width}
    return jax.jit(fun, static_argnames=("controller", "config", "layout"), compiler_options=options)


def _rates(dtype, batch: int, horizon: float, cands, rounds: int, say, ref=None) -> list[dict]:
    """Measured rows of the candidates ``cands``, ``(width, block bytes, sharing)`` each, for
    ``dtype``; ``max_abs_iae_diff`` against ``ref`` (per-run IAE), else the first candidate's."""
    import jax

    from pfjax.controllers import state_feedback
    from pfjax.numerics import elementary
    from pfjax.sim import SimConfig, sharding

    sc = P.scenarios(P.random_batch(batch, 0), dtype)
    sim = SimConfig(dt=P.DT, horizon=horizon, newton_iters=P.NEWTON_ITERS, record=False)
    n_steps = P.n_steps(horizon)
    itemsize = np.dtype(dtype).itemsize
    measured: list[dict] = []
    programs: dict = {}
    for width, bb, sharing in cands:
        if (width, sharing) not in programs:
            programs[(width, sharing)] = _program(width)
        program = programs[(width, sharing)]
        placed, n, layout = sharding.plan_batch(sc, None, max(1, bb // itemsize))
        call = lambda p=placed, lay=layout, f=program, n=n: jax.block_until_ready(
            f(p, controller=state_feedback, config=sim, layout=lay).metrics.iae
        )[:n]  # the padding cut off
        say(f"{np.dtype(dtype).name} width {width or 'default'} block {bb} B sine-cosine {sharing}: compiling")
        with elementary.sharing_mode(sharing):  # traced (and compiled) here, at the first call
            iae = np.asarray(call(), np.float64)
        measured.append(dict(width=width, block_bytes=bb, sharing=sharing, call=call, iae=iae))
    _, _, bests = timing.interleaved([c["call"] for c in measured], rounds, window=1)
    ref = measured[0]["iae"] if ref is None else ref
    rows = [
        dict(
            dtype=np.dtype(dtype).name,
            vector_width=c["width"],
            block_bytes=c["block_bytes"],
            sincos_sharing=c["sharing"],
            seconds=best,
            msteps_per_s=batch * n_steps / best / 1e6,
            max_abs_iae_diff=float(np.max(np.abs(c["iae"] - ref))),
            iae=c["iae"],
        )
        for c, best in zip(measured, bests)
    ]
    return [dict(r, agrees=agrees(r)) for r in rows]


def agrees(row: dict) -> bool:
    """Whether a measured candidate's per-run IAE agrees with the first candidate's: its
    ``max_abs_iae_diff`` (m s) within :data:`TOLERANCE` of its precision (False where not finite)."""
    return row["max_abs_iae_diff"] <= TOLERANCE[row["dtype"]]


#: The units of a calibration's numbers, by field name ("1": dimensionless).
UNITS = {
    "vector_width": "bits (null: XLA's default)",
    "block_bytes": "B (per batched array in one CPU block)",
    "msteps_per_s": "million rollout-steps (runs x RK4 steps) per second",
    "seconds": "s (the best of the rounds)",
    "max_abs_iae_diff": "m s (largest |IAE difference| from the first candidate's, over the runs)",
    "batch": "runs",
    "horizon_s": "s",
    "rounds": "timed calls per candidate",
    "n_steps": "RK4 steps per run",
    "iae_tolerance": "m s (the largest max_abs_iae_diff of a candidate that may be chosen)",
}
DTYPES = ("float32", "float64")


def choose(rows: Sequence[dict]) -> dict:
    """The width and per-precision blocks from measured ``rows`` (see the module docstring), among
    the candidates that agree with the first (``max_abs_iae_diff`` within :data:`TOLERANCE`); with
    none to choose, ``{"vector_width": None, "block_bytes": None, "msteps_per_s": None, "failed":
    reason}``."""
    best: dict = {}
    for r in rows:
        key = (r["vector_width"], r["dtype"])
        if agrees(r) and (key not in best or r["msteps_per_s"] > best[key]["msteps_per_s"]):
            best[key] = r
    ws = sorted({w for w, _ in best if all((w, d) in best for d in DTYPES)}, key=lambda w: w or 0)
    if not ws:
        reason = "no candidate agrees with the first on the per-run IAE in both precisions (m s): " + ", ".join(
            f"{d} tolerance {TOLERANCE[d]:.0e}" for d in DTYPES
        )
        return dict(vector_width=None, block_bytes=None, msteps_per_s=None, failed=reason)
    score = {w: sum(math.log(best[(w, d)]["msteps_per_s"]) for d in DTYPES) for w in ws}
    width = max(ws, key=lambda w: score[w])
    return dict(
        vector_width=width,
        block_bytes={d: best[(width, d)]["block_bytes"] for d in DTYPES},
        msteps_per_s={d: best[(width, d)]["msteps_per_s"] for d in DTYPES},
    )


#: The sharings of the sine-cosine pair a calibration measures: not ``"none"``, which leaves every
#: kernel to recompute the pair and its tangents, so that a forward-mode gradient costs more (the
#: benchmark's, on an Intel Xeon: 2.49x the forward pass against 1.62x with two reals), while the
#: forward pass it is chosen by gains a percent at most there. ``PFJAX_SINCOS_SHARING=none`` still sets it.
SHARINGS = ("complex", "real")


def choose_sharing(rows: Sequence[dict]) -> dict:
    """Per precision, the sine-cosine sharing of the fastest agreeing row among ``rows`` (the
    second stage's: every sharing at the chosen width and block); a precision with none agreeing is
    left out (the rule decides it)."""
    best: dict = {}
    for r in rows:
        d = r["dtype"]
        if agrees(r) and (d not in best or r["msteps_per_s"] > best[d]["msteps_per_s"]):
            best[d] = r
    return {d: r["sincos_sharing"] for d, r in best.items()}


def calibrate(
    batch: int = 20_000,
    horizon: float = 5.0,
    rounds: int = 3,
    blocks: Sequence[int] = BLOCK_BYTES,
    width_set: Sequence[int | None] | None = None,
    progress=None,
    sharings: Sequence[str] | None = None,
) -> dict:
    """Measure every candidate on this CPU; returns ``{"cpu_key", "version", "pfjax_version",
    "config_sha256", "vector_width", "block_bytes", "sincos_sharing", "msteps_per_s", "rows",
    "machine", "sizes", "iae_tolerance", "units"}`` (the file :func:`pfjax.numerics.calibration.save`
    writes; ``config_sha256`` over what was measured: the sizes, the blocks, the widths and the
    sharings), and ``failed`` where no candidate agrees (:func:`choose`: nothing to keep).

    Two stages: every width and block with the sine-cosine pair shared as the rule says
    (:func:`pfjax.numerics.elementary.sincos_sharing_rule`), which :func:`choose` reads; then, per
    precision at the chosen width and block, every sharing (``sharings``, default
    :data:`SHARINGS`), timed in turn, of which
    :func:`choose_sharing` keeps the fastest that agrees with the first stage's first candidate."""
    import jax

    from pfjax.bench.report import MACHINE_UNITS
    from pfjax.bench.run import machine
    from pfjax.numerics import calibration, elementary

    say = progress or (lambda msg: None)
    ws = tuple(widths() if width_set is None else width_set)
    rule = elementary.sincos_sharing_rule()
    shs = tuple(SHARINGS if sharings is None else sharings)
    x64 = {"float32": False, "float64": True}
    rows, refs = [], {}
    for d in DTYPES:
        with jax.enable_x64(x64[d]):
            stage = _rates(np.dtype(d), batch, horizon, [(w, bb, rule) for w in ws for bb in blocks], rounds, say)
        refs[d] = stage[0]["iae"]
        rows += stage
    chosen = choose(rows)
    second = []
    if "failed" not in chosen:
        for d in DTYPES:
            cands = [(chosen["vector_width"], chosen["block_bytes"][d], sh) for sh in shs]
            with jax.enable_x64(x64[d]):
                second += _rates(np.dtype(d), batch, horizon, cands, rounds, say, ref=refs[d])
        chosen["sincos_sharing"] = {**dict.fromkeys(DTYPES, rule), **choose_sharing(second)}
        for r in second:  # the rates of the settings kept (the first stage measured the rule's sharing)
            if r["sincos_sharing"] == chosen["sincos_sharing"][r["dtype"]] and r["agrees"]:
                chosen["msteps_per_s"][r["dtype"]] = r["msteps_per_s"]
    else:
        chosen["sincos_sharing"] = None
    import pfjax
    from pfjax.provenance import config_hash

    measured = dict(
        batch=batch, horizon_s=horizon, rounds=rounds, blocks=list(blocks), widths=list(ws), sharings=list(shs)
    )
    return dict(
        version=calibration.VERSION,
        cpu_key=calibration.cpu_key(),
        pfjax_version=pfjax.__version__,
        config_sha256=config_hash(measured),
        **chosen,
        rows=[{k: v for k, v in r.items() if k != "iae"} for r in rows],
        sharing_rows=[{k: v for k, v in r.items() if k != "iae"} for r in second],
        sizes=dict(batch=batch, horizon_s=horizon, rounds=rounds, n_steps=P.n_steps(horizon)),
        iae_tolerance={d: TOLERANCE[d] for d in DTYPES},
        machine=machine(),
        units={**UNITS, **MACHINE_UNITS},
    )
