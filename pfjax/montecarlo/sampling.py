"""Sampling a study's runs: distributions -> per-run parameters -> a batch of Scenarios.

Determinism: run ``i`` of path ``p`` draws every quantity from
``fold_in(fold_in(fold_in(seed_key(seed), p), i), q)`` (:func:`pfjax.numerics.random.seed_key`) with ``q`` the quantity's fixed index, so a
run's parameters do not depend on the chunk it falls in, and every controller sees the same runs
(common random numbers: controller differences are not sampling noise).
"""

from __future__ import annotations

import functools
import math
from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import pydantic_core

from pfjax import paths
from pfjax.models import DYNAMIC_MODELS
from pfjax.models.slip import CONVENTIONS, Pose, SlipParams
from pfjax.montecarlo.config import Dist, PathSpec, StudySpec
from pfjax.montecarlo.scenario_config import InitialSpec, NoiseSpec, SlipSpec, VehicleSpec
from pfjax.numerics.random import seed_key
from pfjax.paths import shapes
from pfjax.paths.geometry import arc_length, tangent_angle
from pfjax.sim.dynamic import DynamicScenario
from pfjax.sim.simulate import Scenario, SensorNoise
from pfjax.sim.slip_profiles import SlipProfile

#: Fixed quantity indices (never reorder: they define the random streams).
QUANTITIES = (
    "speed",
    "L",
    "delta_max_deg",
    "beta_r_deg",
    "beta_f_deg",
    "step_time_s",
    "step_r_deg",
    "step_f_deg",
    "amp_r_deg",
    "amp_f_deg",
    "freq_hz",
    "phase_r",
    "phase_f",
    "ou_sigma_deg",
    "ou_tau_s",
    "start_along_m",
    "lateral_offset",
    "heading_error_deg",
    "radius",
    "path",
    "noise",
    "ou_r",
    "ou_f",
    "sign_r",
    "sign_f",
    "mu",
)
Q = {name: i for i, name in enumerate(QUANTITIES)}


def run_keys(seed: int, path_index: int, runs: np.ndarray) -> jax.Array:
    base = jax.random.fold_in(seed_key(seed), path_index)
    return _fold_runs(base, jnp.asarray(runs, dtype=jnp.uint32))


@jax.jit
def _fold_runs(base, runs):
    return jax.vmap(lambda i: jax.random.fold_in(base, i))(runs)


def draw(dist: Dist, key, numbers: dict) -> jax.Array:
    """One scalar from a distribution of ``dist``'s kind with the parameters ``numbers``
    (:meth:`Dist.numbers`, as arrays: traced, so one program serves every distribution of a kind)."""
    f = jnp.result_type(float)
    if dist.dist == "constant":
        return jnp.asarray(numbers["value"], f)
    if dist.dist == "uniform":
        return jax.random.uniform(key, (), f, numbers["low"], numbers["high"])
    if dist.dist == "normal":
        return numbers["mean"] + numbers["std"] * jax.random.normal(key, (), f)
    if dist.dist == "truncnormal":
        mean, std = numbers["mean"], numbers["std"]
        lo, hi = (numbers["low"] - mean) / std, (numbers["high"] - mean) / std
        return mean + std * jax.random.truncated_normal(key, lo, hi, (), f)
    return jax.random.choice(key, jnp.asarray(numbers["values"], f))


#: A valid distribution of each kind, standing in for a study's own in the sampler's static arguments.
_PLACEHOLDER: dict[str, dict] = {
    "constant": {"value": 0.0},
    "uniform": {"low": 0.0, "high": 1.0},
    "normal": {"mean": 0.0, "std": 1.0},
    "truncnormal": {"mean": 0.0, "std": 1.0, "low": -1.0, "high": 1.0},
}


def _placeholder(dist: Dist) -> Dist:
    """A distribution of ``dist``'s kind (and, for ``choice``, its number of values) with fixed numbers."""
    if dist.dist == "choice":
        return Dist(dist="choice", values=[0.0] * len(dist.values or ()))
    return Dist(dist=dist.dist, **_PLACEHOLDER[dist.dist])


