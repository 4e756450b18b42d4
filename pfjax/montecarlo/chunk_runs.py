"""A study's runs, chunk by chunk: the controllers and static settings of a study
(:func:`controller_of`, :func:`sim_config`, :func:`precision`), the sampled scenarios of a chunk padded to
the compiled batch size (:func:`sample_aligned`), its simulation through the jitted simulator with
``record=False`` (:func:`simulate_chunk`: one row per run, every sampled parameter, every metric,
status) and the loop over chunks and controllers (:func:`simulate_runs`) that the study
(:mod:`pfjax.montecarlo.runner`) and the slip-margin sweep (:mod:`pfjax.montecarlo.margin`) share.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pandas as pd

from pfjax import controllers as C
from pfjax.config import ConfigError
from pfjax.errors import InputError
from pfjax.metrics.running import METRIC_NAMES
from pfjax.montecarlo.chunks import ChunkSource, chunk_key
from pfjax.montecarlo.config import ControllerSpec, StudySpec, nominal
from pfjax.montecarlo.sampling import column_names, sample_runs
from pfjax.sim import batch, dynamic, sharding
from pfjax.sim.simulate import SimConfig, simulate_batch
from pfjax.sim.status import STATUS_NAMES


def controller_of(c: ControllerSpec, spec: StudySpec, index: int):
    """``(controller, gains pytree, gains as a flat dict)`` for a controller spec, from the registry
    (:mod:`pfjax.controllers.registry`); a design (:data:`pfjax.controllers.DESIGNS`) is made here
    at the nominal speed and wheelbase (the distributions' values, means or midpoints). The flat
    dict holds the entry's scalar gains (designed, configured or default) and any other given. State feedback and PI come
    as :data:`pfjax.controllers.linear`, so a study of both compiles each simulator program once."""
    e, d = C.resolve(c.type, f"controllers[{index}].type")
    flat = C.flat_gains(e)
    if d is not None:
        v, L = nominal(spec.vehicle.speed), nominal_wheelbase(spec)
        flat.update(C.design_gains(d, v, L, f"controllers[{index}]", alpha=c.alpha, beta=c.beta))
    if c.K is not None:
        flat.update(zip(e.labels["K"], c.K))
    flat.update(c.gains)
    try:
        gains = C.params_from_flat(e, flat)
    except InputError as err:  # names gains.<gain>: the study's key is controllers[i].gains.<gain>
        raise ConfigError(f"controllers[{index}].{err}") from None
    flat = {k: float(v) for k, v in flat.items() if k in e.gains or k in c.gains}
    if e.name in ("state_feedback", "pi"):
        return C.linear, C.linear_params(gains), flat
    return e.controller, gains, flat


def nominal_wheelbase(spec: StudySpec) -> float:
    """The wheelbase the designs are made at, m: the kinematic ``L``'s nominal value, the ST set's ``l_f + l_r``."""
    return nominal(spec.vehicle.L) if spec.vehicle.model == "kinematic" else spec.vehicle.wheelbase_bounds()[0]


def sim_config(spec: StudySpec) -> SimConfig:
    s = spec.sim
    return SimConfig(
        dt=s.dt,
        horizon=s.horizon,
        control_every=s.control_every,
        record=False,
        d_fail=s.d_fail,
        settle_band=s.settle_band,
        steady_window=s.steady_window,
        success_band=spec.success.band,
        success_from=spec.success.from_s,
    )


def precision(spec: StudySpec):
    """Context in which the study runs: float64 enables x64; float32 disables it even if it was on."""
    return jax.enable_x64(spec.dtype == "float64")


#: Batches are padded to a multiple of this many runs. XLA's CPU code runs a vmapped batch through
#: SIMD vector lanes plus a scalar remainder loop, and the two round differently (a run's metrics
#: moved by ~1e-6 in float32, ~3e-15 in float64 with the batch size); with every batch a multiple
#: of the widest vector (16 float32 lanes in AVX-512; 32 for margin), every run takes the vector
#: path and a run's numbers do not depend on the chunk size (tests/test_determinism.py).
BATCH_ALIGN = 32


def batch_size(n: int) -> int:
    """``n`` rounded up to a multiple of :data:`BATCH_ALIGN`."""
    return -(-n // BATCH_ALIGN) * BATCH_ALIGN


def simulate_scenarios(scenarios, *, controller, config: SimConfig, devices=None):
    """A batch of sampled runs through its vehicle model's simulator: :func:`pfjax.sim.simulate_batch`
    for the kinematic model's :class:`~pfjax.sim.Scenario`, :func:`pfjax.sim.dynamic.simulate_batch`
    for the ST model's :class:`~pfjax.sim.dynamic.DynamicScenario`."""
    run = dynamic.simulate_batch if isinstance(scenarios, dynamic.DynamicScenario) else simulate_batch
    return run(scenarios, controller=controller, config=config, devices=devices)


def check_record(scenarios, config: SimConfig, **named) -> None:
    """:func:`pfjax.sim.batch.check_record` for a batch of sampled runs, whichever vehicle model
    simulates it (a recorded ST run holds :data:`pfjax.sim.dynamic.RECORD_COPIES` trajectories);
    ``named``: its ``key``, ``runs`` and ``hint``, so a caller's refusal names its own argument."""
    copies = dynamic.RECORD_COPIES if isinstance(scenarios, dynamic.DynamicScenario) else 1
    batch.check_record(scenarios, config.n_steps, copies=copies, **named)


def with_gains(sc, gains, n):
    """Scenarios ``sc`` (a batch of ``n``) with every run's gains set to ``gains``."""
    return sc._replace(gains=jax.tree_util.tree_map(lambda g: jnp.broadcast_to(g, (n,) + jnp.shape(g)), gains))


def sample_aligned(spec: StudySpec, path_index: int, idx: np.ndarray, *, slip_override=None, pad_to: int | None = None):
    """:func:`sample_runs` on ``idx`` padded (with copies of its first run) to ``max(pad_to, batch_size(len(idx)))``
    runs: the scenarios keep the padded batch, the columns only the ``len(idx)`` real runs. Sampling is
    vmapped too, so it is padded like the simulation (see :data:`BATCH_ALIGN`)."""
    n = len(idx)
    m = max(pad_to or 0, batch_size(n))
    pad = lambda a: np.concatenate([np.asarray(a), np.repeat(np.asarray(a)[:1], m - n)])
    sampled = sample_runs(
        spec, path_index, pad(idx), slip_override=None if slip_override is None else tuple(map(pad, slip_override))
    )
    return sampled._replace(columns={k: v[:n] for k, v in sampled.columns.items()})


def sample_few(spec: StudySpec, path_index: int, idx: np.ndarray):
    """:func:`sample_aligned` for a few runs (the float64 check's, the worst-case search's run 0),
    drawn by the program that samples the study's chunks: padded to the chunk's batch, with JAX's
    default device (a program is compiled per default device, and a study's side jobs pin theirs),
    then cut back to ``batch_size(len(idx))`` runs. The scenarios are exactly those the study's
    chunks draw for these runs; sampling a padded chunk takes about 30 ms, compiling a sampler for
    32 runs took 1.1-1.5 s. Random paths are drawn run by run, so they are not padded."""
    if spec.paths[path_index].kind == "random":
        return sample_aligned(spec, path_index, idx)
    with jax.default_device(None):
        sampled = sample_aligned(spec, path_index, idx, pad_to=batch_size(min(spec.chunk_size, spec.n_runs)))
    m = batch_size(len(idx))
    return sampled._replace(scenarios=jax.tree_util.tree_map(lambda a: np.asarray(a)[:m], sampled.scenarios))


def simulate_chunk(
    spec: StudySpec,
    path_index: int,
    idx: np.ndarray,
    name: str,
    controller,
    *,
    slip_override=None,
    pad_to: int | None = None,
    sampled=None,
) -> pd.DataFrame:
    """Simulate runs ``idx`` of one path with one controller; one row per run (see :mod:`pfjax.montecarlo.runner`).

    The batch is padded to ``pad_to`` runs (default: the study's chunk, or fewer for a smaller
    study) so every chunk of a study has one shape (one compilation per controller and path).
    ``sampled``: the chunk's :func:`sample_aligned` result if the caller already has it."""
    ctrl, gains, _ = controller
    n = len(idx)
    if sampled is None:
        sampled = sample_aligned(spec, path_index, idx, slip_override=slip_override, pad_to=pad_to)
    m = jax.tree_util.tree_leaves(sampled.scenarios)[0].shape[0]
    res = sharding.gather(
        simulate_scenarios(with_gains(sampled.scenarios, gains, m), controller=ctrl, config=sim_config(spec))
    )
    df = pd.DataFrame({"path": spec.paths[path_index].label, "controller": name, "run": idx})
    for col in column_names(spec):
        # in the study's precision, as the simulation ran them (a column this path lacks: NaN)
        df[col] = (
            np.asarray(sampled.columns[col], spec.dtype) if col in sampled.columns else np.full(n, np.nan, spec.dtype)
        )
    return add_results(df, res, n)


def add_results(df: pd.DataFrame, res, n: int) -> pd.DataFrame:
    """``df`` (one row per run) with the first ``n`` runs of a :class:`~pfjax.sim.SimResult` added
    as columns: every metric (:data:`~pfjax.metrics.running.METRIC_NAMES`), ``status_code``,
    ``status`` (its name) and ``fail_time`` (s, NaN without failure); the run table's layout."""
    for m in METRIC_NAMES:
        df[m] = np.asarray(getattr(res.metrics, m))[:n]
    df["status_code"] = np.asarray(res.status)[:n].astype(np.int8)
    df["status"] = [STATUS_NAMES[int(s)] for s in df["status_code"]]
    df["fail_time"] = np.asarray(res.fail_time)[:n]
    df["success"] = df["success"].astype(bool)
    for m in dynamic.SLIP_METRIC_NAMES if isinstance(res, dynamic.DynamicResult) else ():
        df[m] = np.asarray(getattr(res.slip, m))[:n]
    return df


def simulate_runs(
    spec: StudySpec,
    path_index: int,
    runs: np.ndarray,
    controllers,
    *,
    slip_override=None,
    chunk=None,
    store: ChunkSource | None = None,
    prefix: str = "runs",
):
    """Simulate ``runs`` of one path for every controller; yields ``(controller name, chunk key, DataFrame)``.

    Rows come in a canonical order (controller, then run) whatever the chunk size. Every controller
    runs the same sampled chunks (deterministic): kept from the first controller for the others
    while they fit in :data:`SHARED_SAMPLES_BYTES`, else re-sampled, so memory stays bounded. With a
    ``store``, chunks finished earlier are read back instead of simulated (resume)."""
    chunk = chunk or spec.chunk_size
    pad_to = batch_size(min(chunk, max(spec.n_runs, len(runs))))  # the margin sweep pads up to the study's chunk
    # The controllers run the same sampled chunks: while all of them fit in SHARED_SAMPLES_BYTES,
    # each chunk is sampled once and kept for the next controller (sampling is dispatched op by op:
    # ~0.4 s per chunk of the default study); beyond, every controller re-samples, so memory stays
    # O(chunk) (a sampled slip sequence alone is kilobytes per run).
    shared: dict | None = {} if len(controllers) > 1 else None
    for ci, (name, controller) in enumerate(controllers.items()):
        for a in range(0, len(runs), chunk):
            idx = runs[a : a + chunk]
            over = None if slip_override is None else tuple(np.asarray(o)[a : a + chunk] for o in slip_override)
            key = chunk_key(prefix, path_index, ci, a)

            def compute(a=a, idx=idx, over=over, name=name, controller=controller, last=ci == len(controllers) - 1):
                nonlocal shared
                sampled = None if shared is None else (shared.pop(a, None) if last else shared.get(a))
                if sampled is None:
                    sampled = sample_aligned(spec, path_index, idx, slip_override=over, pad_to=pad_to)
                    if shared is not None and not last:
                        if _nbytes(sampled) * len(runs) / len(idx) <= SHARED_SAMPLES_BYTES:
                            shared[a] = sampled
                        else:
                            shared = None
                return simulate_chunk(
                    spec, path_index, idx, name, controller, slip_override=over, pad_to=pad_to, sampled=sampled
                )

            yield name, key, (compute() if store is None else store.get(key, compute))


#: Most memory :func:`simulate_runs` spends keeping one path's sampled chunks for the next controller.
SHARED_SAMPLES_BYTES = 64 << 20


def _nbytes(sampled) -> int:
    leaves = jax.tree_util.tree_leaves(sampled.scenarios) + list(sampled.columns.values())
    return sum(int(x.nbytes) for x in leaves)
