"""Single-track drift model: CommonRoad's STD model (Pacejka tyres, wheel speeds) as a pure JAX vector field.

State and input are CommonRoad's ``vehicle_dynamics_std`` (``commonroad-vehicle-models`` 3.0.2,
version 2020a), in its order and units::

    x = (sx, sy, delta, v, psi, psi_dot, beta, omega_f, omega_r)   m, m, rad, m/s, rad, rad/s, rad, rad/s, rad/s
    u = (v_delta, a_long)                                          rad/s, m/s^2

the ST model's seven states (:mod:`pfjax.models.single_track`) and the front and rear wheels' angular
speeds. The inputs pass CommonRoad's constraints (:func:`~pfjax.models.single_track_params.steering_rate`,
:func:`~pfjax.models.single_track_params.acceleration`), giving ``v_delta`` and ``a``. With
``l = l_f + l_r``, wheel radius ``R_w``, wheel inertia ``I_w``, and above ``v_min = 0.1`` m/s (below it
the slip angles and ``beta'`` are 0)::

    alpha_f = atan((v sin beta + l_f psi_dot) / (v cos beta)) - delta      tyre slip angles, rad
    alpha_r = atan((v sin beta - l_r psi_dot) / (v cos beta))
    F_zf = m (g l_r - a h) / l,   F_zr = m (g l_f + a h) / l                vertical loads, N
    u_wf = max(0, v cos beta cos delta + (v sin beta + l_f psi_dot) sin delta),   u_wr = max(0, v cos beta)
    s_i  = 1 - R_w omega_i / max(u_wi, v_min)                               longitudinal slip
    F_xi, F_yi = Pacejka's combined-slip forces (pfjax.models.tyres) at (s_i, alpha_i, F_zi)
    v'       = [-F_yf sin(delta - beta) + F_yr sin beta + F_xr cos beta + F_xf cos(delta - beta)] / m
    psi_dot' = [F_yf cos(delta) l_f - F_yr l_r + F_xf sin(delta) l_f] / I_z
    beta'    = -psi_dot + [F_yf cos(delta - beta) + F_yr cos beta - F_xr sin beta + F_xf sin(delta - beta)] / (m v)
    omega_f' = [-R_w F_xf + T_sb T_B + T_se T_E] / I_w       (0 if omega_f < 0)
    omega_r' = [-R_w F_xr + (1 - T_sb) T_B + (1 - T_se) T_E] / I_w

with the acceleration input as engine torque ``T_E = m R_w a`` (``a > 0``) or brake torque
``T_B = m R_w a`` (``a <= 0``) split between the axles by ``T_se``, ``T_sb``. At low speed the model
blends with the kinematic single-track model at the centre of mass (the ST model's kinematic branch,
with wheel speeds relaxing to rolling, ``omega_i' = (u_wi / R_w - max(0, omega_i)) / 0.02 s``) by the
weight ``w = (tanh((v - 0.2) / 0.05) + 1) / 2`` on the dynamic terms (1 - w on the kinematic):
``v'``, ``psi'``, ``psi_dot'``, ``beta'`` and the wheel speeds' derivatives; ``sx' = v cos(psi + beta)``,
``sy' = v sin(psi + beta)``, ``delta' = v_delta`` are not blended. These are CommonRoad's expressions
(its blend speeds fixed at 0.2 and 0.05 m/s), tested against it to 1e-9 relative.

The friction coefficient ``mu`` (:class:`~pfjax.models.single_track_params.STParams`' field) scales
both of the tyre's peak coefficients: ``mu_y = mu``, ``mu_x = p_dx1 mu / p_dy1``; at CommonRoad's
``mu = p_dy1`` they are its own. Unlike the ST model's linear tyres, the lateral force saturates near
``mu F_z``: the car can skid.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

from pfjax.models import tyres
from pfjax.models.single_track_params import (
    COMMONROAD_VEHICLES,
    STParams,
    acceleration,
    params_from_commonroad,
    steering_rate,
)
from pfjax.numerics import elementary as E

#: Names of the drift model's state vector's entries, in CommonRoad's order.
DRIFT_STATE_NAMES = ("sx", "sy", "delta", "v", "psi", "psi_dot", "beta", "omega_f", "omega_r")
V_BLEND = 0.2  # m/s, centre of the blend between the kinematic and the dynamic model (CommonRoad's v_s)
V_BLEND_WIDTH = 0.05  # m/s, its width (CommonRoad's v_b)
V_MIN = 0.1  # m/s, below it no tyre slip angles and beta' = 0 in the dynamic terms (CommonRoad's v_s / 2)
WHEEL_RELAX = 0.02  # s, the wheel speeds' time constant towards rolling in the kinematic terms


class STDParams(NamedTuple):
    """Parameters of the drift model (a pytree): the ST model's and the wheels' and tyre's."""

    body: STParams  # geometry, mass, inertia, friction mu, constraints (C_Sf, C_Sr unused)
    R_w: Array | float  # m, wheel radius [R_w]
    I_w: Array | float  # kg m^2, wheel's moment of inertia about its axle [I_y_w]
    T_sb: Array | float  # 1, brake torque fraction on the front axle [T_sb]
    T_se: Array | float  # 1, engine torque fraction on the front axle [T_se]
    tyre: tyres.PacejkaParams  # magic-formula coefficients [tire]


