"""Parameters of the single-track models (CommonRoad's ST and STD): the :class:`STParams` pytree, the
named sets (CommonRoad's vehicles 1-3 and a small robot scaled from the F1TENTH car) and CommonRoad's
input constraints (steering rate and acceleration limits) that both models apply to their inputs.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import jax.numpy as jnp
from jax import Array


class STParams(NamedTuple):
    """Parameters of the single-track model (a pytree: sample, vmap, differentiate).

    CommonRoad's names in brackets (:func:`params_from_commonroad`).
    """

    l_f: Array | float  # m, centre of mass to front axle [a]
    l_r: Array | float  # m, centre of mass to rear axle [b]
    h: Array | float  # m, centre-of-mass height [h_s]
    m: Array | float  # kg, total mass [m]
    I_z: Array | float  # kg m^2, yaw moment of inertia [I_z]
    mu: Array | float  # 1, tyre-road friction coefficient [tire.p_dy1]
    C_Sf: Array | float  # 1/rad, front cornering stiffness per unit vertical load [-tire.p_ky1 / tire.p_dy1]
    C_Sr: Array | float  # 1/rad, rear cornering stiffness per unit vertical load [-tire.p_ky1 / tire.p_dy1]
    delta_min: Array | float  # rad, steering angle limits [steering.min, steering.max]
    delta_max: Array | float  # rad
    v_delta_min: Array | float  # rad/s, steering rate limits [steering.v_min, steering.v_max]
    v_delta_max: Array | float  # rad/s
    v_min: Array | float  # m/s, speed limits [longitudinal.v_min, longitudinal.v_max]
    v_max: Array | float  # m/s
    v_switch: Array | float  # m/s, above it the acceleration limit falls as a_max v_switch / v [longitudinal.v_switch]
    a_max: Array | float  # m/s^2, acceleration and braking limit [longitudinal.a_max]
    v_kinematic: Array | float = 0.1  # m/s, below it the kinematic model (CommonRoad's fixed 0.1)
    g: Array | float = 9.81  # m/s^2

    @property
    def wheelbase(self):
        """``l = l_f + l_r``, m."""
        return self.l_f + self.l_r


def params_from_commonroad(p: Any, *, mu: float | None = None) -> STParams:
    """:class:`STParams` from a CommonRoad parameter object (``parameters_vehicle1()`` ...).

    Args:
        p: a ``vehiclemodels`` ``VehicleParameters`` (anything with its attributes).
        mu: friction coefficient; default CommonRoad's ``p.tire.p_dy1``.

    Returns:
        Python floats; both cornering stiffnesses are ``-p.tire.p_ky1 / p.tire.p_dy1`` as in
        CommonRoad's ``vehicle_dynamics_st`` (``mu`` does not change them).
    """
    c_s = -float(p.tire.p_ky1) / float(p.tire.p_dy1)
    s, lon = p.steering, p.longitudinal
    return STParams(
        l_f=float(p.a),
        l_r=float(p.b),
        h=float(p.h_s),
        m=float(p.m),
        I_z=float(p.I_z),
        mu=float(p.tire.p_dy1) if mu is None else float(mu),
        C_Sf=c_s,
        C_Sr=c_s,
        delta_min=float(s.min),
        delta_max=float(s.max),
        v_delta_min=float(s.v_min),
        v_delta_max=float(s.v_max),
        v_min=float(lon.v_min),
        v_max=float(lon.v_max),
        v_switch=float(lon.v_switch),
        a_max=float(lon.a_max),
    )


#: Geometric scale from the F1TENTH car (wheelbase 0.3302 m) to the source robot (wheelbase 0.2 m).
ROBOT_SCALE = 0.2 / 0.3302


def robot_params() -> STParams:
    """A small-robot parameter set: the source robot's wheelbase (0.2 m) and steering limit (30 deg),
    the rest scaled from the F1TENTH 1/10 car (the F1TENTH gym's single-track parameters: m = 3.74 kg,
    I_z = 0.04712 kg m^2, l_f = 0.15875 m, l_r = 0.17145 m, h = 0.074 m, mu = 1.0489,
    C_Sf = 4.718 /rad, C_Sr = 5.4562 /rad, steering rate +-3.2 rad/s, v_switch = 7.319 m/s,
    a_max = 9.51 m/s^2, speeds -5..20 m/s).

    Scaling with the geometric factor ``s = 0.2 / 0.3302 = 0.606`` at equal density (Froude scaling):
    lengths ``x s`` (``l_f = 0.0962``, ``l_r = 0.1038``, ``h = 0.0448`` m), mass ``x s^3`` (0.831 kg),
    inertia ``x s^5`` (0.003841 kg m^2), speeds ``x sqrt(s)`` (``v_switch = 5.70``, limits -3.89..15.6 m/s),
    accelerations, angles, ``mu`` and the per-load cornering stiffnesses unchanged; the steering rate
    ``x 1/sqrt(s)`` (4.11 rad/s). These are assumptions of a plausible small car-like robot, not
    measurements of the source's robot (which publishes only its wheelbase, speed and slip).
    """
    s = ROBOT_SCALE
    rs = s**0.5
    return STParams(
        l_f=0.15875 * s,
        l_r=0.17145 * s,
        h=0.074 * s,
        m=3.74 * s**3,
        I_z=0.04712 * s**5,
        mu=1.0489,
        C_Sf=4.718,
        C_Sr=5.4562,
        delta_min=-0.5235987755982988,
        delta_max=0.5235987755982988,
        v_delta_min=-3.2 / rs,
        v_delta_max=3.2 / rs,
        v_min=-5.0 * rs,
        v_max=20.0 * rs,
        v_switch=7.319 * rs,
        a_max=9.51,
    )


#: CommonRoad's vehicles 1-3 (1: Ford Escort, 2: BMW 320i, 3: VW Vanagon) as :func:`params_from_commonroad`
#: reads them from ``commonroad-vehicle-models`` 3.0.2 (stored here so that studies need not install
#: it; the tests check them against it).
COMMONROAD_VEHICLES = {
    "vehicle1": STParams(
        l_f=0.88392,
        l_r=1.50876,
        h=0.59436,
        m=1225.8878467253344,
        I_z=1538.8533713561394,
        mu=1.0489,
        C_Sf=20.898083706740398,
        C_Sr=20.898083706740398,
        delta_min=-0.91,
        delta_max=0.91,
        v_delta_min=-0.4,
        v_delta_max=0.4,
        v_min=-13.9,
        v_max=45.8,
        v_switch=4.755,
        a_max=11.5,
    ),
    "vehicle2": STParams(
        l_f=1.1561957064,
        l_r=1.4227170936,
        h=0.61373004,
        m=1093.2952334674046,
        I_z=1791.5995300122856,
        mu=1.0489,
        C_Sf=20.898083706740398,
        C_Sr=20.898083706740398,
        delta_min=-1.066,
        delta_max=1.066,
        v_delta_min=-0.4,
        v_delta_max=0.4,
        v_min=-13.9,
        v_max=50.8,
        v_switch=7.319,
        a_max=11.5,
    ),
    "vehicle3": STParams(
        l_f=1.1507916024,
        l_r=1.3211363976000001,
        h=0.804490644,
        m=1478.8979637767998,
        I_z=2473.1176915564442,
        mu=1.0489,
        C_Sf=20.898083706740398,
        C_Sr=20.898083706740398,
        delta_min=-1.023,
        delta_max=1.023,
        v_delta_min=-0.4,
        v_delta_max=0.4,
        v_min=-11.2,
        v_max=41.7,
        v_switch=7.824,
        a_max=11.5,
    ),
}


def parameter_set(name: str) -> STParams:
    """A named parameter set: ``"robot"`` (:func:`robot_params`) or ``"vehicle1"``-``"vehicle3"``
    (:data:`COMMONROAD_VEHICLES`)."""
    if name == "robot":
        return robot_params()
    if name not in COMMONROAD_VEHICLES:
        from pfjax.errors import InputError

        raise InputError(f"params: expected one of {', '.join(PARAMETER_SETS)}, got {name!r}", "params")
    return COMMONROAD_VEHICLES[name]


#: The names :func:`parameter_set` takes.
PARAMETER_SETS = ("robot", *COMMONROAD_VEHICLES)


def steering_rate(delta: Array, v_delta: Array, p: STParams) -> Array:
    """CommonRoad's ``steering_constraints``: the steering rate (rad/s) held at 0 at an angle limit
    when it pushes further, else clipped to ``[v_delta_min, v_delta_max]``."""
    at_limit = ((delta <= p.delta_min) & (v_delta <= 0)) | ((delta >= p.delta_max) & (v_delta >= 0))
    clipped = jnp.where(
        v_delta <= p.v_delta_min, p.v_delta_min, jnp.where(v_delta >= p.v_delta_max, p.v_delta_max, v_delta)
    )
    return jnp.where(at_limit, jnp.zeros_like(v_delta), clipped)


def acceleration(v: Array, a: Array, p: STParams) -> Array:
    """CommonRoad's ``acceleration_constraints``: 0 at a speed limit when pushing further, braking
    limited to ``-a_max``, driving to ``a_max`` up to ``v_switch`` and ``a_max v_switch / v`` above
    (constant power), m/s^2."""
    fast = v > p.v_switch
    pos_limit = jnp.where(fast, p.a_max * p.v_switch / jnp.where(fast, v, 1.0), p.a_max)
    at_limit = ((v <= p.v_min) & (a <= 0)) | ((v >= p.v_max) & (a >= 0))
    clipped = jnp.where(a <= -p.a_max, -p.a_max, jnp.where(a >= pos_limit, pos_limit, a))
    return jnp.where(at_limit, jnp.zeros_like(a), clipped)
