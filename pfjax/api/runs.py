"""Batches of runs, vectorised: numbers, arrays of ``n`` numbers or distributions per quantity."""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np

from pfjax import errors, resources
from pfjax.errors import arguments_checked

#: :func:`scenarios`'s arguments -> the study config's keys.
_SCENARIO_KEYS = {
    "speed": "vehicle.speed",
    "L": "vehicle.L",
    "delta_max_deg": "vehicle.delta_max_deg",
    "beta_r_deg": "slip.beta_r_deg",
    "beta_f_deg": "slip.beta_f_deg",
    "start_along_m": "initial.start_along_m",
    "lateral_offset": "initial.lateral_offset",
    "heading_error_deg": "initial.heading_error_deg",
    "mu": "vehicle.mu",
    "vehicle_params": "vehicle.params",
    "tau_delta_s": "vehicle.tau_delta_s",
    "k_v": "vehicle.k_v",
    "model": "vehicle.model",
}


class Scenarios(NamedTuple):
    """A batch of runs of one path (:func:`scenarios`), for :func:`pfjax.simulate`.

    Attributes:
        batch: the runs as the simulator takes them, every leaf with a leading run axis of length
            :attr:`n` and no gains (the controller's are added by :func:`pfjax.simulate`): a
            :class:`pfjax.sim.Scenario` (SI units, angles in rad) for the kinematic model, a
            :class:`pfjax.sim.dynamic.DynamicScenario` for ``st`` and ``std``.
        table: a pandas DataFrame, one row per run: ``run`` (its index) and the values drawn, in the
            study config's units and the simulation's precision: ``speed`` (m/s), ``L`` (m),
            ``delta_max_deg`` (deg), the slip columns (``beta_r_deg``, ``beta_f_deg``, deg; NaN on
            ``st`` and ``std``, whose slip comes from the tyres), ``start_along_m`` (m),
            ``lateral_offset`` (m), ``heading_error_deg`` (deg), and ``mu`` (1) on ``st`` and ``std``.
        spec: the study config that describes the runs (:class:`pfjax.montecarlo.config.StudySpec`):
            its ``vehicle`` section holds the model and its settings.
        n: the number of runs (the table's rows).
    """

    batch: Any
    table: Any
    spec: Any

    @property
    def n(self) -> int:
        """The number of runs."""
        return len(self.table)


