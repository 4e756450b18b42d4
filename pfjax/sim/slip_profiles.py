"""Time-varying slip angles as one pytree.

Every profile is the superposition, per axle (index 0 rear ``beta_r``, 1 front ``beta_f``)::

    beta(t) = constant
              + step_size * [t >= step_time]
              + sin_amp * sin(2 pi sin_freq t + sin_phase)
              + seq[floor(t / seq_dt)]          (zero-order hold of a sampled sequence)

over the terms present: an absent term is ``None`` and costs nothing, so a constant slip is cheap
(time-invariant within an RK4 step) and the time-varying terms are paid for only when used.
Runs batched together need the same terms present (a study samples one kind for all its runs;
give every run the same terms, zeros where a run has none, to mix kinds in one batch).
All angles in rad, times in s, frequencies in Hz.
"""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp
import numpy as np
from jax import Array

from pfjax.numerics import elementary as E


class SlipProfile(NamedTuple):
    """Slip of one run. Only ``constant`` is required; a term left ``None`` is absent (not computed).

    A constant profile (``constant_slip``) does not depend on time, so within an RK4 step the
    slip, the yaw rate and the stage headings that depend on them are computed once (XLA merges
    the identical stage expressions); a present term, even an all-zero one, is evaluated at every
    stage. Runs batched together must have the same terms present.
    """

    constant: Array  # (2,) rad
    step_time: Array | None = None  # () s
    step_size: Array | None = None  # (2,) rad
    sin_amp: Array | None = None  # (2,) rad
    sin_freq: Array | None = None  # (2,) Hz
    sin_phase: Array | None = None  # (2,) rad
    seq: Array | None = None  # (n, 2) rad, held for seq_dt each; held at its last value after the end
    seq_dt: Array | None = None  # () s


def _pair(a) -> Array:
    return jnp.broadcast_to(jnp.asarray(a, dtype=float), (2,))


def slip_profile(
    constant=0.0, step_time=0.0, step_size=None, sin_amp=None, sin_freq=0.0, sin_phase=0.0, seq=None, seq_dt=1.0
) -> SlipProfile:
    """General constructor; scalars apply to both axles, pairs are ``(rear, front)``.

    The step term is present when ``step_size`` is given, the sinusoid when ``sin_amp`` is given,
    the sampled sequence when ``seq`` is given (``step_time``, ``sin_freq``, ``sin_phase`` and
    ``seq_dt`` only complete them).
    """
    f = lambda a: jnp.asarray(a, dtype=float)
    step = step_size is not None
    sine = sin_amp is not None
    sampled = seq is not None
    return SlipProfile(
        constant=_pair(constant),
        step_time=f(step_time) if step else None,
        step_size=_pair(step_size) if step else None,
        sin_amp=_pair(sin_amp) if sine else None,
        sin_freq=_pair(sin_freq) if sine else None,
        sin_phase=_pair(sin_phase) if sine else None,
        seq=f(seq).reshape(-1, 2) if sampled else None,
        seq_dt=f(seq_dt) if sampled else None,
    )


def constant_slip(beta_r, beta_f) -> SlipProfile:
    """Constant slip angles (rad), as in the source's tests (5 deg each)."""
    return slip_profile(constant=jnp.stack([jnp.asarray(beta_r, float), jnp.asarray(beta_f, float)]))


def step_slip(before, after, t_step) -> SlipProfile:
    """Slip ``before`` (rear, front) until ``t_step`` s, ``after`` from then on."""
    before, after = _pair(before), _pair(after)
    return slip_profile(constant=before, step_time=t_step, step_size=after - before)


def sinusoid_slip(mean, amplitude, freq_hz, phase=0.0) -> SlipProfile:
    """``mean + amplitude sin(2 pi f t + phase)`` per axle."""
    return slip_profile(constant=mean, sin_amp=amplitude, sin_freq=freq_hz, sin_phase=phase)


def sampled_slip(values, dt) -> SlipProfile:
    """Zero-order hold of sampled values, shape ``(n, 2)`` (rear, front), one every ``dt`` s."""
    values = np.asarray(values, dtype=float)
    if values.ndim != 2 or values.shape[1] != 2:
        raise ValueError(f"sampled slip values: expected shape (n, 2), got {values.shape}")
    return slip_profile(seq=values, seq_dt=dt)


#: Relative tolerance, in units of the working dtype's epsilon, under which a time counts as having
#: reached a switching instant (the step's ``step_time``, a sample boundary ``j seq_dt``).
BOUNDARY_ULPS = 16


def _boundary_scale(t: Array):
    """``1 + BOUNDARY_ULPS eps``: integrator stage times ``k dt + dt/2`` are rounded, so a stage at a
    switching instant in exact arithmetic can land a few ulps before it, and whether its slip is the
    old or the new one would depend on the compiler's rounding (measured: a falsifier's worst case
    replayed by two XLA code paths differed by 3e-5 in IAE). Times within this margin switch."""
    return 1.0 + BOUNDARY_ULPS * jnp.finfo(jnp.result_type(t, float)).eps


def slip_at(profile: SlipProfile, t: Array) -> tuple[Array, Array]:
    """``(beta_r(t), beta_f(t))`` in rad (the sum of the profile's present terms). A time within
    :data:`BOUNDARY_ULPS` ulps before a switching instant counts as having reached it."""
    beta = profile.constant
    if profile.step_size is not None:
        beta = beta + profile.step_size * (t * _boundary_scale(t) >= profile.step_time)
    if profile.sin_amp is not None:
        assert profile.sin_freq is not None and profile.sin_phase is not None  # set with sin_amp (sinusoid)
        beta = beta + profile.sin_amp * E.sin(2.0 * jnp.pi * profile.sin_freq * t + profile.sin_phase)
    if profile.seq is not None:
        assert profile.seq_dt is not None  # set with seq (sequence)
        n = profile.seq.shape[0]
        if n == 1:  # a single value: no gather (a gather splits XLA's fused loop body)
            beta = beta + profile.seq[0]
        else:
            j = jnp.floor(t / profile.seq_dt * _boundary_scale(t)).astype(jnp.int32)
            beta = beta + profile.seq[jnp.clip(j, 0, n - 1)]
    return beta[0], beta[1]