def _q(key, name):
    return jax.random.fold_in(key, Q[name])


def ou_sequence(key, n: int, dt: float, sigma, tau) -> jax.Array:
    """Stationary Ornstein-Uhlenbeck samples ``x_{k+1} = a x_k + sigma sqrt(1 - a^2) n_k``, ``a = exp(-dt/tau)``
    (exact discretisation; stationary std ``sigma``)."""
    a = jnp.exp(-dt / tau)
    noise = jax.random.normal(key, (n,), jnp.result_type(float))
    x0 = sigma * noise[0]
    step = lambda x, nk: (a * x + sigma * jnp.sqrt(1 - a * a) * nk,) * 2
    _, xs = jax.lax.scan(step, x0, noise[1:])
    return jnp.concatenate([x0[None], xs])


class Sampled(NamedTuple):
    """Per-run sampled values in config units (the columns of runs.parquet)."""

    columns: dict  # name -> np.ndarray (n,)
    scenarios: Scenario | DynamicScenario  # batched (by vehicle.model), gains = None (filled per controller)


SLIP_COLUMNS = SlipSpec.KIND_KEYS


def column_names(spec: StudySpec) -> list[str]:
    """The sampled-parameter columns of a study's run table (fixed for the whole study; NaN where
    a column does not apply to a path)."""
    cols = [
        "speed",
        "L",
        "delta_max_deg",
        "beta_r_deg",
        "beta_f_deg",
        *SLIP_COLUMNS[spec.slip.kind],
        "start_along_m",
        "lateral_offset",
        "heading_error_deg",
    ]
    if any(p.kind == "circle" for p in spec.paths):
        cols.append("radius")
    if spec.vehicle.model in DYNAMIC_MODELS:
        cols.append("mu")
    return cols


class _Static:
    """Pydantic models (or a tuple of them and plain values) as a static ``jax.jit`` argument:
    hashed and compared by their JSON."""

    __slots__ = ("_json", "model")

    def __init__(self, model):
        self.model, self._json = model, pydantic_core.to_json(model)

    def __hash__(self):
        return hash(self._json)

    def __eq__(self, other):
        return isinstance(other, _Static) and other._json == self._json


class _Design(NamedTuple):
    """What the sampler reads of a study (static in :func:`_draw_runs`): its vehicle, slip,
    initial-condition and noise sections and its horizon (s), every distribution in them reduced to
    its kind by :func:`_placeholder`. The distributions' numbers are the program's arguments, so
    studies, and the arms of one, that differ only in those numbers share one compiled sampler."""

    vehicle: VehicleSpec
    slip: SlipSpec
    initial: InitialSpec
    noise: NoiseSpec
    horizon: float


def _design(spec: StudySpec, pspec: PathSpec) -> tuple[_Design, dict, Dist | None]:
    """The sampler's static part of ``spec`` for the path ``pspec``, the numbers of their
    distributions by quantity name (:data:`QUANTITIES`; :meth:`Dist.numbers`), and for a circle its
    radius distribution's placeholder (``None`` for other paths)."""
    numbers: dict = {}

    def masked(section):
        dists = {name: value for name, value in section if isinstance(value, Dist)}
        numbers.update({name: d.numbers() for name, d in dists.items()})
        return section.model_copy(update={name: _placeholder(d) for name, d in dists.items()})

    circle = None
    if pspec.kind == "circle":
        numbers["radius"], circle = pspec.radius.numbers(), _placeholder(pspec.radius)
    design = _Design(masked(spec.vehicle), masked(spec.slip), masked(spec.initial), spec.noise, spec.sim.horizon)
    return design, numbers, circle