@arguments_checked
def scenarios(
    path: str = "sine",
    n: int = 1,
    *,
    beta_r_deg=None,
    beta_f_deg=None,
    lateral_offset=0.0,
    heading_error_deg=0.0,
    start_along_m=0.0,
    speed=1.0,
    L=None,
    delta_max_deg=None,
    convention: str | None = None,
    horizon: float = 20.0,
    key=0,
    model: str = "kinematic",
    vehicle_params: str | None = None,
    mu=None,
    tau_delta_s: float | None = None,
    k_v: float | None = None,
) -> Scenarios:
    """``n`` runs on a registered path (:data:`pfjax.paths.PATHS`), vectorised: each quantity is a
    number (every run), an array of ``n`` numbers (run by run), or a distribution
    (:func:`uniform`, :func:`normal`, :func:`truncnormal`, :func:`choice`, or a study config's
    ``{"dist": ...}`` dict) drawn per run. One jitted program draws them all; no Python loop.

    Args:
        path: a registered path kind (``line``, ``parabola``, ``sine``, ``circle``, ...).
        n: number of runs, at most 10^8 and what fits the memory budget (about 300 bytes per run,
            :data:`pfjax.resources.SCENARIO_BYTES`; :func:`pfjax.resources.memory_budget`).
        beta_r_deg: constant rear slip angle, deg (kinematic model; default 5).
        beta_f_deg: constant front slip angle, deg (kinematic model; default 5).
        lateral_offset: start offset left of the path, m (default 0: a run starts on the path,
            where ``pfjax simulate``, which runs the source's scenario, starts at the path's own
            start pose unless given ``--x0``; :data:`pfjax.paths.PATHS`' ``start_pose``).
        heading_error_deg: start heading error, deg (default 0).
        start_along_m: start, m along the path from its nominal start.
        speed: rear-axle speed, m/s (``st``, ``std``: the reference of the centre of mass's speed
            loop, at most the parameter set's top speed).
        L: wheelbase, m (kinematic model; default 0.2).
        delta_max_deg: steering limit, deg (kinematic model; default 30).
        convention: front-slip sign convention (``source`` or ``lenain``; kinematic model).
        horizon: s, only to size slip sequences (the simulation's horizon and step are
            :func:`simulate`'s, which checks the step against the ``st`` and ``std`` runs' tyre modes,
            steering actuator and speed loop).
        key: an int seed or a JAX PRNG key. An int seed ``s`` draws the runs a study with
            ``seed = s`` draws on its first path (run ``i`` from
            ``fold_in(fold_in(seed_key(s), 0), i)``, :func:`pfjax.numerics.random.seed_key`); a key
            ``k`` draws run ``i`` from ``fold_in(k, i)``. So ``key=0`` and
            ``key=jax.random.key(0)`` draw different runs. Either way the first runs of a larger
            ``n`` are the same runs.
        model: ``"kinematic"`` (slip declared by ``beta_r_deg``, ``beta_f_deg``), ``"st"``
            (CommonRoad's single-track model, :mod:`pfjax.sim.dynamic`: the slip comes from the tyre
            forces and the wheelbase and steering limit from the parameter set, so ``beta_r_deg``,
            ``beta_f_deg``, ``L``, ``delta_max_deg`` and ``convention`` are refused with it, at any
            value, as ``pfjax simulate --model st`` refuses their flags) or ``"std"`` (its drift
            model, CommonRoad's vehicles only).
        vehicle_params: st, std: parameter set, ``robot`` or ``vehicle1``-``vehicle3`` (default
            ``robot`` for st, ``vehicle2`` for std).
        mu: st: friction coefficient (default the set's). tau_delta_s: st: steering actuator time
            constant, s (default 0.05). k_v: st: speed loop gain, 1/s (default 5).

    The arguments are checked as a study config's ``[vehicle]``, ``[slip]`` and ``[initial]`` keys
    are (the same validation, the message naming the argument).
    """
    import pandas as pd

    from pfjax.montecarlo.sampling import sample_runs

    if path == "spline":  # the one kind that needs more than its name: its waypoints
        raise errors.InputError(
            "path: kind 'spline' needs its waypoints, which scenarios() does not take; run a study whose "
            '[[paths]] has kind = "spline" and points = [[x, y], ...]',
            "path",
        )
    n = errors.integer("n", n, low=1, high=100_000_000)
    resources.check_memory(
        "n",
        n * resources.SCENARIO_BYTES,
        f"drawing {n} runs at once",
        "draw fewer runs per call, or run a study (pfjax.run_study), which streams any number in chunks",
    )
    given = dict(beta_r_deg=beta_r_deg, beta_f_deg=beta_f_deg, L=L, delta_max_deg=delta_max_deg)
    given.update(convention=convention, vehicle_params=vehicle_params, mu=mu, tau_delta_s=tau_delta_s, k_v=k_v)
    _refuse_other_models(model, given)
    if model == "kinematic":  # the kinematic defaults (None: not given, so the ST model can refuse a given one)
        beta_r_deg = 5.0 if beta_r_deg is None else beta_r_deg
        beta_f_deg = 5.0 if beta_f_deg is None else beta_f_deg
    values = dict(
        speed=speed,
        L=L,
        delta_max_deg=delta_max_deg,
        beta_r_deg=beta_r_deg,
        beta_f_deg=beta_f_deg,
        start_along_m=start_along_m,
        lateral_offset=lateral_offset,
        heading_error_deg=heading_error_deg,
        mu=mu,
    )
    seed, jkey = seed_or_key(key)
    spec, given = _checked_spec(
        path, n, 0 if seed is None else seed, horizon, model, values, convention, vehicle_params, tau_delta_s, k_v
    )
    sampled = sample_runs(spec, 0, np.arange(n), key=jkey, given=given)
    table = pd.DataFrame({"run": np.arange(n), **{k: np.asarray(v) for k, v in sampled.columns.items()}})
    return Scenarios(sampled.scenarios, table, spec)


def _refuse_other_models(model: str, given: dict) -> None:
    """:class:`~pfjax.errors.InputError` naming the first argument of ``given`` (not None) that only
    the other vehicle model reads (:data:`pfjax.montecarlo.config.MODEL_SETTINGS`, the table the
    study config and ``pfjax simulate`` refuse from); an unknown ``model`` is the config's to refuse."""
    from pfjax.models import MODELS
    from pfjax.montecarlo.scenario_config import other_models_settings

    if model not in MODELS:
        return
    for setting in other_models_settings(model):
        name = setting.argument
        if name is not None and given[name] is not None:
            raise errors.InputError(f'{name}: not with model = "{model}" ({setting.refusal(model)}); remove it', name)


def seed_or_key(key, name: str = "key") -> tuple[int | None, Any]:
    """``(seed, None)`` for an int seed (``0`` to ``2**63 - 1``), ``(None, key)`` for a JAX PRNG key (a
    typed key or raw ``uint32`` key data, one key); :class:`~pfjax.errors.InputError` naming ``name``
    otherwise."""
    import jax
    import jax.numpy as jnp

    if isinstance(key, (int, np.integer)):  # a bool is refused here, as an integer (errors.integer)
        return errors.seed(name, key), None
    if isinstance(key, (jax.Array, np.ndarray)):
        if jnp.issubdtype(key.dtype, jax.dtypes.prng_key):
            one = key.shape == ()
        else:  # raw key data: uint32 words of one key (a wider type would be cast silently)
            try:
                one = key.dtype == np.uint32 and jax.random.wrap_key_data(jnp.asarray(key)).shape == ()
            except (TypeError, ValueError):
                one = False
        if one:
            return None, key
        got = f"an array of {key.dtype}, shape {key.shape}"
    else:
        got = repr(key) if len(repr(key)) <= 60 else f"a {type(key).__name__}"
    raise errors.InputError(f"{name}: must be an int seed or a JAX PRNG key, got {got}", name)