class STDState(NamedTuple):
    """The drift model's state as named scalars (CommonRoad's vector ``x`` in this order)."""

    sx: Array  # m, centre of mass
    sy: Array  # m
    delta: Array  # rad, front steering angle
    v: Array  # m/s, speed of the centre of mass
    psi: Array  # rad, yaw angle
    psi_dot: Array  # rad/s, yaw rate
    beta: Array  # rad, slip angle at the centre of mass
    omega_f: Array  # rad/s, front wheel's angular speed
    omega_r: Array  # rad/s, rear wheel's angular speed


def drift_params_from_commonroad(p: Any, *, mu: float | None = None) -> STDParams:
    """:class:`STDParams` from a CommonRoad parameter object (``parameters_vehicle2()`` ...); ``mu``
    defaults to CommonRoad's ``p.tire.p_dy1`` (:func:`~pfjax.models.single_track_params.params_from_commonroad`)."""
    return STDParams(
        body=params_from_commonroad(p, mu=mu),
        R_w=float(p.R_w),
        I_w=float(p.I_y_w),
        T_sb=float(p.T_sb),
        T_se=float(p.T_se),
        tyre=tyres.pacejka_from_commonroad(p.tire),
    )


#: CommonRoad's vehicles 1-3 for the drift model (wheel radius 0.344 m, wheel inertia 1.7 kg m^2; torque
#: split ``T_sb``, ``T_se``: 0.76, 1.0 for vehicle 1, 0.66, 0.0 and 0.64, 0.0 for 2 and 3), as
#: ``commonroad-vehicle-models`` 3.0.2 stores them (the tests check them against it). The robot set has
#: no drift parameters: its source (the F1TENTH car) publishes no magic-formula tyre.
COMMONROAD_DRIFT_VEHICLES = {
    name: STDParams(COMMONROAD_VEHICLES[name], 0.344, 1.7, t_sb, t_se, tyres.COMMONROAD_TYRE)
    for name, t_sb, t_se in (("vehicle1", 0.76, 1.0), ("vehicle2", 0.66, 0.0), ("vehicle3", 0.64, 0.0))
}


def drift_parameter_set(name: str) -> STDParams:
    """A named drift parameter set, ``"vehicle1"``-``"vehicle3"`` (:data:`COMMONROAD_DRIFT_VEHICLES`)."""
    if name not in COMMONROAD_DRIFT_VEHICLES:
        from pfjax.errors import InputError

        sets = ", ".join(COMMONROAD_DRIFT_VEHICLES)
        raise InputError(f'params: model "std" has the sets {sets}, got {name!r}', "params")
    return COMMONROAD_DRIFT_VEHICLES[name]


def _tyre_forces(s, alpha, f_z, mu_x, mu_y, t: tyres.PacejkaParams) -> tuple[Array, Array]:
    """Combined-slip ``(F_x, F_y)`` (N) of one axle's tyre."""
    f_x = tyres.longitudinal_combined(s, alpha, tyres.longitudinal(s, f_z, mu_x, t), t)
    f_y = tyres.lateral_combined(s, alpha, tyres.lateral(alpha, f_z, mu_y, t), f_z, mu_y, t)
    return f_x, f_y