def _slip(design: _Design, key, given: dict, numbers: dict):
    s, horizon = design.slip, design.horizon
    d = lambda name: given[name] if name in given else draw(getattr(s, name), _q(key, name), numbers[name])
    rad = math.pi / 180
    br, bf = d("beta_r_deg"), d("beta_f_deg")
    cols = {"beta_r_deg": br, "beta_f_deg": bf}
    n_seq = int(math.ceil(horizon / s.seq_dt)) + 2
    terms: dict[str, jax.Array] = {}  # only the kind's own terms: an absent term is not computed in the simulator
    if s.kind == "step":
        step_time = d("step_time_s")
        sr, sf = d("step_r_deg"), d("step_f_deg")
        terms.update(step_time=step_time, step_size=jnp.stack([sr, sf]) * rad)
        cols.update(step_time_s=step_time, step_r_deg=sr, step_f_deg=sf)
    elif s.kind == "sinusoid":
        ar, af, fr = d("amp_r_deg"), d("amp_f_deg"), d("freq_hz")
        phase = lambda name: given[name] if name in given else jax.random.uniform(_q(key, name), (), maxval=2 * math.pi)
        ph = jnp.stack([phase("phase_r"), phase("phase_f")])
        terms.update(sin_amp=jnp.stack([ar, af]) * rad, sin_freq=jnp.stack([fr, fr]), sin_phase=ph)
        cols.update(amp_r_deg=ar, amp_f_deg=af, freq_hz=fr)
    elif s.kind == "ou":
        sig, tau = d("ou_sigma_deg"), d("ou_tau_s")
        seq = jnp.stack(
            [
                ou_sequence(_q(key, "ou_r"), n_seq, s.seq_dt, sig * rad, tau),
                ou_sequence(_q(key, "ou_f"), n_seq, s.seq_dt, sig * rad, tau),
            ],
            axis=1,
        )
        terms.update(seq=seq, seq_dt=jnp.asarray(s.seq_dt, float))
        cols.update(ou_sigma_deg=sig, ou_tau_s=tau)
    profile = SlipProfile(constant=jnp.stack([br, bf]) * rad, **terms)
    return profile, cols


def _start_pose(path, u_nominal, start_along_m, offset, heading_err):
    """Pose ``offset`` metres left of the point ``start_along_m`` metres along from ``u_nominal``, heading
    ``theta_p + heading_err`` (Newton on the arc length; 6 steps are exact to rounding here), and
    that point's parameter ``u`` (the simulator's initial closest-point guess)."""
    s0 = arc_length(path, u_nominal) + start_along_m
    u = u_nominal + start_along_m
    for _ in range(6):
        dx, dy = path.d1(u)
        u = u - (arc_length(path, u) - s0) / jnp.sqrt(dx * dx + dy * dy)
    px, py = path.point(u)
    th = tangent_angle(path, u)
    return Pose(px - offset * jnp.sin(th), py + offset * jnp.cos(th), th + heading_err), u


def random_path(key, spec: PathSpec, kappa_max: float) -> shapes.Spline:
    """A smooth random path: curvature ``kappa(s) = sum_j a_j sin(w_j s + phi_j)`` (3 modes, wavelengths
    6-30 m) scaled so ``max|kappa| = kappa_max``, integrated from the origin heading +x, and a natural
    cubic spline through ``n_waypoints`` points along it. Built with NumPy (SciPy spline) at the edge.
    The integral is taken on 4001 samples, or 4 per waypoint interval where there are more than
    1000 intervals (so that the waypoints are distinct samples)."""
    rng = np.random.default_rng(np.asarray(key).astype(np.uint32).tolist())
    s = np.linspace(0.0, spec.length, max(4001, 4 * (spec.n_waypoints - 1) + 1))
    w = 2 * np.pi / rng.uniform(6.0, 30.0, 3)
    a = rng.normal(size=3)
    phi = rng.uniform(0, 2 * np.pi, 3)
    kappa = (a[None, :] * np.sin(w[None, :] * s[:, None] + phi[None, :])).sum(1)
    kappa *= kappa_max / max(np.abs(kappa).max(), 1e-12)
    ds = s[1] - s[0]
    theta = np.concatenate([[0.0], np.cumsum(0.5 * (kappa[1:] + kappa[:-1]) * ds)])
    x = np.concatenate([[0.0], np.cumsum(0.5 * (np.cos(theta[1:]) + np.cos(theta[:-1])) * ds)])
    y = np.concatenate([[0.0], np.cumsum(0.5 * (np.sin(theta[1:]) + np.sin(theta[:-1])) * ds)])
    idx = np.linspace(0, s.size - 1, spec.n_waypoints).round().astype(int)
    return shapes.spline_through(np.stack([x[idx], y[idx]], 1))