def prng_key(key, name: str = "key"):
    """A JAX PRNG key from an int seed (:func:`pfjax.numerics.random.seed_key`: all 63 bits, in any
    precision) or a JAX PRNG key (:func:`seed_or_key`)."""
    from pfjax.numerics.random import seed_key

    seed, k = seed_or_key(key, name)
    return k if seed is None else seed_key(seed)


def _checked_spec(path, n, seed, horizon, model, values, convention, vehicle_params, tau_delta_s, k_v):
    """The study spec of :func:`scenarios`'s arguments, checked as a study config is (the message naming
    the argument), and the per-run ``given`` arrays of ``values``."""
    from pfjax.montecarlo.config import load_study, step_checked_by_simulate

    horizon = errors.number("horizon", horizon, positive=True, unit=" s")  # before it becomes the step too
    dists, given = _as_dists(values, n)
    data = _study_data(path, n, seed, horizon, model, dists, convention, vehicle_params, tau_delta_s, k_v)
    try:  # the step is simulate()'s, checked there against the tyre modes of the runs' worst case
        with step_checked_by_simulate():
            spec, _ = load_study(data=data)
    except errors.InputError as e:
        raise _renamed(e) from None
    return spec, given


def _as_dists(values: dict, n: int) -> tuple[dict, dict]:
    """``(distribution tables by argument, per-run arrays given)`` from numbers, arrays of ``n``
    numbers and distributions (``None``: not given)."""
    from pfjax.montecarlo.config import Dist

    dists, given = {}, {}
    for name, v in values.items():
        if v is None:
            continue
        if isinstance(v, (Dist, dict)):
            dists[name] = v.model_dump() if isinstance(v, Dist) else v
            continue
        a = np.asarray(errors.numbers(name, v), dtype=float)
        if a.ndim == 0:
            dists[name] = {"dist": "constant", "value": float(a)}
        elif a.shape != (n,):
            raise errors.InputError(
                f"{name}: expected a number or {n} numbers (one per run), got shape {a.shape}", name
            )
        else:  # the config sees the values' range (its bounds are checked), the runs get the values
            lo, hi = float(a.min()), float(a.max())
            dists[name] = {"dist": "constant", "value": lo} if lo == hi else {"dist": "uniform", "low": lo, "high": hi}
            given[name] = a
    return dists, given


def _study_data(path, n, seed, horizon, model, dists, convention, vehicle_params, tau_delta_s, k_v) -> dict:
    """The study config (a dict) that describes the runs :func:`scenarios` draws."""
    from pfjax.sim.settings import SimConfig

    data: dict[str, Any] = {
        "name": "scenarios",
        "n_runs": n,
        "seed": seed,
        "paths": [{"kind": path}],
        "controllers": [{"name": "none", "type": "state_feedback"}],
        # the horizon only sizes the slip sequences: the rest of the run's timing is simulate()'s, so
        # the windows are kept inside any horizon, and the step is the default one, adjusted to divide
        # it into whole steps (the step count's limit still bounds the horizon)
        "sim": {
            "horizon": horizon,
            "dt": horizon / max(1, round(horizon / SimConfig.dt)),
            "steady_window": min(horizon, 5.0),
        },
        "success": {"from_s": min(horizon, 15.0)},
        "vehicle": {
            "model": model,
            **{k: dists[k] for k in ("speed", "L", "delta_max_deg", "mu") if k in dists},
            **{
                k: v
                for k, v in (
                    ("convention", convention),
                    ("params", vehicle_params),
                    ("tau_delta_s", tau_delta_s),
                    ("k_v", k_v),
                )
                if v is not None
            },
        },
        "slip": {k: dists[k] for k in ("beta_r_deg", "beta_f_deg") if k in dists},
        "initial": {k: dists[k] for k in ("start_along_m", "lateral_offset", "heading_error_deg")},
    }
    from pfjax.models import DYNAMIC_MODELS

    if model in DYNAMIC_MODELS:  # the slip-margin sweep declares slip, which these models do not take
        data["margin"] = {"enabled": False}
    return data


def _renamed(e: errors.InputError) -> errors.InputError:
    """A study-config error named by :func:`scenarios`'s argument (``slip.beta_r_deg`` -> ``beta_r_deg``)."""
    text = str(e)
    for arg, key in _SCENARIO_KEYS.items():
        text = text.replace(key, arg)
    text = (
        text.replace("paths[0].kind", "path")
        .replace("paths[0]", "path")
        .replace("sim.horizon", "horizon")
        .replace("sim.dt: horizon / dt", "horizon: horizon / dt")
        .replace("vehicle.convention", "convention")
    )
    return errors.InputError(text, text.split(":", 1)[0].split(".", 1)[0])
