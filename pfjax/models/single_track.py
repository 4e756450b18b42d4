"""Dynamic single-track (bicycle) model with linear tyres: CommonRoad's ST model as a pure JAX vector field.

State and input are CommonRoad's, in its order and units (CommonRoad vehicle models, ST model;
M. Althoff, M. Koschi, S. Manzinger, "CommonRoad: Composable benchmarks for motion planning on roads",
IEEE IV 2017, doi:10.1109/IVS.2017.7995802)::

    x = (sx, sy, delta, v, psi, psi_dot, beta)    m, m, rad, m/s, rad, rad/s, rad
    u = (v_delta, a_long)                         rad/s, m/s^2

``(sx, sy)`` is the centre of mass, ``delta`` the front steering angle, ``v`` the speed of the centre
of mass, ``psi`` the yaw angle, ``beta`` the slip angle at the centre of mass (the velocity's angle to
the body axis). The inputs first pass CommonRoad's constraints (:func:`steering_rate` and
:func:`acceleration`). With ``l = l_f + l_r``, the axle loads per unit mass (load transfer through the
centre-of-mass height ``h``) ``F_f = g l_r - a h`` and ``F_r = g l_f + a h`` (m^2/s^2, times ``m / l``
the vertical forces in N), and linear tyres whose lateral force is ``mu C_S F_z alpha`` (``C_S``:
cornering stiffness per unit vertical load, 1/rad), the dynamic branch (``|v| >= v_kinematic``) is::

    sx'      = v cos(psi + beta)
    sy'      = v sin(psi + beta)
    delta'   = v_delta
    v'       = a
    psi'     = psi_dot
    psi_dot' = mu m / (I_z l) [ -(l_f^2 C_Sf F_f + l_r^2 C_Sr F_r) psi_dot / v
                                + (l_r C_Sr F_r - l_f C_Sf F_f) beta + l_f C_Sf F_f delta ]
    beta'    = [mu (C_Sr F_r l_r - C_Sf F_f l_f) / (v^2 l) - 1] psi_dot
               - mu (C_Sr F_r + C_Sf F_f) beta / (v l) + mu C_Sf F_f delta / (v l)

(the tyre slip angles are linearised: front ``alpha_f = delta - beta - l_f psi_dot / v``, rear
``alpha_r = -beta + l_r psi_dot / v``). Below ``v_kinematic`` (0.1 m/s in CommonRoad) the dynamic
branch is singular in ``1/v`` and the model switches to the kinematic single-track model at the centre
of mass, with ``beta_ks = atan(tan(delta) l_r / l)``::

    sx'      = v cos(psi + beta_ks),   sy' = v sin(psi + beta_ks),   delta' = v_delta,   v' = a
    psi'     = v cos(beta_ks) tan(delta) / l
    beta'    = l_r v_delta / (l cos^2(delta) (1 + (tan^2(delta) l_r / l)^2))
    psi_dot' = [a cos(beta) tan(delta) - v sin(beta) beta' tan(delta) + v cos(beta) v_delta / cos^2(delta)] / l

These are CommonRoad's expressions exactly (``vehicle_dynamics_st``, version 2020a in
``commonroad-vehicle-models`` 3.0.2), including the state's ``beta`` (not ``beta_ks``) in ``psi_dot'``;
the tests check agreement with it to 1e-9 relative. Gravity ``g = 9.81`` m/s^2 as in CommonRoad.

:func:`rhs` is NaN-safe for differentiation: the branch not taken never divides by zero.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import jax.numpy as jnp
import numpy as np
from jax import Array

from pfjax.numerics import elementary as E

#: Names of the state vector's entries, in CommonRoad's order.
STATE_NAMES = ("sx", "sy", "delta", "v", "psi", "psi_dot", "beta")
#: Names of the input vector's entries.
INPUT_NAMES = ("v_delta", "a_long")


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
    inertia ``x s^5`` (0.00383 kg m^2), speeds ``x sqrt(s)`` (``v_switch = 5.70``, limits -3.89..15.6 m/s),
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


#: ``|lambda| dt`` up to which a fixed RK4 step is taken as stable for the model's modes (RK4's
#: stability region reaches 2.785 on the negative real axis and about 2.8 along the imaginary one).
RK4_REACH = 2.5


def lateral_eigenvalues(params: STParams, v: float) -> np.ndarray:
    """Eigenvalues (1/s) of the dynamic branch's lateral-yaw dynamics in ``(psi_dot, beta)`` at speed
    ``v`` (m/s) without longitudinal acceleration (``a = 0``; host code, NumPy)::

        A = [[-k (l_f^2 C_Sf F_f + l_r^2 C_Sr F_r) / v,            k (l_r C_Sr F_r - l_f C_Sf F_f)],
             [mu (l_r C_Sr F_r - l_f C_Sf F_f) / (v^2 l) - 1,      -mu (C_Sf F_f + C_Sr F_r) / (v l)]]

    with ``F_f = g l_r``, ``F_r = g l_f``, ``k = mu m / (I_z l)``. Their magnitude grows as ``mu / v``:
    the tyres' time constants are short at high friction and low speed.
    """
    p = STParams(*(float(np.asarray(a)) for a in params))
    l = p.l_f + p.l_r
    cf, cr = p.C_Sf * p.g * p.l_r, p.C_Sr * p.g * p.l_f
    k = p.mu * p.m / (p.I_z * l)
    a = np.array(
        [
            [-k * (p.l_f**2 * cf + p.l_r**2 * cr) / v, k * (p.l_r * cr - p.l_f * cf)],
            [p.mu * (cr * p.l_r - cf * p.l_f) / (v**2 * l) - 1, -p.mu * (cr + cf) / (v * l)],
        ]
    )
    return np.linalg.eigvals(a)


def max_stable_step(params: STParams, v: float, tau_delta: float = math.inf, k_v: float = 0.0) -> float:
    """The largest RK4 step (s) for which ``|lambda| dt <= RK4_REACH`` for the lateral-yaw modes at
    speed ``v`` (:func:`lateral_eigenvalues`), a first-order steering actuator (``lambda = -1 /
    tau_delta``) and a proportional speed loop (``lambda = -k_v``). A step beyond it lets the
    integration blow up (a run then fails as ``diverged`` or ``nonfinite``)."""
    fastest = max(float(np.max(np.abs(lateral_eigenvalues(params, v)))), 1 / tau_delta, k_v)
    return RK4_REACH / fastest


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


class STState(NamedTuple):
    """The ST model's state as named scalars (CommonRoad's vector ``x`` in this order)."""

    sx: Array  # m, centre of mass
    sy: Array  # m
    delta: Array  # rad, front steering angle
    v: Array  # m/s, speed of the centre of mass
    psi: Array  # rad, yaw angle
    psi_dot: Array  # rad/s, yaw rate
    beta: Array  # rad, slip angle at the centre of mass


def vector_field(x: STState, v_delta: Array, a_long: Array, params: STParams) -> STState:
    """The ST model's vector field on named scalars (module docstring's equations): what the
    simulator integrates (a batch of runs keeps each field a contiguous vector). :func:`rhs` is the
    same on CommonRoad's vectors.

    Args:
        x: the state (m, m, rad, m/s, rad, rad/s, rad).
        v_delta: steering rate input, rad/s; a_long: longitudinal acceleration input, m/s^2 (both
            before the constraints).
        params: :class:`STParams`.

    Returns:
        ``x'`` as an :class:`STState` (each field's unit per second).
    """
    p = params
    delta, v, psi_dot, beta = x.delta, x.v, x.psi_dot, x.beta
    v_delta = steering_rate(delta, v_delta, p)
    a = acceleration(v, a_long, p)
    lf, lr, h, g, mu = p.l_f, p.l_r, p.h, p.g, p.mu
    l = lf + lr  # m, the wheelbase
    slow = jnp.abs(v) < p.v_kinematic
    # dynamic branch (CommonRoad's terms), with v replaced by 1 where it is not taken; the divisions
    # by v, l, I_z and cos(delta) as multiplications by their reciprocals (one division each)
    inv_v = 1 / jnp.where(slow, jnp.ones_like(v), v)
    inv_l = 1 / l
    ff = g * lr - a * h  # front load per unit mass, m^2/s^2 (times m / l: N)
    fr = g * lf + a * h  # rear
    cf, cr = p.C_Sf * ff, p.C_Sr * fr
    k = mu * p.m / p.I_z * inv_l
    dd_psi_dyn = -k * inv_v * (lf**2 * cf + lr**2 * cr) * psi_dot + k * (lr * cr - lf * cf) * beta + k * lf * cf * delta
    mu_vl = mu * inv_v * inv_l
    d_beta_dyn = (mu_vl * inv_v * (cr * lr - cf * lf) - 1) * psi_dot - mu_vl * (cr + cf) * beta + mu_vl * cf * delta
    # kinematic branch at the centre of mass: beta_ks = atan(t), cos beta_ks = 1/sqrt(1 + t^2)
    sin_d, cos_d = E.sincos(delta)
    sec2_d = 1 / (cos_d * cos_d)  # 1 / cos^2(delta)
    tan_d = sin_d * cos_d * sec2_d
    sin_b, cos_b = E.sincos(beta)
    t = tan_d * lr * inv_l
    cos_ks = E.rsqrt(1 + t * t)
    d_beta_ks = lr * v_delta * inv_l * sec2_d / (1 + (tan_d * t) ** 2)
    dd_psi_ks = inv_l * (a * cos_b * tan_d - v * sin_b * d_beta_ks * tan_d + v * cos_b * v_delta * sec2_d)
    # the velocity's direction psi + (beta_ks or beta), by the angle-sum formulas
    sin_p, cos_p = E.sincos(x.psi)
    cb, sb = jnp.where(slow, cos_ks, cos_b), jnp.where(slow, t * cos_ks, sin_b)
    return STState(
        sx=v * (cos_p * cb - sin_p * sb),
        sy=v * (sin_p * cb + cos_p * sb),
        delta=v_delta,
        v=a,
        psi=jnp.where(slow, v * cos_ks * tan_d * inv_l, psi_dot),
        psi_dot=jnp.where(slow, dd_psi_ks, dd_psi_dyn),
        beta=jnp.where(slow, d_beta_ks, d_beta_dyn),
    )


def rhs(x: Array, u: Array, params: STParams) -> Array:
    """The ST model's vector field ``x' = f(x, u, params)`` on CommonRoad's vectors (module
    docstring's equations; :func:`vector_field` on named scalars).

    Args:
        x: state ``(sx, sy, delta, v, psi, psi_dot, beta)``, shape ``(7,)`` (m, m, rad, m/s, rad, rad/s, rad).
        u: input ``(v_delta, a_long)``, shape ``(2,)`` (rad/s, m/s^2), before the constraints.
        params: :class:`STParams`.

    Returns:
        ``x'``, shape ``(7,)``, in the state's units per second.
    """
    return jnp.stack(vector_field(STState(*(x[i] for i in range(7))), u[0], u[1], params))


def tyre_slip(x: STState, params: STParams) -> tuple[Array, Array, Array]:
    """The slip angles of a state as the model's tyre forces see them, in pfjax's kinematic slip
    model's convention (:mod:`pfjax.models.slip`, ``SOURCE``), rad: ``(beta_r, beta_f, beta)``::

        beta_r = beta - l_r psi_dot / v              = -alpha_r   (rear axle's velocity angle to the body)
        beta_f = delta - beta - l_f psi_dot / v      =  alpha_f   (front wheel's angle to its velocity)
        beta   = the state's slip angle at the centre of mass

    ``alpha_f``, ``alpha_r`` are the ST model's (linearised) tyre slip angles. They are the
    small-angle forms of the exact angles ``atan2(v sin(beta) - l_r psi_dot, v cos(beta))`` and
    ``delta - atan2(v sin(beta) + l_f psi_dot, v cos(beta))``, with which the kinematic slip model
    (speed ``v cos(beta)``) has the dynamic state's yaw rate and rear-axle velocity; the two differ
    by third-order terms (measured in the tests: below ``|angle|^3``). In the kinematic branch
    (``|v| < v_kinematic``) the tyres do not slip: ``beta_r = beta_f = 0``.
    """
    slow = jnp.abs(x.v) < params.v_kinematic
    inv_v = 1 / jnp.where(slow, jnp.ones_like(x.v), x.v)
    zero = jnp.zeros_like(x.v)
    beta_r = jnp.where(slow, zero, x.beta - params.l_r * x.psi_dot * inv_v)
    beta_f = jnp.where(slow, zero, x.delta - x.beta - params.l_f * x.psi_dot * inv_v)
    return beta_r, beta_f, x.beta
