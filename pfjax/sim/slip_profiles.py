"""Time-varying slip angles as one pytree.

Every profile is the superposition, per axle (index 0 rear ``beta_r``, 1 front ``beta_f``)::

    beta(t) = constant
              + step_size * [t >= step_time]
              + sin_amp * sin(2 pi sin_freq t + sin_phase)
              + seq[floor(t / seq_dt)]          (zero-order hold of a sampled sequence)

so constant, step, sinusoid and sampled profiles (and mixtures) share one shape and a batch
can mix them freely. Unused terms are zeros. All angles in rad, times in s, frequencies in Hz.
"""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp
import numpy as np
from jax import Array

from pfjax.numerics import elementary as E


class SlipProfile(NamedTuple):
    constant: Array  # (2,) rad
    step_time: Array  # () s
    step_size: Array  # (2,) rad
    sin_amp: Array  # (2,) rad
    sin_freq: Array  # (2,) Hz
    sin_phase: Array  # (2,) rad
    seq: Array  # (n, 2) rad, held for seq_dt each; held at its last value after the end
    seq_dt: Array  # () s


def _pair(a) -> Array:
    return jnp.broadcast_to(jnp.asarray(a, dtype=float), (2,))


def slip_profile(constant=0.0, step_time=0.0, step_size=0.0, sin_amp=0.0, sin_freq=0.0, sin_phase=0.0,
                 seq=None, seq_dt=1.0) -> SlipProfile:
    """General constructor; scalars apply to both axles, pairs are ``(rear, front)``."""
    seq = jnp.zeros((1, 2)) if seq is None else jnp.asarray(seq, dtype=float).reshape(-1, 2)
    return SlipProfile(
        constant=_pair(constant),
        step_time=jnp.asarray(step_time, dtype=float),
        step_size=_pair(step_size),
        sin_amp=_pair(sin_amp),
        sin_freq=_pair(sin_freq),
        sin_phase=_pair(sin_phase),
        seq=seq,
        seq_dt=jnp.asarray(seq_dt, dtype=float),
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


def slip_at(profile: SlipProfile, t: Array) -> tuple[Array, Array]:
    """``(beta_r(t), beta_f(t))`` in rad."""
    n = profile.seq.shape[0]
    if n == 1:  # static: no sequence, no gather (a gather splits XLA's fused loop body)
        held = profile.seq[0]
    else:
        held = profile.seq[jnp.clip(jnp.floor(t / profile.seq_dt).astype(jnp.int32), 0, n - 1)]
    beta = (
        profile.constant
        + profile.step_size * (t >= profile.step_time)
        + profile.sin_amp * E.sin(2.0 * jnp.pi * profile.sin_freq * t + profile.sin_phase)
        + held
    )
    return beta[0], beta[1]