def _fixed_path(spec: PathSpec):
    """The path every run of a non-random kind shares (``None`` for ``circle``: its radius is drawn per run)."""
    e = paths.entry(spec.kind)
    if not e.parametric and e.build is not None:
        return _built_path(e.build, np.dtype(jnp.result_type(float)).name)
    if spec.kind == "spline":  # the same user-defined path for every run
        return shapes.spline_through(np.asarray(spec.points, float))
    if spec.kind == "circle":
        return None
    raise AssertionError(spec.kind)


@functools.cache
def _built_path(build, dtype: str):
    """A registered path without parameters, ``build()``, once per build function (a path
    registered again by its module has a new one) and precision (``dtype``: the floats JAX makes,
    which the build follows): a rare-event estimate samples thousands of small batches, and each
    build is a dozen array conversions."""
    return build()


#: Runs whose start poses the sampler computes at once (bounds its memory: about 4 MB per
#: arc-length intermediate in float32).
SAMPLE_BLOCK = 2048


#: Quantities :func:`sample_runs` can take per run (``given``) instead of drawing them (the
#: slip profile's terms are used only by their kind; the sinusoid's phases are in rad).
GIVEN = (
    "speed",
    "L",
    "delta_max_deg",
    "beta_r_deg",
    "beta_f_deg",
    "start_along_m",
    "lateral_offset",
    "heading_error_deg",
    "mu",
    "step_time_s",
    "step_r_deg",
    "step_f_deg",
    "amp_r_deg",
    "amp_f_deg",
    "freq_hz",
    "phase_r",
    "phase_f",
)


def sample_runs(
    spec: StudySpec, path_index: int, runs: np.ndarray, *, slip_override=None, key=None, given: dict | None = None
) -> Sampled:
    """Scenarios (without gains) and sampled columns for the given run indices of one path.

    ``slip_override``: optional ``(beta_r_deg, beta_f_deg)`` arrays replacing the constant slip
    (used by the slip-margin sweep). ``key``: a JAX PRNG key to draw from instead of the study's
    seed (run ``i`` draws from ``fold_in(key, i)``). ``given``: per-run values (arrays of
    ``len(runs)``, config units) of some of :data:`GIVEN`, used instead of drawing them.

    The draws are one jitted program (:func:`_draw_runs`) per batch shape, precision and study design
    (:class:`_Design`: the distributions' kinds, not their numbers), shared by the paths of one shape
    (line, parabola and sine pass their path in): a chunk of 2,500 runs costs milliseconds instead of
    the ~0.2 s of some hundred op-by-op dispatches, and a study that differs from another only in its
    distributions' numbers reuses its compiled sampler.
    """
    pspec = spec.paths[path_index]
    keys = (
        run_keys(spec.seed, path_index, runs) if key is None else _fold_runs(key, jnp.asarray(runs, dtype=jnp.uint32))
    )
    # the program's small arguments as NumPy arrays: the compiled call moves them to the device in
    # one go, where a jnp.asarray each costs tens of microseconds of dispatch (dozens per call)
    f = np.dtype(jnp.result_type(float))
    given = {k: np.asarray(v, f) for k, v in (given or {}).items()}
    design, numbers, circle = _design(spec, pspec)
    numbers = {q: {k: np.asarray(v, f) for k, v in d.items()} for q, d in numbers.items()}
    if pspec.kind == "random":
        drawn = [
            random_path(jax.random.fold_in(k, Q["path"]), pspec, pspec.curvature_margin * _kappa_follow(spec))
            for k in keys
        ]
        path = jax.tree_util.tree_map(lambda *xs: jnp.stack(xs), *drawn)
    else:
        path = _fixed_path(pspec)
    # the override is always passed (zeros and a false flag when absent): one program for both
    over = (np.zeros(len(runs)),) * 2 if slip_override is None else slip_override
    over = tuple(np.asarray(a, f) for a in over)
    cols, sc = _draw_runs(
        keys,
        given,
        path,
        np.asarray(paths.entry(pspec.kind).start_u, f),
        over,
        slip_override is not None,
        numbers,
        design=_Static(design),
        circle=None if circle is None else _Static(circle),
        batched_path=pspec.kind == "random",
    )
    return Sampled({k: np.asarray(v) for k, v in cols.items()}, sc)


