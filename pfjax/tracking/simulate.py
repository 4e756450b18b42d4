"""One tracking run on the simulation loop (:mod:`pfjax.sim.loop`: one ``lax.scan``, the first failure
freezes the run); ``simulate_batch`` is its jit(vmap), sharded over every
device and, on CPU, evaluated in cache-sized blocks (:mod:`pfjax.sim.sharding`), like the slip model's.

Each step ``k`` (``t_k = k dt``): measure the state (plus white noise), read the leader's
``z_d(t_k), z_d'(t_k)``, evaluate :func:`focus_control`, hold ``(v, omega)`` for ``dt`` and advance
the follower with RK4 (:func:`pfjax.sim.integrators.rk4_step`; the steering is integrated exactly
because ``omega`` is held). The metrics use the true state after each step, ``t_{k+1}``.

Per run (``TrackMetrics``): ``iae = sum |z~| dt`` (m s), ``max_abs_gamma`` (rad), the final
window ``t >= horizon - window`` maxima of ``|z~|`` and ``|phi - p gamma|``, the final values, the
smallest ``|det M / (l p)|`` met and the fraction of steps with a limit active. Lemma 8.1's two
limits are decided on the final window with the config's tolerances::

    z~ -> 0           :  max_{t >= T - window} |z~(t)|          <= tol_z      (m)
    phi - p gamma -> 0:  max_{t >= T - window} |phi - p gamma|   <= tol_phi    (rad)

``success`` (Monte Carlo) is ``status == OK`` and ``max_{window} |z~| <= band``. The first failure
(non-finite state, ``|z~| > z_fail``, ``|det M / (l p)| < sing_tol``) sets ``status`` and freezes
the state and the metrics; it never raises.
"""

from __future__ import annotations

import dataclasses
from enum import IntEnum
from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp
from jax import Array

from pfjax.arrays import FloatLeaf
from pfjax.numerics import elementary as E
from pfjax.numerics.layout import all_true, first_true
from pfjax.numerics.random import step_normals
from pfjax.sim import batch, loop
from pfjax.sim.integrators import rk4_step
from pfjax.sim.loop import stack, unstack  # noqa: F401  (re-exported: a batch of runs, run i of a batch)
from pfjax.sim.slip_profiles import SlipProfile, constant_slip, slip_at
from pfjax.sim.status import Status
from pfjax.tracking.controller import Command, FocusGains, focus_control, steering_stop
from pfjax.tracking.geometry import Connection, connection, focus_point, tracking_error
from pfjax.tracking.leader import Leader, position, position_velocity, start_heading
from pfjax.tracking.model import Follower, FollowerParams, as_arrays, follower_rhs


class TrackStatus(IntEnum):
    """The tracker's run status: the codes ``0-3`` of :class:`pfjax.sim.status.Status`, each read from
    that member of the same name (the one table of their meanings is in :mod:`pfjax.sim.loop`)."""

    OK = Status.OK.value  #: ran the whole horizon
    NONFINITE = Status.NONFINITE.value  #: a state became NaN or infinite
    DIVERGED = Status.DIVERGED.value  #: |z~| exceeded TrackConfig.z_fail
    SINGULAR = Status.SINGULAR.value  #: |det M / (l p)| < sing_tol: the input matrix could not be inverted


TRACK_STATUS_NAMES = {int(s): s.name.lower() for s in TrackStatus}


@dataclasses.dataclass(frozen=True)
class TrackConfig:
    """Static settings of one tracking run (hashable: a jitted program's static argument). The
    defaults are those of :func:`pfjax.tracking.run`, ``pfjax track`` and the study's ``[sim]`` section
    (:class:`pfjax.tracking.study_config.TrackSim`), which read them from here."""

    dt: float = 0.01  # s
    horizon: float = 30.0  # s
    window: float = 5.0  # s, final window for the limits
    tol_z: float = 1e-2  # m
    tol_phi: float = 2e-2  # rad
    band: float = 0.1  # m, success band on |z~| over the final window
    z_fail: float = 50.0  # m
    sing_tol: float = 1e-3  # on |det M / (l p)|
    record: bool = False

    @property
    def n_steps(self) -> int:
        return int(round(self.horizon / self.dt))