def vector_field_drift(x: STDState, v_delta: Array, a_long: Array, params: STDParams) -> STDState:
    """The drift model's vector field on named scalars (module docstring's equations); :func:`rhs_drift`
    is the same on CommonRoad's vectors.

    Args:
        x: the state (m, m, rad, m/s, rad, rad/s, rad, rad/s, rad/s).
        v_delta: steering rate input, rad/s; a_long: longitudinal acceleration input, m/s^2 (both
            before the constraints).
        params: :class:`STDParams`.

    Returns:
        ``x'`` as an :class:`STDState` (each field's unit per second).
    """
    p, t = params.body, params.tyre
    delta, v, psi_dot, beta = x.delta, x.v, x.psi_dot, x.beta
    v_delta = steering_rate(delta, v_delta, p)
    a = acceleration(v, a_long, p)
    lf, lr, m = p.l_f, p.l_r, p.m
    inv_l = 1 / (lf + lr)
    moving = v > V_MIN
    sin_b, cos_b = E.sincos(beta)
    sin_d, cos_d = E.sincos(delta)
    vx = v * cos_b  # m/s, the body's longitudinal velocity
    vx_safe = jnp.where(moving, vx, jnp.ones_like(vx))
    zero = jnp.zeros_like(v)
    alpha_f = jnp.where(moving, E.atan((v * sin_b + psi_dot * lf) / vx_safe) - delta, zero)
    alpha_r = jnp.where(moving, E.atan((v * sin_b - psi_dot * lr) / vx_safe), zero)
    f_zf = m * (-a * p.h + p.g * lr) * inv_l
    f_zr = m * (a * p.h + p.g * lf) * inv_l
    u_wf = jnp.maximum(0.0, vx * cos_d + (v * sin_b + lf * psi_dot) * sin_d)
    u_wr = jnp.maximum(0.0, vx)
    s_f = 1 - params.R_w * x.omega_f / jnp.maximum(u_wf, V_MIN)
    s_r = 1 - params.R_w * x.omega_r / jnp.maximum(u_wr, V_MIN)
    mu_y = p.mu
    mu_x = t.p_dx1 * p.mu / t.p_dy1
    f_xf, f_yf = _tyre_forces(s_f, alpha_f, f_zf, mu_x, mu_y, t)
    f_xr, f_yr = _tyre_forces(s_r, alpha_r, f_zr, mu_x, mu_y, t)
    torque = m * params.R_w * a  # N m, engine (a > 0) or brake (a <= 0) torque
    t_b, t_e = jnp.where(a > 0, zero, torque), jnp.where(a > 0, torque, zero)
    # sin(delta - beta), cos(delta - beta) by the angle-difference formulas
    s_db, c_db = sin_d * cos_b - cos_d * sin_b, cos_d * cos_b + sin_d * sin_b
    d_v = (-f_yf * s_db + f_yr * sin_b + f_xr * cos_b + f_xf * c_db) / m
    dd_psi = (f_yf * cos_d * lf - f_yr * lr + f_xf * sin_d * lf) / p.I_z
    inv_mv = 1 / (m * jnp.where(moving, v, jnp.ones_like(v)))
    d_beta = jnp.where(moving, -psi_dot + inv_mv * (f_yf * c_db + f_yr * cos_b - f_xr * sin_b + f_xf * s_db), zero)
    d_om_f = jnp.where(x.omega_f >= 0, (-params.R_w * f_xf + params.T_sb * t_b + params.T_se * t_e) / params.I_w, zero)
    d_om_r = jnp.where(
        x.omega_r >= 0, (-params.R_w * f_xr + (1 - params.T_sb) * t_b + (1 - params.T_se) * t_e) / params.I_w, zero
    )
    # the kinematic terms at the centre of mass (the ST model's kinematic branch)
    sec2_d = 1 / (cos_d * cos_d)
    tan_d = sin_d * cos_d * sec2_d
    tk = tan_d * lr * inv_l  # tan(beta_ks)
    d_psi_ks = v * E.rsqrt(1 + tk * tk) * tan_d * inv_l
    d_beta_ks = lr * v_delta * inv_l * sec2_d / (1 + (tan_d * tk) ** 2)
    dd_psi_ks = inv_l * (a * cos_b * tan_d - v * sin_b * d_beta_ks * tan_d + v * cos_b * v_delta * sec2_d)
    d_om_f_ks = (u_wf / params.R_w - jnp.maximum(0.0, x.omega_f)) / WHEEL_RELAX
    d_om_r_ks = (u_wr / params.R_w - jnp.maximum(0.0, x.omega_r)) / WHEEL_RELAX
    w = 0.5 * (jnp.tanh((v - V_BLEND) / V_BLEND_WIDTH) + 1)
    blend = lambda dyn, ks: w * dyn + (1 - w) * ks
    sin_p, cos_p = E.sincos(x.psi)
    return STDState(
        sx=v * (cos_p * cos_b - sin_p * sin_b),
        sy=v * (sin_p * cos_b + cos_p * sin_b),
        delta=v_delta,
        v=blend(d_v, a),
        psi=blend(psi_dot, d_psi_ks),
        psi_dot=blend(dd_psi, dd_psi_ks),
        beta=blend(d_beta, d_beta_ks),
        omega_f=blend(d_om_f, d_om_f_ks),
        omega_r=blend(d_om_r, d_om_r_ks),
    )


