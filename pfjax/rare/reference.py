"""An independent reference for the estimators: static state feedback on a straight line under
constant Gaussian slip from zero initial error.

On a line the loop ``δ = K x`` rests at ``θ_e* = -β_r``, ``δ* = β_r + β_f`` and an offset
``d*(β_r, β_f)`` (:func:`pfjax.analysis.equilibrium`); from zero initial error a stable loop
settles there, so a run fails (``|d| > band`` late in the run) exactly where ``|d*| > band``.
With ``β_r, β_f ~ N(0, s²)`` independent,

$$
p = \\int φ_s(β_r)\\, \\bigl[Φ(β_f^-(β_r)/s) + Φ(-β_f^+(β_r)/s)\\bigr]\\, dβ_r,
$$

with ``β_f^∓(β_r)`` the slips at which ``d* = ∓band`` (``d*`` is monotone in ``β_f``), found by
``scipy.optimize.brentq`` on the equilibrium and integrated by ``scipy.integrate.quad`` over
``±12 s`` (relative tolerance 1e-8). Nothing here samples.
"""

from __future__ import annotations

import math

import numpy as np


def line_offset_failure_probability(
    K, std_deg: float, band: float = 0.05, *, v: float = 1.0, L: float = 0.2, delta_max_deg: float = 30.0
) -> float:
    """``P(|d*(β_r, β_f)| > band)`` for ``β_r, β_f ~ N(0, std_deg²)`` (deg) and the gain ``K``
    (``[k_d rad/m, k_θ rad/rad]``) at speed ``v`` (m/s) and wheelbase ``L`` (m) (module docstring)."""
    import jax
    from scipy import integrate, optimize
    from scipy.special import ndtr

    from pfjax.analysis import equilibrium
    from pfjax.models.slip import SlipParams

    K = np.asarray(K, dtype=float)
    with jax.enable_x64(True):
        params = SlipParams(v=v, L=L, delta_max=math.radians(delta_max_deg), convention=np.asarray(0, np.int32))
        offset = jax.jit(lambda br, bf: equilibrium(K, br, bf, params).d)
        s = math.radians(std_deg)

        def inner(br: float) -> float:
            f = lambda bf, c: float(offset(br, bf)) - c
            ends = sorted(optimize.brentq(f, -1.0, 1.0, args=(c,), xtol=1e-14) for c in (band, -band))
            return (
                math.exp(-0.5 * (br / s) ** 2) / (s * math.sqrt(2 * math.pi)) * (ndtr(ends[0] / s) + ndtr(-ends[1] / s))
            )

        return integrate.quad(inner, -12 * s, 12 * s, epsabs=0, epsrel=1e-8, limit=200)[0]