class SensorNoise(NamedTuple):
    """White Gaussian noise on the follower's measured pose and steering angle: one draw per integrator
    step ``k`` and quantity from ``(key, k)`` (:func:`pfjax.numerics.random.step_normals`)."""

    sigma_pos: FloatLeaf = 0.0  # m, on x and y
    sigma_theta: FloatLeaf = 0.0  # rad
    sigma_gamma: FloatLeaf = 0.0  # rad


class TrackScenario(NamedTuple):
    params: FollowerParams
    gains: FocusGains
    leader: Leader
    init: Follower
    slip: SlipProfile
    noise: SensorNoise
    key: Array  # PRNG key for the sensor noise


class TrackMetrics(NamedTuple):
    iae: Array  # m s
    max_abs_gamma: Array  # rad
    window_max_z: Array  # m
    window_max_phi_err: Array  # rad
    final_error_norm: Array  # m
    final_phi_minus_pgamma: Array  # rad
    final_d: Array  # m
    min_abs_factor: Array  # -
    limit_fraction: Array  # -
    converged: Array  # bool, z~ -> 0 (tol_z)
    phi_converged: Array  # bool, phi - p gamma -> 0 (tol_phi)
    success: Array  # bool


class TrackTrajectory(NamedTuple):
    t: Array
    state: Follower
    zd: Array  # (n, 2)
    z_err: Array  # (n, 2)
    d: Array
    phi: Array
    v: Array
    omega: Array


class TrackResult(NamedTuple):
    final: Follower
    metrics: TrackMetrics
    status: Array  # int32
    fail_time: Array  # s, inf when OK
    trajectory: TrackTrajectory | None


def initial_state(leader: Leader, params: FollowerParams, offset=(0.0, 0.0), heading_error=0.0, gamma0=0.0) -> Follower:
    """A follower whose focus point sits on ``z_d(0)`` at ``gamma = gamma0``, then displaced.

    Heading: the leader's direction of travel (forward) or its opposite (backward, the follower
    reverses), plus ``heading_error`` (rad). ``offset`` (m) is added to ``P_b`` in the leader's
    frame (along, left of its direction of travel).
    """
    zd = position(leader, jnp.zeros(()))
    h = start_heading(leader)
    theta0 = h + jnp.where(jnp.asarray(params.f) < 0, jnp.pi, 0.0)
    g0 = jnp.asarray(gamma0, dtype=float) + 0.0 * zd[0]
    lever = focus_point(Follower(0.0 * g0, 0.0 * g0, theta0, g0), params)  # z - P_b at (theta0, gamma0)
    c, s = E.cos(h), E.sin(h)
    x = zd[0] - lever[0] + c * offset[0] - s * offset[1]
    y = zd[1] - lever[1] + s * offset[0] + c * offset[1]
    return Follower(x=x, y=y, theta=theta0 + heading_error, gamma=g0)


@jax.jit
def initial_states(leaders: Leader, params: FollowerParams, offsets: Array, heading_errors: Array) -> Follower:
    """Batched :func:`initial_state` (a leading axis on every argument; ``offsets`` is ``(n, 2)`` m).

    One compilation per batch size; far cheaper than evaluating :func:`initial_state` op by op.
    """
    return jax.vmap(lambda ld, pr, o, h: initial_state(ld, pr, offset=(o[0], o[1]), heading_error=h))(
        leaders, params, offsets, heading_errors
    )


def scenario(
    params: FollowerParams,
    leader: Leader,
    *,
    gains: FocusGains = FocusGains(),
    init: Follower | None = None,
    slip: SlipProfile | None = None,
    noise: SensorNoise = SensorNoise(),
    key=None,
) -> TrackScenario:
    """A scenario with defaults: no slip, no noise, follower placed on the leader (zero error)."""
    f = lambda v: jnp.asarray(v, dtype=float)
    params = as_arrays(params)
    return TrackScenario(
        params=params,
        gains=FocusGains(*map(f, gains)),
        leader=leader,
        init=Follower(*map(f, init if init is not None else initial_state(leader, params))),
        slip=slip if slip is not None else constant_slip(0.0, 0.0),
        noise=SensorNoise(*map(f, noise)),
        key=jax.random.PRNGKey(0) if key is None else key,
    )