def _kappa_follow(spec: StudySpec) -> float:
    """The followable curvature for the most restrictive vehicle in the distribution (random paths)."""
    veh = spec.vehicle
    return math.tan(math.radians(veh.delta_max_deg_bounds()[0])) / veh.wheelbase_bounds()[1]


def _draw_one(design: _Design, key, given: dict, numbers: dict):
    """One run's draws from its ``key`` (``given[name]`` instead where given; the distributions'
    numbers from ``numbers``, :func:`_design`): the slip profile, the
    vehicle's :class:`~pfjax.models.slip.SlipParams` (speed m/s, wheelbase m, steering limit rad), the
    columns of the run table (degrees where named ``_deg``) and the start's ``(arc length m, lateral
    offset m, heading error rad)``."""
    v = design.vehicle
    rad = math.pi / 180
    d = lambda dist, name: given[name] if name in given else draw(dist, _q(key, name), numbers[name])
    speed, L, dmax = d(v.speed, "speed"), d(v.L, "L"), d(v.delta_max_deg, "delta_max_deg")
    extra = {}
    if v.model in DYNAMIC_MODELS:  # the set's wheelbase and steering limit; the friction drawn
        st_nominal = v.st_params()
        L = jnp.asarray(st_nominal.l_f + st_nominal.l_r, float)
        dmax = jnp.asarray(math.degrees(st_nominal.delta_max), float)
        extra["mu"] = jnp.asarray(st_nominal.mu, float) if v.mu is None else d(v.mu, "mu")
    profile, cols = _slip(design, key, given, numbers)
    if v.model in DYNAMIC_MODELS:  # nothing declared: the tyres make the slip (max_abs_beta_* record it)
        cols = {k: jnp.full_like(c, jnp.nan) for k, c in cols.items()}
    start_along_m = d(design.initial.start_along_m, "start_along_m")
    offset = d(design.initial.lateral_offset, "lateral_offset")
    herr = d(design.initial.heading_error_deg, "heading_error_deg")
    cols.update(
        speed=speed,
        L=L,
        delta_max_deg=dmax,
        start_along_m=start_along_m,
        lateral_offset=offset,
        heading_error_deg=herr,
        **extra,
    )
    params = SlipParams(
        v=speed,
        L=L,
        delta_max=dmax * rad,
        convention=jnp.asarray(CONVENTIONS[v.convention], jnp.int32),
        delta_rate_max=jnp.asarray(math.inf if v.delta_rate_max_deg is None else v.delta_rate_max_deg * rad, float),
    )
    return profile, params, cols, (start_along_m, offset, herr * rad)


