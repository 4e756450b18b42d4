"""Dynamic single-track (bicycle) model with linear tyres: CommonRoad's ST model as a pure JAX vector field.

State and input are CommonRoad's, in its order and units (CommonRoad vehicle models, ST model;
M. Althoff, M. Koschi, S. Manzinger, "CommonRoad: Composable benchmarks for motion planning on roads",
IEEE IV 2017, doi:10.1109/IVS.2017.7995802)::

    x = (sx, sy, delta, v, psi, psi_dot, beta)    m, m, rad, m/s, rad, rad/s, rad
    u = (v_delta, a_long)                         rad/s, m/s^2

``(sx, sy)`` is the centre of mass, ``delta`` the front steering angle, ``v`` the speed of the centre
of mass, ``psi`` the yaw angle, ``beta`` the slip angle at the centre of mass (the velocity's angle to
the body axis). The inputs first pass CommonRoad's constraints (:func:`steering_rate` and
:func:`acceleration`, in :mod:`pfjax.models.single_track_params` with the parameter sets). With ``l = l_f + l_r``, the axle loads per unit mass (load transfer through the
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

:func:`rhs` is NaN-safe for differentiation: the branch not taken never divides by zero. The
single-track drift model (CommonRoad's STD: Pacejka tyres and wheel speeds) is :func:`rhs_drift`
(:mod:`pfjax.models.single_track_drift`), its tyre :mod:`pfjax.models.tyres`.
"""

from __future__ import annotations

import functools
import math
from typing import NamedTuple

import jax.numpy as jnp
import numpy as np
from jax import Array

from pfjax.models.single_track_drift import (
    COMMONROAD_DRIFT_VEHICLES,
    DRIFT_STATE_NAMES,
    STDParams,
    STDState,
    drift_modes,
    drift_parameter_set,
    drift_params_from_commonroad,
    drift_tyre_slip,
    rhs_drift,
    vector_field_drift,
)
from pfjax.models.single_track_params import (
    COMMONROAD_VEHICLES,
    PARAMETER_SETS,
    ROBOT_SCALE,
    STParams,
    acceleration,
    parameter_set,
    params_from_commonroad,
    robot_params,
    steering_rate,
)
from pfjax.numerics import elementary as E

__all__ = [
    "COMMONROAD_DRIFT_VEHICLES",
    "COMMONROAD_VEHICLES",
    "DRIFT_STATE_NAMES",
    "INPUT_NAMES",
    "PARAMETER_SETS",
    "RK4_REACH",
    "ROBOT_SCALE",
    "STATE_NAMES",
    "STDParams",
    "STDState",
    "STParams",
    "STState",
    "acceleration",
    "body",
    "check_step",
    "drift_modes",
    "drift_parameter_set",
    "drift_params_from_commonroad",
    "drift_tyre_slip",
    "lateral_eigenvalues",
    "lateral_yaw_matrices",
    "max_stable_step",
    "model_parameter_set",
    "parameter_set",
    "params_from_commonroad",
    "rhs",
    "rhs_drift",
    "robot_params",
    "stable_step",
    "steering_rate",
    "tyre_slip",
    "vector_field",
    "vector_field_drift",
    "with_mu",
]

#: Names of the state vector's entries, in CommonRoad's order.
STATE_NAMES = ("sx", "sy", "delta", "v", "psi", "psi_dot", "beta")
#: Names of the input vector's entries.
INPUT_NAMES = ("v_delta", "a_long")


#: ``|lambda| dt`` up to which a fixed RK4 step is taken as stable for the model's modes (RK4's
#: stability region reaches 2.785 on the negative real axis and about 2.8 along the imaginary one).
RK4_REACH = 2.5