class _Running(NamedTuple):
    """The running metrics (the loop's ``metrics``), after the last sample counted."""

    iae: Array  # m s, sum |z~| dt
    max_g: Array  # rad, max |gamma|
    win_z: Array  # m, max |z~| over the final window
    win_phi: Array  # rad, max |phi - p gamma| over the final window
    min_fac: Array  # -, min |det M / (l p)| (counted up to and including the failing step)
    n_lim: Array  # steps with a limit active
    z_err: Array  # m, |z~| at the last sample
    phi_err: Array  # rad, phi - p gamma at the last sample
    d: Array  # m, the connection's d at the last sample


class _Out(NamedTuple):
    """Step ``k`` as the metrics and the record read it (the state after the step, at ``t_{k+1}``)."""

    t: Array  # s, t_{k+1}
    zd: Array  # (2,) m, z_d(t_{k+1})
    err: Array  # (2,) m, z~
    enorm: Array  # m, |z~|
    conn: Connection  # phi (rad), d (m)
    phi_err: Array  # rad, phi - p gamma
    cmd: Command  # the focus-point law's command
    w: Array  # rad/s, the applied steering rate


def _start(sc: TrackScenario) -> loop.Start:
    """The follower at ``sc.init``; the metrics' last-sample values are those of ``t = 0``."""
    fz = jnp.zeros(()) + 0.0 * sc.init.x
    z0, p = sc.init, sc.params
    zd0, _ = position_velocity(sc.leader, 0.0 * fz)
    e0 = tracking_error(z0, zd0, p)
    conn0 = connection(z0, zd0, p)
    m0 = _Running(
        iae=fz,
        max_g=jnp.abs(z0.gamma),
        win_z=fz,
        win_phi=fz,
        min_fac=fz + jnp.inf,
        n_lim=fz,
        z_err=jnp.hypot(e0[0], e0[1]),
        phi_err=conn0.phi - p.p * z0.gamma,
        d=conn0.d,
    )
    return loop.Start(state=z0, metrics=m0, zero=fz)


def _step(config: TrackConfig, sc: TrackScenario, carry: loop.LoopCarry, k) -> loop.Sample:
    """Step ``k``: measure, command, RK4 to ``t_{k+1}``, then check the new state there."""
    dt, p, s, ns = config.dt, sc.params, carry.state, sc.noise
    t = k * dt
    eps = step_normals(sc.key, k, 4, carry.status.dtype)  # the run's float type (the status's)
    meas = Follower(
        s.x + ns.sigma_pos * eps[0],
        s.y + ns.sigma_pos * eps[1],
        s.theta + ns.sigma_theta * eps[2],
        s.gamma + ns.sigma_gamma * eps[3],
    )
    zd, zd_dot = position_velocity(sc.leader, t)
    cmd = focus_control(meas, zd, zd_dot, p, sc.gains, config.sing_tol)
    w = steering_stop(cmd.omega, s.gamma, p.gamma_max, dt)

    def rhs(tt, st):
        br, bf = slip_at(sc.slip, tt)
        return follower_rhs(st, cmd.v, w, br, bf, p)

    s1 = rk4_step(rhs, t, s, dt)
    s1 = s1._replace(gamma=jnp.clip(s1.gamma, -p.gamma_max, p.gamma_max))  # round-off only
    t1 = t + dt
    zd1, _ = position_velocity(sc.leader, t1)
    err = tracking_error(s1, zd1, p)
    enorm = jnp.hypot(err[0], err[1])
    conn = connection(s1, zd1, p)
    # elementwise over the state's fields and a where chain, not a reduction over a stacked short
    # axis (no vectorisation over the runs on CPU; see pfjax.numerics.layout)
    finite = all_true(jnp.isfinite(v) for v in s1)
    now = first_true(
        [~finite, enorm > config.z_fail, cmd.singular],
        [TrackStatus.NONFINITE, TrackStatus.DIVERGED, TrackStatus.SINGULAR],
        jnp.int32(TrackStatus.OK),
    )
    return loop.Sample(s1, now, t1, _Out(t1, zd1, err, enorm, conn, conn.phi - p.p * s1.gamma, cmd, w))


