"""α schedules (docs/reproductions/parking.md §4) and the 24-bit chromosome decoding of the GA search (docs/reproductions/parking.md §5).

A schedule lists α at the start and then after each direction switch; the last value holds from
then on (case C: ``1, 0.5``; case D: ``1, 0.5, 8, 1``). Inside the simulation it is a fixed-length
array (:data:`SCHEDULE_LEN`) padded with its last value, so schedules of different lengths batch
together; after ``n`` switches the gain is ``schedule[min(n, SCHEDULE_LEN − 1)]``.
"""

from __future__ import annotations

from typing import Any

import jax.numpy as jnp
import numpy as np

from pfjax import errors
from pfjax.errors import InputError
from pfjax.parking.defaults import GARAGE_START  # noqa: F401  (re-exported)

SCHEDULE_LEN = 8

#: The source's cases (docs/reproductions/parking.md §4).
CASES: dict[str, dict[str, Any]] = {
    "A": {"map": "parallel", "x0": (-0.4, 0.5, 0.0), "direction": 1, "schedule": (1.0,)},
    "B": {"map": "parallel", "x0": (0.1, 0.5, 0.0), "direction": -1, "schedule": (1.0,)},
    "C": {"map": "parallel", "x0": (0.1, 0.5, 0.0), "direction": -1, "schedule": (1.0, 0.5)},
    "D": {"map": "parallel", "x0": (0.1, 0.5, 0.0), "direction": -1, "schedule": (1.0, 0.5, 8.0, 1.0)},
}

#: Decoding ranges of the 24-bit chromosome (docs/reproductions/parking.md §5, assumed).
XS_MIN, XS_MAX, ALPHA_MAX = -1.2, -0.6, 10.0


def pad_schedule(values, key: str = "alpha_schedule") -> np.ndarray:
    """Schedule values -> (SCHEDULE_LEN,) array padded with the last value.

    The one check of a schedule, whatever form it came in (:func:`parse_schedule`'s string, a
    sequence from :func:`pfjax.parking.run` or a study config): 1 to :data:`SCHEDULE_LEN` values,
    each a number in [:data:`~pfjax.errors.MIN_POSITIVE`, :data:`~pfjax.errors.MAX_MAGNITUDE`]
    (:func:`pfjax.errors.number` with ``positive``). Raises :class:`~pfjax.errors.InputError` (a
    ``ValueError``) naming ``key``, or ``key[i]`` for the i-th value.
    """
    v = list(values)
    if not v or len(v) > SCHEDULE_LEN:
        raise InputError(f"{key}: expected 1..{SCHEDULE_LEN} values, got {len(v)}", key)
    v = [errors.number(f"{key}[{i}]", a, positive=True) for i, a in enumerate(v)]
    return np.asarray(v + [v[-1]] * (SCHEDULE_LEN - len(v)))


def parse_schedule(text: str, key: str = "alpha_schedule") -> np.ndarray:
    """'1,0.5,8,1' -> padded schedule (:func:`pad_schedule`'s checks); InputError naming ``key``."""
    try:
        vals = [float(s) for s in text.split(",")]
    except ValueError:
        raise InputError(f"{key}: expected comma-separated numbers, got {text!r:.80}", key) from None
    return pad_schedule(vals, key)


def alpha_at(schedule, n_switches):
    """α after ``n_switches`` direction switches (jittable)."""
    return schedule[jnp.minimum(n_switches, schedule.shape[-1] - 1)]


def three_phase(alpha1, alpha2):
    """The GA's schedule: α = 1 at the start, α₁ after the 1st switch, α₂ from the 2nd on (batched)."""
    a1, a2 = jnp.asarray(alpha1, float), jnp.asarray(alpha2, float)
    one = jnp.ones_like(a1)
    return jnp.stack([one, a1] + [a2] * (SCHEDULE_LEN - 2), axis=-1)


def decode_bits(bits):
    """(..., 24) bits (most significant first per 8-bit field) -> (X_s m, α₁, α₂) (docs/reproductions/parking.md §5).

    ``X_s = X_smin + (X_smax − X_smin) ξ₁ / 255``, ``α_i = α_max (ξ_{i+1} + 1) / 256``.
    """
    b = jnp.asarray(bits).astype(jnp.int32).reshape(bits.shape[:-1] + (3, 8))
    xi = jnp.sum(b * (2 ** jnp.arange(7, -1, -1)), axis=-1)
    xs = XS_MIN + (XS_MAX - XS_MIN) * xi[..., 0] / 255.0
    return xs, ALPHA_MAX * (xi[..., 1] + 1) / 256.0, ALPHA_MAX * (xi[..., 2] + 1) / 256.0


def decoded_levels():
    """The 256 values each gene can take: (X_s levels, α levels)."""
    xi = np.arange(256)
    return XS_MIN + (XS_MAX - XS_MIN) * xi / 255.0, ALPHA_MAX * (xi + 1) / 256.0
