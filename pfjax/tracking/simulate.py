"""One tracking run as one ``lax.scan``; ``simulate_batch`` is its jit(vmap), sharded over every
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
from typing import NamedTuple

import jax
import jax.numpy as jnp
from jax import Array

from pfjax.numerics import compiler
from pfjax.numerics import elementary as E
from pfjax.numerics.layout import all_true, first_true
from pfjax.numerics.random import step_normals

from pfjax.sim import sharding
from pfjax.sim.integrators import rk4_step
from pfjax.sim.simulate import stack, unstack  # noqa: F401  (re-exported: a batch of runs, run i of a batch)
from pfjax.sim.slip_profiles import SlipProfile, constant_slip, slip_at
from pfjax.sim.status import first_failure
from pfjax.tracking.controller import FocusGains, focus_control, steering_stop
from pfjax.tracking.geometry import connection, focus_point, tracking_error
from pfjax.tracking.leader import Leader, position, position_velocity, start_heading
from pfjax.tracking.model import Follower, FollowerParams, as_arrays, follower_rhs


class TrackStatus(IntEnum):
    OK = 0  #: ran the whole horizon
    NONFINITE = 1  #: a state became NaN or infinite
    DIVERGED = 2  #: |z~| exceeded TrackConfig.z_fail
    SINGULAR = 3  #: |det M / (l p)| < sing_tol: the input matrix could not be inverted


TRACK_STATUS_NAMES = {int(s): s.name.lower() for s in TrackStatus}


@dataclasses.dataclass(frozen=True)
class TrackConfig:
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

    sigma_pos: Array | float = 0.0  # m, on x and y
    sigma_theta: Array | float = 0.0  # rad
    sigma_gamma: Array | float = 0.0  # rad


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


def initial_state(leader: Leader, params: FollowerParams, offset=(0.0, 0.0), heading_error=0.0,
                  gamma0=0.0) -> Follower:
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
        leaders, params, offsets, heading_errors)


def scenario(params: FollowerParams, leader: Leader, *, gains: FocusGains = FocusGains(), init: Follower | None = None,
             slip: SlipProfile | None = None, noise: SensorNoise = SensorNoise(), key=None) -> TrackScenario:
    """A scenario with defaults: no slip, no noise, follower placed on the leader (zero error)."""
    f = lambda v: jnp.asarray(v, dtype=float)  # noqa: E731
    params = as_arrays(params)
    return TrackScenario(
        params=params, gains=FocusGains(*map(f, gains)), leader=leader,
        init=Follower(*map(f, init if init is not None else initial_state(leader, params))),
        slip=slip if slip is not None else constant_slip(0.0, 0.0),
        noise=SensorNoise(*map(f, noise)), key=jax.random.PRNGKey(0) if key is None else key,
    )


class _Carry(NamedTuple):
    s: Follower
    status: Array
    fail_time: Array
    iae: Array
    max_g: Array
    win_z: Array
    win_phi: Array
    min_fac: Array
    n_lim: Array
    z_err: Array
    phi_err: Array
    d: Array


def simulate(sc: TrackScenario, config: TrackConfig) -> TrackResult:
    """One run (see module doc); pure, for ``vmap``."""
    dt, n = config.dt, config.n_steps
    p = sc.params
    fz = jnp.zeros(()) + 0.0 * sc.init.x

    def rhs_for(v, w):
        def rhs(t, s):
            br, bf = slip_at(sc.slip, t)
            return follower_rhs(s, v, w, br, bf, p)
        return rhs

    def step(c: _Carry, k):
        t = k * dt
        eps = step_normals(sc.key, k, 4, fz.dtype)
        ns = sc.noise
        meas = Follower(c.s.x + ns.sigma_pos * eps[0], c.s.y + ns.sigma_pos * eps[1],
                        c.s.theta + ns.sigma_theta * eps[2], c.s.gamma + ns.sigma_gamma * eps[3])
        zd, zd_dot = position_velocity(sc.leader, t)
        cmd = focus_control(meas, zd, zd_dot, p, sc.gains, config.sing_tol)
        w = steering_stop(cmd.omega, c.s.gamma, p.gamma_max, dt)
        s1 = rk4_step(rhs_for(cmd.v, w), t, c.s, dt)
        s1 = s1._replace(gamma=jnp.clip(s1.gamma, -p.gamma_max, p.gamma_max))  # round-off only
        zd1, _ = position_velocity(sc.leader, t + dt)
        err = tracking_error(s1, zd1, p)
        enorm = jnp.hypot(err[0], err[1])
        conn = connection(s1, zd1, p)
        phi_err = conn.phi - p.p * s1.gamma
        # elementwise over the state's fields and a where chain, not a reduction over a stacked short
        # axis (no vectorisation over the runs on CPU; see pfjax.numerics.layout)
        finite = all_true(jnp.isfinite(v) for v in s1)
        now = first_true([~finite, enorm > config.z_fail, cmd.singular], [1, 2, 3], jnp.int32(0))
        ok = c.status == 0
        status, fail_time = first_failure(c.status, c.fail_time, now, t + dt)  # status: a float code
        live = status == 0
        in_win = (t + dt) >= config.horizon - config.window - 1e-9
        limited = (cmd.v != cmd.v_cmd) | (w != cmd.omega_cmd)
        upd = lambda new, old: jnp.where(live, new, old)  # noqa: E731
        c2 = _Carry(
            s=jax.tree_util.tree_map(upd, s1, c.s),
            status=status,
            fail_time=fail_time,
            iae=upd(c.iae + enorm * dt, c.iae),
            max_g=upd(jnp.maximum(c.max_g, jnp.abs(s1.gamma)), c.max_g),
            win_z=upd(jnp.where(in_win, jnp.maximum(c.win_z, enorm), c.win_z), c.win_z),
            win_phi=upd(jnp.where(in_win, jnp.maximum(c.win_phi, jnp.abs(phi_err)), c.win_phi), c.win_phi),
            min_fac=jnp.where(ok, jnp.minimum(c.min_fac, jnp.abs(cmd.factor)), c.min_fac),
            n_lim=upd(c.n_lim + limited, c.n_lim),
            z_err=upd(enorm, c.z_err), phi_err=upd(phi_err, c.phi_err), d=upd(conn.d, c.d),
        )
        rec = None
        if config.record:
            rec = (t + dt, c2.s, zd1, err, conn.d, conn.phi, cmd.v, w)
        return c2, rec

    z0 = sc.init
    zd0, _ = position_velocity(sc.leader, 0.0 * fz)
    e0 = tracking_error(z0, zd0, p)
    conn0 = connection(z0, zd0, p)
    c0 = _Carry(s=z0, status=fz, fail_time=fz + jnp.inf, iae=fz, max_g=jnp.abs(z0.gamma),
                win_z=fz, win_phi=fz, min_fac=fz + jnp.inf, n_lim=fz, z_err=jnp.hypot(e0[0], e0[1]),
                phi_err=conn0.phi - p.p * z0.gamma, d=conn0.d)
    cN, rec = jax.lax.scan(step, c0, jnp.arange(n))
    failed = cN.status != 0
    nanf = lambda x: jnp.where(failed, jnp.nan, x)  # noqa: E731
    win_z, win_phi = nanf(cN.win_z), nanf(cN.win_phi)
    metrics = TrackMetrics(
        iae=jnp.where(failed, jnp.inf, cN.iae), max_abs_gamma=cN.max_g, window_max_z=win_z, window_max_phi_err=win_phi,
        final_error_norm=cN.z_err, final_phi_minus_pgamma=cN.phi_err, final_d=cN.d, min_abs_factor=cN.min_fac,
        limit_fraction=cN.n_lim / n,
        converged=~failed & (cN.win_z <= config.tol_z), phi_converged=~failed & (cN.win_phi <= config.tol_phi),
        success=~failed & (cN.win_z <= config.band),
    )
    traj = None
    if config.record:
        t, st, zd, err, d, phi, v, w = rec
        traj = TrackTrajectory(t=t, state=st, zd=zd, z_err=err, d=d, phi=phi, v=v, omega=w)
    return TrackResult(final=cN.s, metrics=metrics, status=cN.status.astype(jnp.int32), fail_time=cN.fail_time, trajectory=traj)


@compiler.jit(static_argnames=("config", "layout"))
def _simulate_vmapped(scenarios: TrackScenario, *, config: TrackConfig,
                      layout: sharding.Layout = sharding.Layout(None, 1)) -> TrackResult:
    return sharding.map_runs(lambda sc: simulate(sc, config), scenarios, layout)


def simulate_batch(scenarios: TrackScenario, *, config: TrackConfig, devices=None,
                   block: int | None | str = "auto") -> TrackResult:
    """``jit(vmap(simulate))`` over the leading axis of every scenario leaf, sharded over ``devices``
    (default: all) and blocked on CPU (``block``: runs per block; see
    :func:`pfjax.sim.simulate.simulate_batch`). The same results, run for run, for any layout (to an ulp or two)."""
    placed, n, layout = sharding.plan_batch(scenarios, devices, block)
    return sharding.unpad(_simulate_vmapped(placed, config=config, layout=layout), n)


simulate_batch._cache_size = _simulate_vmapped._cache_size  # the jitted core's compilation count