def _update(config: TrackConfig, sc: TrackScenario, m: _Running, s: loop.Sample, live, was_live) -> _Running:
    """Accumulate step ``k``'s metrics while the run is live (``min_fac`` also at the failing step)."""
    o = s.out
    in_win = o.t >= config.horizon - config.window - 1e-9
    limited = (o.cmd.v != o.cmd.v_cmd) | (o.w != o.cmd.omega_cmd)
    upd = partial(loop.freeze, live)  # new while live, else old
    return _Running(
        iae=upd(m.iae + o.enorm * config.dt, m.iae),
        max_g=upd(jnp.maximum(m.max_g, jnp.abs(s.state.gamma)), m.max_g),
        win_z=upd(jnp.where(in_win, jnp.maximum(m.win_z, o.enorm), m.win_z), m.win_z),
        win_phi=upd(jnp.where(in_win, jnp.maximum(m.win_phi, jnp.abs(o.phi_err)), m.win_phi), m.win_phi),
        min_fac=jnp.where(was_live, jnp.minimum(m.min_fac, jnp.abs(o.cmd.factor)), m.min_fac),
        n_lim=upd(m.n_lim + limited, m.n_lim),
        z_err=upd(o.enorm, m.z_err),
        phi_err=upd(o.phi_err, m.phi_err),
        d=upd(o.conn.d, m.d),
    )


def _record(sc: TrackScenario, s: loop.Sample, state: Follower) -> TrackTrajectory:
    o = s.out
    return TrackTrajectory(t=o.t, state=state, zd=o.zd, z_err=o.err, d=o.conn.d, phi=o.conn.phi, v=o.cmd.v, omega=o.w)


def _finish(config: TrackConfig, sc: TrackScenario, r: loop.Run) -> TrackResult:
    m, failed = r.metrics, r.failed
    nanf = lambda x: jnp.where(failed, jnp.nan, x)
    metrics = TrackMetrics(
        iae=jnp.where(failed, jnp.inf, m.iae),
        max_abs_gamma=m.max_g,
        window_max_z=nanf(m.win_z),
        window_max_phi_err=nanf(m.win_phi),
        final_error_norm=m.z_err,
        final_phi_minus_pgamma=m.phi_err,
        final_d=m.d,
        min_abs_factor=m.min_fac,
        limit_fraction=m.n_lim / config.n_steps,
        converged=~failed & (m.win_z <= config.tol_z),
        phi_converged=~failed & (m.win_phi <= config.tol_phi),
        success=~failed & (m.win_z <= config.band),
    )
    return TrackResult(final=r.state, metrics=metrics, status=r.status, fail_time=r.fail_time, trajectory=r.records)


def system(config: TrackConfig) -> loop.System:
    """The focus-point tracker as a :class:`pfjax.sim.loop.System` (inputs: a :class:`TrackScenario`)."""
    return loop.System(
        init=_start,
        step=partial(_step, config),
        update=partial(_update, config),
        record=_record,
        finish=partial(_finish, config),
        no_failure=float("inf"),
    )


def simulate(sc: TrackScenario, config: TrackConfig, *, runs: int = 1) -> TrackResult:
    """One run (see module doc); pure, for ``vmap``: steps ``k = 0..N-1`` of :func:`system` through
    :func:`pfjax.sim.loop.run` (``runs``: the runs on its device, which the
    batched entry point passes; without a checkpoint policy the loop does not use it)."""
    return loop.run(system(config), sc, config.n_steps, record=config.record, runs=runs)


#: The jitted, vmapped :func:`simulate` and the jitted single run without a batch axis
#: (:func:`pfjax.sim.batch.programs`).
_simulate_vmapped, _simulate_one = batch.programs(simulate, module=__name__, static=("config",))


def simulate_batch(
    scenarios: TrackScenario, *, config: TrackConfig, devices=None, block: int | str | None = "auto"
) -> TrackResult:
    """``jit(vmap(simulate))`` over the leading axis of every scenario leaf, sharded over ``devices``
    (default: all) and blocked on CPU (``block``: runs per block; see
    :func:`pfjax.sim.simulate.simulate_batch`). The same results, run for run, for any layout (to an ulp or two)."""
    return batch.call(_simulate_vmapped, scenarios, devices=devices, block=block, config=config)


def simulate_one(scenario: TrackScenario, *, config: TrackConfig) -> TrackResult:
    """Jitted :func:`simulate` of one run (a scenario without a batch axis) on JAX's default device:
    the numbers of that run in :func:`simulate_batch` up to rounding (tests/test_sharding.py), traced
    in less than half the time of a batch of one (:func:`pfjax.sim.batch.one_run`). ``pfjax track``
    calls it."""
    return _simulate_one(scenario, config=config)
