"""Per-run metrics accumulated while the simulation runs (memory independent of the horizon).

The simulator calls :func:`update` once per integrator sample ``t_k = k dt``, ``k = 0..N``, with
the trapezoid weight ``w_k dt`` (``w = 1/2`` at both ends, 1 inside, 0 once the run has failed),
so the integrals are the composite trapezoid rule on the samples::

    IAE  = int |d| dt          ISE = int d^2 dt         ITAE = int t |d| dt
    steering energy = int delta^2 dt                    (applied steering, rad^2 s)

and the remaining metrics are sample statistics:

* ``max_abs_d``: max |d| (m);
* ``steady_abs_d``, ``steady_abs_theta_e_rad``: time-mean of |d| (m) and |theta_e| (rad) over the
  last ``steady_window`` seconds of the horizon (trapezoid rule on the samples in the window);
* ``settling_time``: first sample time after which |d| stays within ``settle_band`` (s);
  NaN if the run ends outside the band or fails;
* ``overshoot``: largest excursion of ``d`` past zero on the side opposite to ``d(0)`` (m, >= 0);
* ``steer_tv``: total variation of the applied steering, sum |delta_k - delta_{k-1}| (rad);
* ``sat_fraction``: fraction of the run's time with the command beyond the steering limit;
* ``late_max_abs_d``: max |d| from ``success_from`` on (m); NaN for a run that failed before
  ``success_from`` (no sample in the success window);
* ``success``: the run did not fail and ``late_max_abs_d <= success_band``.

A failed run's metrics describe it up to its failure (the failing sample excluded). A run that
fails at its first sample (``t = 0``: it starts beyond ``d_fail``, or not finite) has no samples:
its integrals and ``steer_tv`` are 0, its maxima (``max_abs_d``, ``late_max_abs_d``,
``overshoot``) and ``sat_fraction`` NaN. A run that did not fail has samples up to the horizon, and
``success_from <= horizon``, so its ``late_max_abs_d`` is a number.
"""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp
from jax import Array


class Accumulator(NamedTuple):
    iae: Array
    ise: Array
    itae: Array
    max_abs_d: Array
    steady_abs_d: Array  # running weighted sum over the steady window
    steady_abs_theta_e_rad: Array
    steady_weight: Array
    settle: Array  # time of the first sample after the last out-of-band one
    overshoot: Array
    d0_sign: Array
    steer_energy: Array
    steer_tv: Array
    prev_delta: Array
    sat_time: Array
    time: Array  # total weighted time
    late_max_abs_d: Array  # max |d| from success_from on (-inf: no sample there yet)


class Metrics(NamedTuple):
    iae: Array  # m s
    ise: Array  # m^2 s
    itae: Array  # m s^2
    max_abs_d: Array  # m
    steady_abs_d: Array  # m
    steady_abs_theta_e_rad: Array  # rad
    settling_time: Array  # s (NaN: not settled)
    overshoot: Array  # m
    steer_energy: Array  # rad^2 s
    steer_tv: Array  # rad
    sat_fraction: Array  # 1
    late_max_abs_d: Array  # m
    success: Array  # bool


METRIC_NAMES = Metrics._fields


def init(d0: Array, delta0: Array) -> Accumulator:
    z = jnp.zeros_like(d0)
    return Accumulator(
        iae=z,
        ise=z,
        itae=z,
        max_abs_d=z,
        steady_abs_d=z,
        steady_abs_theta_e_rad=z,
        steady_weight=z,
        settle=z,
        overshoot=z,
        d0_sign=jnp.sign(d0),
        steer_energy=z,
        steer_tv=z,
        prev_delta=delta0,
        sat_time=z,
        time=z,
        late_max_abs_d=jnp.full_like(d0, -jnp.inf),
    )


def update(
    acc: Accumulator,
    t,
    dt,
    weight,
    d,
    theta_e,
    delta,
    saturated,
    *,
    band: float,
    steady_from: float,
    success_from: float,
) -> Accumulator:
    """Add sample ``k`` (time ``t``) with trapezoid weight ``weight`` (0 after a failure)."""
    w = weight * dt
    live = weight > 0
    # A failed run's samples carry weight 0 but may be NaN (NONFINITE): mask them, 0 * NaN = NaN.
    d, theta_e, delta, saturated = (jnp.where(live, a, 0.0) for a in (d, theta_e, delta, saturated))
    ad = jnp.abs(d)
    # Steady window [t_k0, t_N]: trapezoid weights on it, so the first sample in the window gets
    # half a step (the end sample already has it), and the mean is (1/(t_N - t_k0)) int |d| dt.
    in_window = t >= steady_from - 1e-9
    first = in_window & (t < steady_from + dt - 1e-9)
    ws = jnp.where(in_window, jnp.where(first, jnp.minimum(w, 0.5 * dt), w), 0.0)
    return Accumulator(
        iae=acc.iae + w * ad,
        ise=acc.ise + w * d * d,
        itae=acc.itae + w * t * ad,
        max_abs_d=jnp.where(live, jnp.maximum(acc.max_abs_d, ad), acc.max_abs_d),
        steady_abs_d=acc.steady_abs_d + ws * ad,
        steady_abs_theta_e_rad=acc.steady_abs_theta_e_rad + ws * jnp.abs(theta_e),
        steady_weight=acc.steady_weight + ws,
        settle=jnp.where(live & (ad > band), t + dt, acc.settle),
        overshoot=jnp.where(live, jnp.maximum(acc.overshoot, -acc.d0_sign * d), acc.overshoot),
        d0_sign=acc.d0_sign,
        steer_energy=acc.steer_energy + w * delta * delta,
        steer_tv=acc.steer_tv + jnp.where(live, jnp.abs(delta - acc.prev_delta), 0.0),
        prev_delta=jnp.where(live, delta, acc.prev_delta),
        sat_time=acc.sat_time + w * saturated,
        time=acc.time + w,
        late_max_abs_d=jnp.where(
            live & (t >= success_from - 1e-9), jnp.maximum(acc.late_max_abs_d, ad), acc.late_max_abs_d
        ),
    )


def finalize(acc: Accumulator, horizon: float, failed: Array, success_band: float) -> Metrics:
    """Turn the accumulator into :class:`Metrics`."""
    nan = jnp.nan
    settled = (acc.settle <= horizon) & ~failed
    sw = jnp.where(acc.steady_weight > 0, acc.steady_weight, 1.0)
    # a run that failed at its first sample has no samples: its integrals are 0 (over no time), its
    # maxima and its saturated fraction are undefined (NaN), not 0
    empty = acc.time <= 0
    return Metrics(
        iae=acc.iae,
        ise=acc.ise,
        itae=acc.itae,
        max_abs_d=jnp.where(empty, nan, acc.max_abs_d),
        steady_abs_d=jnp.where(failed, nan, acc.steady_abs_d / sw),
        steady_abs_theta_e_rad=jnp.where(failed, nan, acc.steady_abs_theta_e_rad / sw),
        settling_time=jnp.where(settled, acc.settle, nan),
        overshoot=jnp.where(empty, nan, jnp.maximum(acc.overshoot, 0.0)),
        steer_energy=acc.steer_energy,
        steer_tv=acc.steer_tv,
        sat_fraction=jnp.where(empty, nan, acc.sat_time / jnp.where(empty, 1.0, acc.time)),
        # no sample in the success window (a run that failed before success_from): NaN
        late_max_abs_d=jnp.where(acc.late_max_abs_d >= 0, acc.late_max_abs_d, nan),
        success=~failed & (acc.late_max_abs_d <= success_band),
    )