def _scenarios(design: _Design, keys, cols: dict, profiles, params, path, pose0, u0):
    """The batch's scenarios from its draws: the slip vehicle's :class:`Scenario` or, for the ``st``
    and ``std`` models, the :class:`DynamicScenario` with the drawn friction ``cols["mu"]``; sensor
    noise (``sigma_d`` m, ``sigma_theta_e_deg`` deg) with one key per run where the study has any."""
    v, sensor = design.vehicle, design.noise
    n = keys.shape[0]
    rad = math.pi / 180
    noise = None
    if sensor.sigma_d > 0 or sensor.sigma_theta_e_deg > 0:
        noise = SensorNoise(
            jnp.full((n,), sensor.sigma_d, float),
            jnp.full((n,), sensor.sigma_theta_e_deg * rad, float),
            jax.vmap(lambda k: jax.random.fold_in(k, Q["noise"]))(keys),
        )
    if v.model in DYNAMIC_MODELS:
        from pfjax.models.single_track import with_mu

        per_run = lambda a: jnp.full((n,), a, params.v.dtype)
        vehicle = with_mu(jax.tree_util.tree_map(per_run, v.model_params()), cols["mu"])
        return DynamicScenario(
            pose0=pose0,
            vehicle=vehicle,
            v_ref=params.v,
            path=path,
            gains=None,
            tau_delta=per_run(v.tau_delta_s),
            k_v=per_run(v.k_v),
            noise=noise,
            u0=u0,
        )
    return Scenario(pose0=pose0, slip=profiles, params=params, path=path, gains=None, noise=noise, u0=u0)


@partial(jax.jit, static_argnames=("design", "circle", "batched_path"))
def _draw_runs(
    keys,
    given,
    path,
    u_nom,
    slip_override,
    use_override,
    numbers,
    *,
    design: _Static,
    circle: _Static | None,
    batched_path: bool,
):
    """Every run's draws (vmapped over ``keys``; per-run ``given`` values instead where given; the
    distributions of ``design``, a :class:`_Design`, with the parameters ``numbers``) and its start
    pose on ``path`` (batched if ``batched_path``; a circle of drawn radius if ``circle`` is its
    radius distribution); the constant slip replaced by ``slip_override`` (deg) where ``use_override``."""
    study_design = design.model  # the _Design inside its static wrapper
    rad = math.pi / 180
    profiles, params, cols, starts = jax.vmap(lambda k, g: _draw_one(study_design, k, g, numbers))(keys, given)
    n = keys.shape[0]
    br = jnp.where(use_override, slip_override[0], cols["beta_r_deg"])
    bf = jnp.where(use_override, slip_override[1], cols["beta_f_deg"])
    profiles = profiles._replace(constant=jnp.where(use_override, jnp.stack([br, bf], 1) * rad, profiles.constant))
    cols.update(beta_r_deg=br, beta_f_deg=bf)
    if circle is not None:
        r = jax.vmap(lambda k: draw(circle.model, _q(k, "radius"), numbers["radius"]))(keys)
        path, batched_path = jax.vmap(lambda r: shapes.circle(radius=r, cy=r))(r), True
        cols.update(radius=r)
    runs_path = (
        path if batched_path else jax.tree_util.tree_map(lambda a: jnp.broadcast_to(a, (n,) + jnp.shape(a)), path)
    )
    if not batched_path and study_design.initial.start_along_m.dist == "constant" and "start_along_m" not in given:
        # one path and one arc length for every run: the start point's Newton on the arc length
        # (512 nodes per step) is solved once, only the offset and heading error are per run
        along = draw(study_design.initial.start_along_m, None, numbers["start_along_m"])  # the constant
        pose0, u0 = jax.vmap(lambda o, h: _start_pose(path, u_nom, along, o, h))(*starts[1:])
    else:
        # in blocks of runs: each start pose integrates arc length on 512 nodes per Newton step, and
        # a 65,536-run chunk at once held about 1.6 GB of such intermediates (measured)
        pose0, u0 = jax.lax.map(
            lambda a: _start_pose(a[0], u_nom, *a[1:]), (runs_path, *starts), batch_size=SAMPLE_BLOCK
        )
    return cols, _scenarios(study_design, keys, cols, profiles, params, runs_path, pose0, u0)
