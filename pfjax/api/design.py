"""Controller design through the public API: the mixed H2/H∞ state feedback by LMIs."""

from __future__ import annotations

from pfjax import errors
from pfjax.errors import arguments_checked


@arguments_checked
def design_mixed(v: float = 1.0, L: float = 0.2, alpha: float = 10.0, beta: float = 1.0, region=None):
    """The mixed H2/H∞ state feedback of the slip plant at speed ``v`` (m/s) and wheelbase ``L``
    (m), minimising ``alpha γ∞² + beta γ₂²`` by LMIs (cvxpy + Clarabel).

    Args:
        v: the design speed, m/s, above 0.
        L: the wheelbase, m, above 0.
        alpha: the weight of ``γ∞²`` (dimensionless, at least 0; the source's 10).
        beta: the weight of ``γ₂²`` (dimensionless, at least 0; the source's 1); ``alpha`` and
            ``beta`` may not both be 0.
        region: an optional pole region for the closed loop: a :class:`pfjax.synthesis.PoleRegion`
            or a dict of its fields (``max_real``, ``disk_center``, ``disk_radius``, 1/s;
            ``sector_angle``, rad).

    Returns:
        pfjax.synthesis.Design: ``K`` (1×2: rad/m, rad/rad, for ``[d, θ_e]``), the LMI
        bounds ``gamma_inf``, ``gamma_2``, the closed loop's true norms ``hinf_norm``,
        ``h2_norm`` and its poles. Pass it as ``gains`` to :func:`simulate` with ``"state_feedback"``.

    Raises:
        InputError: a bad argument, named (``v``, ``L``, ``alpha``, ``beta``, ``region.<field>``).
        SynthesisError: the LMIs are infeasible (:class:`pfjax.errors.SynthesisError`, a ``ValueError``).
    """
    from pfjax.synthesis import synthesize

    return synthesize("mixed", v=v, L=L, alpha=alpha, beta=beta, region=_region(region))


def _region(region):
    """``region`` as a :class:`~pfjax.synthesis.PoleRegion` (or None); :class:`~pfjax.errors.InputError`
    naming ``region`` (``region.max_real``, ...) otherwise. The fields are checked by ``PoleRegion``."""
    import dataclasses

    from pfjax.synthesis import PoleRegion

    if region is None or isinstance(region, PoleRegion):
        return region
    fields = [f.name for f in dataclasses.fields(PoleRegion)]
    if not isinstance(region, dict):
        raise errors.InputError(
            f"region: expected a PoleRegion or a dict of {', '.join(fields)}, got {type(region).__name__}", "region"
        )
    unknown = [k for k in region if k not in fields]
    if unknown:
        raise errors.InputError(f"region.{unknown[0]}: unknown field; expected some of {', '.join(fields)}", "region")
    try:
        return PoleRegion(**region)
    except errors.InputError as e:
        raise errors.InputError(f"region.{e}", "region") from None
