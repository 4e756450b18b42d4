"""Controller design through the public API: the mixed H2/H∞ state feedback by LMIs."""

from __future__ import annotations


def design_mixed(v: float = 1.0, L: float = 0.2, alpha: float = 10.0, beta: float = 1.0, region=None):
    """The mixed H2/H∞ state feedback of the slip plant at speed ``v`` (m/s) and wheelbase ``L``
    (m), minimising ``alpha γ∞² + beta γ₂²`` by LMIs (cvxpy + Clarabel).

    Returns:
        a :class:`pfjax.synthesis.Design`: ``K`` (1×2: rad/m, rad/rad, for ``[d, θ_e]``), the LMI
        bounds ``gamma_inf``, ``gamma_2``, the closed loop's true norms ``hinf_norm``,
        ``h2_norm`` and its poles. Pass it as ``gains`` to :func:`simulate` with ``"state_feedback"``.

    Raises:
        InputError: a bad argument. SynthesisError: the LMIs are infeasible.
    """
    from pfjax.synthesis import synthesize

    return synthesize("mixed", v=v, L=L, alpha=alpha, beta=beta, region=region)
