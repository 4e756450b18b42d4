"""The source's two controllers: static state feedback and the MISO PI (docs/reproductions/path-following.md §4-5)."""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp
import numpy as np
from jax import Array

from pfjax.controllers.base import Controller, Observation, no_rate, no_state
from pfjax.controllers.registry import register
from pfjax.numerics import elementary as E

#: The source's published mixed H2/Hinf gain (docs/reproductions/path-following.md §4): u = K [d, theta_e].
PAPER_K = (-2.7381, -2.0772)
#: Table 3's GA-optimal PI gains in the order printed; the row labels were lost (docs/reproductions/path-following.md §5).
TABLE3_GAINS = (1.6390, 0.0230, 39.5204, 11.6124)
#: The reading of Table 3 adopted as the source's PI. The labels were lost (docs/reproductions/path-following.md §5); the
#: paper-reproduction study simulates all 24 readings and this is the one consistent with the
#: claims the source makes about its PI (the reproduction's verdict table says how sensitive that
#: choice is): Table 3's printed order is (Ki_d, Ki_theta, Kp_d, Kp_theta).
PAPER_PI = dict(kp_d=TABLE3_GAINS[2], ki_d=TABLE3_GAINS[0], kp_theta=TABLE3_GAINS[3], ki_theta=TABLE3_GAINS[1])


class StateFeedbackParams(NamedTuple):
    """``delta = K [d, theta_e] + feedforward * atan(L kappa)``."""

    K: Array  # (2,) rad/m, rad/rad
    feedforward: Array  # 0 (source) or 1: add the path-curvature steering atan(L kappa)


def state_feedback_params(K=PAPER_K, feedforward=0.0) -> StateFeedbackParams:
    return StateFeedbackParams(jnp.asarray(np.ravel(K), dtype=float), jnp.asarray(feedforward, dtype=float))


def _sf_output(p: StateFeedbackParams | LinearParams, c, obs: Observation) -> Array:
    return p.K[0] * obs.d + p.K[1] * obs.theta_e + p.feedforward * E.atan(obs.L * obs.kappa)


state_feedback = Controller("state_feedback", no_state, _sf_output, no_rate, StateFeedbackParams)
"""Static state feedback ``delta = K x``, ``x = [d, theta_e]`` (source eq. 8; the design is in
:mod:`pfjax.synthesis`)."""
register(
    state_feedback,
    state_feedback_params,
    box=(("K",), (-20.0, -10.0), (0.0, 0.0)),
    style={"color": "#17becf", "lw": 1.2, "ls": "--", "label": "state feedback"},
    labels={"K": ("k_d", "k_theta")},
    gains=("k_d", "k_theta"),
    units={"k_d": "rad/m", "k_theta": "rad/rad", "feedforward": "1"},
)


class PIParams(NamedTuple):
    """MISO PI gains (docs/reproductions/path-following.md §5, eq. 14)::

        delta = kp_d (-d) + ki_d int(-d) + kp_theta (-theta_e) + ki_theta int(-theta_e)

    ``k_aw`` is the back-calculation anti-windup gain (1/s; 0 = none, the source's PI).
    """

    kp_d: Array  # rad/m
    ki_d: Array  # rad/(m s)
    kp_theta: Array  # rad/rad
    ki_theta: Array  # 1/s
    k_aw: Array  # 1/s


def pi_params(kp_d, ki_d, kp_theta, ki_theta, k_aw=0.0) -> PIParams:
    return PIParams(*(jnp.asarray(g, dtype=float) for g in (kp_d, ki_d, kp_theta, ki_theta, k_aw)))


#: The 24 ways to read Table 3 as (kp_d, ki_d, kp_theta, ki_theta); which one the source used is
#: decided by simulation in the paper-reproduction study. ``"d:P,I|theta:P,I"`` is the printed order
#: read as Kp1, Ki1, Kp2, Ki2 with e1 = d.
def table3_assignments(values=TABLE3_GAINS) -> dict[str, PIParams]:
    """The 24 readings of Table 3's four printed ``values`` (default the published ones), labelled
    by :func:`table3_label`, in the order of :func:`itertools.permutations` of the printed order."""
    from itertools import permutations

    out = {}
    for perm in permutations(range(4)):
        gains = {n: float(values[perm[j]]) for j, n in enumerate(PI_GAIN_NAMES)}
        out[table3_label(gains)] = pi_params(**gains)
    return out


