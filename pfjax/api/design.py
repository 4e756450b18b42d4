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
        ``h2_norm`` and its poles ``closed_loop_poles``. Pass it as ``gains`` to :func:`simulate` with ``"state_feedback"``.

    Raises:
        InputError: a bad argument, named (``v``, ``L``, ``alpha``, ``beta``, ``region.<field>``);
            no design at these values (the LMIs infeasible, the solver failing): a
            :class:`pfjax.errors.NoDesignError` naming ``region`` where one is given, else ``v/L``
            (and ``alpha``, ``beta`` where not the source's: ``v/L/alpha``; :func:`synthesized`),
            as ``pfjax synth`` refuses them.
    """
    return synthesized("mixed", v=v, L=L, region=_region(region), alpha=alpha, beta=beta)


def synthesized(method: str, *, v: float, L: float, region=None, **weights):
    """:func:`pfjax.synthesis.synthesize` for a caller's values (:func:`design_mixed`, ``pfjax
    synth``): a synthesis that finds no design is a one-line :class:`~pfjax.errors.NoDesignError`
    (an ``InputError`` and a ``SynthesisError`` with the solver's status) naming what the caller can
    change: ``region`` where a pole region is given, else ``v/L``, with the operating point and the
    solver's verdict. Weights other than the source's (:func:`~pfjax.synthesis.synthesize`'s
    defaults, ``alpha`` 10, ``beta`` 1) are named with
    ``v/L`` and shown: a weight ratio of many decades can leave the solver without a design where
    the source's weights find one."""
    from pfjax.synthesis import SynthesisError, synthesize
    from pfjax.synthesis.lmi import SOURCE_WEIGHTS

    try:
        return synthesize(method, v=v, L=L, region=region, **weights)
    except errors.NoDesignError:
        raise
    except SynthesisError as e:  # the operating point, the weights or the region: the solver found none
        changed = {k: w for k, w in weights.items() if w is not None and w != SOURCE_WEIGHTS.get(k)}
        key = "region" if region is not None else "/".join(["v", "L", *changed])
        what = "with its closed-loop poles there" if region is not None else ""
        shown = "".join(f", {k} {w:g}" for k, w in changed.items())
        raise errors.NoDesignError(
            f"{key}: the solver found no {method} design{' ' + what if what else ''} at speed {v:g} m/s, "
            f"wheelbase {L:g} m{shown} ({e})",
            key,
            e.status,
        ) from None


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