def lateral_yaw_matrices(params: STParams, v: float) -> tuple[np.ndarray, np.ndarray]:
    """The dynamic branch linearised in ``(psi_dot, beta)`` and ``delta`` at speed ``v`` (m/s), without
    longitudinal acceleration (``a = 0``; host code, NumPy): ``(psi_dot', beta')' = A (psi_dot, beta)' +
    B delta`` (the model's equations are linear in these three at fixed ``v`` and ``a``, so this is
    exact there)::

        A = [[-k (l_f^2 C_Sf F_f + l_r^2 C_Sr F_r) / v,            k (l_r C_Sr F_r - l_f C_Sf F_f)],
             [mu (l_r C_Sr F_r - l_f C_Sf F_f) / (v^2 l) - 1,      -mu (C_Sf F_f + C_Sr F_r) / (v l)]]
        B = [[k l_f C_Sf F_f], [mu C_Sf F_f / (v l)]]

    with ``F_f = g l_r``, ``F_r = g l_f``, ``k = mu m / (I_z l)``.

    Returns:
        ``A`` (2, 2) in 1/s and 1 (``beta'`` per ``psi_dot``), ``B`` (2, 1) in 1/s^2 and 1/s.
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
    b = np.array([[k * p.l_f * cf], [p.mu * cf / (v * l)]])
    return a, b


def lateral_eigenvalues(params: STParams, v: float) -> np.ndarray:
    """Eigenvalues (1/s) of the lateral-yaw dynamics :func:`lateral_yaw_matrices` at speed ``v`` (m/s).
    Their magnitude grows as ``mu / v``: the tyres' time constants are short at high friction and low
    speed."""
    return np.linalg.eigvals(lateral_yaw_matrices(params, v)[0])


def max_stable_step(params: STParams | STDParams, v: float, tau_delta: float = math.inf, k_v: float = 0.0) -> float:
    """The largest RK4 step (s) for which ``|lambda| dt <= RK4_REACH`` for the model's modes at speed
    ``v`` (the ST model's lateral-yaw modes, :func:`lateral_eigenvalues`; the drift model's, wheel
    speeds included, :func:`~pfjax.models.single_track_drift.drift_modes`), a first-order steering
    actuator (``lambda = -1 / tau_delta``) and a proportional speed loop (``lambda = -k_v``). A step
    beyond it lets the integration blow up (a run then fails as ``diverged`` or ``nonfinite``). The
    modes of a set of plain numbers are remembered (the drift model's take tens of milliseconds, and
    every chunk of a study checks its step)."""
    try:
        return _max_stable_step(params, float(v), float(tau_delta), float(k_v))
    except TypeError:  # parameters holding arrays: not hashable, computed each time
        return _max_stable_step.__wrapped__(params, v, tau_delta, k_v)


@functools.lru_cache(maxsize=256)
def _max_stable_step(params, v: float, tau_delta: float, k_v: float) -> float:
    modes = drift_modes(params, v) if isinstance(params, STDParams) else lateral_eigenvalues(params, v)
    fastest = max(float(np.max(np.abs(modes))), 1 / tau_delta, k_v)
    return RK4_REACH / fastest


def stable_step(
    params: STParams | STDParams,
    v: float,
    tau_delta: float = math.inf,
    k_v: float = 0.0,
    *,
    largest: float = 0.005,
) -> float:
    """The largest step (s) of the 1-2-5 series ``largest``, ``largest`` x 0.4, x 0.2, x 0.1, ...
    (0.005, 0.002, 0.001, 0.0005, 0.0002 s, ...) within :func:`max_stable_step`, so that
    :func:`check_step` accepts it. ``pfjax simulate --model st|std`` takes it when no ``--dt`` is
    given: 0.0002 s for the STD model's ``vehicle2`` at 1 m/s, 0.005 s for the ST robot."""
    bound = max_stable_step(params, v, tau_delta, k_v)
    step, k = largest, 0
    while step > bound:
        k += 1
        step = float(f"{largest * (1.0, 0.4, 0.2)[k % 3] * 10.0 ** -(k // 3):.6g}")
    return step


def check_step(
    key: str,
    dt: float,
    params: STParams | STDParams,
    v: float,
    tau_delta: float = math.inf,
    k_v: float = 0.0,
    *,
    worst_case: str | None = None,
) -> None:
    """:class:`~pfjax.errors.InputError` naming ``key`` when ``dt`` (s) is beyond
    :func:`max_stable_step` of ``params`` (their friction) at speed ``v`` (m/s) with the steering
    actuator ``tau_delta`` (s) and speed loop ``k_v`` (1/s): the one check of the step that a study
    config, :func:`pfjax.simulate`, ``pfjax simulate`` and tuning make. ``worst_case``: where
    ``params`` and ``v`` come from, said in the message (``"the runs' worst case"``)."""
    from pfjax.errors import InputError

    dt_max = max_stable_step(params, v, tau_delta, k_v)
    if dt > dt_max:
        name = "STD" if isinstance(params, STDParams) else "ST"
        where = f" ({worst_case})" if worst_case else ""
        raise InputError(
            f"{key}: the {name} model at mu = {float(body(params).mu):g} and speed {v:g} m/s{where} needs "
            f"dt <= {dt_max:.3g} s for a stable RK4 step, got {dt:g}",
            key,
        )


def check_speed(key: str, v: float, params: STParams | STDParams) -> None:
    """:class:`~pfjax.errors.InputError` naming ``key`` when the speed ``v`` (m/s; a range's
    upper end) is above the parameter set's top speed ``v_max``: CommonRoad's acceleration
    constraint only stops the vehicle from speeding up past it, so a run started above it would stay
    there. The one check of a single-track run's speed, for a study config (and
    :func:`pfjax.scenarios`) and ``pfjax simulate --model``."""
    from pfjax.errors import InputError

    v_max = float(body(params).v_max)
    if v > v_max:
        raise InputError(f"{key}: must be at most the parameter set's top speed, {v_max:.4g} m/s, got {v:g} m/s", key)


def body(params: STParams | STDParams) -> STParams:
    """The :class:`STParams` of either model's parameters (the drift model's ``params.body``)."""
    return params.body if isinstance(params, STDParams) else params


def with_mu(params: STParams | STDParams, mu) -> STParams | STDParams:
    """Either model's parameters with the friction coefficient ``mu`` replaced."""
    if isinstance(params, STDParams):
        return params._replace(body=params.body._replace(mu=mu))
    return params._replace(mu=mu)


def model_parameter_set(model: str, name: str) -> STParams | STDParams:
    """The named parameter set of ``model`` (``"st"``: :func:`parameter_set`; ``"std"``:
    :func:`~pfjax.models.single_track_drift.drift_parameter_set`)."""
    return drift_parameter_set(name) if model == "std" else parameter_set(name)


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
    # the rates that select between the branches, computed in kernels of their own on CPU (values
    # and derivatives exact): every kernel of the integrator that reads them would otherwise
    # recompute both branches (docs/dynamic-model.md, Cost)
    d_psi = E.computed_once(jnp.where(slow, v * cos_ks * tan_d * inv_l, psi_dot))
    dd_psi, d_beta = E.computed_once_pair(
        jnp.where(slow, dd_psi_ks, dd_psi_dyn), jnp.where(slow, d_beta_ks, d_beta_dyn), v
    )
    return STState(
        sx=v * (cos_p * cb - sin_p * sb),
        sy=v * (sin_p * cb + cos_p * sb),
        delta=v_delta,
        v=a,
        psi=d_psi,
        psi_dot=dd_psi,
        beta=d_beta,
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