#: The PI's gains in the order Table 3's readings assign them.
PI_GAIN_NAMES = ("kp_d", "ki_d", "kp_theta", "ki_theta")


def table3_label(gains) -> str:
    """``"kp_d=…,ki_d=…,kp_theta=…,ki_theta=…"``: the label of a reading of Table 3."""
    return ",".join(f"{n}={gains[n]:g}" for n in PI_GAIN_NAMES)


def _pi_output(p: PIParams, c: Array, obs: Observation) -> Array:
    # c = [int(-d) * ki_d, int(-theta_e) * ki_theta]: the integral *terms*, rad.
    return -p.kp_d * obs.d - p.kp_theta * obs.theta_e + c[0] + c[1]


def _pi_rate(p, c: Array, obs: Observation, delta_cmd: Array, delta: Array) -> Array:
    # p: PIParams or LinearParams (ki_d, ki_theta, k_aw)
    # Back-calculation: the saturation excess is fed back into the integral terms, split in
    # proportion to their integral gains (k_aw = 0 disables it).
    ki = jnp.abs(p.ki_d) + jnp.abs(p.ki_theta)
    w_d = jnp.where(ki > 0, jnp.abs(p.ki_d) / jnp.where(ki > 0, ki, 1.0), 0.5)
    aw = p.k_aw * (delta - delta_cmd)
    return jnp.stack([-p.ki_d * obs.d + w_d * aw, -p.ki_theta * obs.theta_e + (1.0 - w_d) * aw])


def _pi_init(p) -> Array:
    return jnp.zeros((2,), dtype=jnp.result_type(p.ki_d))


pi = Controller("pi", _pi_init, _pi_output, _pi_rate, PIParams)
"""MISO PI on ``d`` and ``theta_e`` summed into the steering (docs/reproductions/path-following.md §5, eq. 14), optional anti-windup."""
register(
    pi,
    pi_params,
    defaults=PAPER_PI,
    box=(("kp_d", "ki_d", "kp_theta", "ki_theta"), (0.0, 0.0, 0.0, 0.0), (60.0, 5.0, 30.0, 1.0)),
    style={"color": "#d62728", "lw": 1.6, "label": "MISO PI (Table 3)"},
    units={"kp_d": "rad/m", "ki_d": "rad/(m s)", "kp_theta": "rad/rad", "ki_theta": "1/s", "k_aw": "1/s"},
)


class LinearParams(NamedTuple):
    """State feedback and the MISO PI as one controller (:data:`linear`)::

        delta = K [d, theta_e] + feedforward atan(L kappa) + c_0 + c_1,
        c' = [-ki_d d, -ki_theta theta_e] (+ back-calculation anti-windup, as :data:`pi`).

    State feedback is ``ki_d = ki_theta = k_aw = 0`` (the integral terms stay exactly 0); the PI
    is ``K = (-kp_d, -kp_theta)``, ``feedforward = 0``. :func:`linear_params` converts either.
    """

    K: Array  # (2,) rad/m, rad/rad
    feedforward: Array  # 0 or 1
    ki_d: Array  # rad/(m s)
    ki_theta: Array  # 1/s
    k_aw: Array  # 1/s


def linear_params(gains: StateFeedbackParams | PIParams) -> LinearParams:
    """The :data:`linear` form of state-feedback or PI gains (the same steering, up to rounding)."""
    if isinstance(gains, StateFeedbackParams):
        z = jnp.zeros_like(gains.feedforward)
        return LinearParams(gains.K, gains.feedforward, z, z, z)
    if isinstance(gains, PIParams):
        return LinearParams(
            jnp.stack([-gains.kp_d, -gains.kp_theta]),
            jnp.zeros_like(gains.kp_d),
            gains.ki_d,
            gains.ki_theta,
            gains.k_aw,
        )
    raise TypeError(f"gains: expected StateFeedbackParams or PIParams, got {type(gains).__name__}")


def _linear_output(p: LinearParams, c: Array, obs: Observation) -> Array:
    return _sf_output(p, c, obs) + c[0] + c[1]


linear = Controller("linear", _pi_init, _linear_output, _pi_rate, LinearParams)
"""State feedback and the MISO PI as one controller (:class:`LinearParams`): a Monte Carlo study
evaluates both with it, so they share one compiled simulator program (one compile instead of two
for the runs, the float64 check and the worst-case search each)."""