def rhs_drift(x: Array, u: Array, params: STDParams) -> Array:
    """The drift model's vector field ``x' = f(x, u, params)`` on CommonRoad's vectors (module
    docstring; :func:`vector_field_drift` on named scalars).

    Args:
        x: state ``(sx, sy, delta, v, psi, psi_dot, beta, omega_f, omega_r)``, shape ``(9,)``.
        u: input ``(v_delta, a_long)``, shape ``(2,)`` (rad/s, m/s^2), before the constraints.
        params: :class:`STDParams`.

    Returns:
        ``x'``, shape ``(9,)``, in the state's units per second.
    """
    return jnp.stack(vector_field_drift(STDState(*(x[i] for i in range(9))), u[0], u[1], params))


def rolling_state(sx, sy, psi, v, params: STDParams) -> STDState:
    """A drift state driving straight at ``v`` (m/s) with its wheels rolling (``omega = v / R_w``)."""
    zero = jnp.zeros_like(jnp.asarray(v, float))
    om = zero + v / params.R_w
    return STDState(zero + sx, zero + sy, zero, zero + v, zero + psi, zero, zero, om, om)


def drift_tyre_slip(x: STDState, params: STDParams) -> tuple[Array, Array, Array]:
    """The slip angles the drift model's tyres see, in pfjax's kinematic slip model's ``SOURCE``
    convention (as :func:`pfjax.models.single_track.tyre_slip`), rad: ``(beta_r, beta_f, beta)`` with
    ``beta_r = alpha_r`` (the rear axle's velocity angle to the body) and ``beta_f = -alpha_f`` (the
    front wheel's angle to its velocity), the model's exact (arctangent) slip angles; 0 at or below
    ``V_MIN``."""
    p = params.body
    moving = x.v > V_MIN
    sin_b, cos_b = E.sincos(x.beta)
    vx = jnp.where(moving, x.v * cos_b, jnp.ones_like(x.v))
    zero = jnp.zeros_like(x.v)
    beta_r = jnp.where(moving, E.atan((x.v * sin_b - x.psi_dot * p.l_r) / vx), zero)
    beta_f = jnp.where(moving, x.delta - E.atan((x.v * sin_b + x.psi_dot * p.l_f) / vx), zero)
    return beta_r, beta_f, x.beta


def drift_modes(params: STDParams, v: float) -> np.ndarray:
    """Eigenvalues (1/s) of the drift model linearised about straight driving at ``v`` (m/s), wheels
    rolling, no input (host code: a forward-mode Jacobian of :func:`rhs_drift` in the states ``v``,
    ``psi_dot``, ``beta``, ``omega_f``, ``omega_r``). The wheel-speed modes, ``~ -R_w^2 p_kx1 F_z /
    (I_w v)``, are the fastest: hundreds of 1/s for the cars at 10 m/s."""
    p = jax.tree_util.tree_map(float, params)
    x0 = jnp.asarray(rolling_state(0.0, 0.0, 0.0, float(v), p), float)
    jac = np.asarray(jax.jacfwd(lambda x: rhs_drift(x, jnp.zeros(2, x.dtype), p))(x0), float)
    idx = [3, 5, 6, 7, 8]
    return np.linalg.eigvals(jac[np.ix_(idx, idx)])
