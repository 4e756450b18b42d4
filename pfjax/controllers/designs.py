"""Designed controllers: gains computed by a synthesis (LMIs, cvxpy) for a registered controller.

A study's ``controllers[i].type`` and ``pfjax simulate --controller`` take these names beside the
registry's (:mod:`pfjax.controllers.registry`): ``lmi`` (``mixed`` on the command line) is the
mixed H2/H∞ state feedback of the source's design problem at the nominal speed and wheelbase,
``integral_lmi`` the same criterion on the plant augmented with the integral of ``d`` (integral
action), ``polytopic_integral_lmi`` (``polytopic-integral``) the integral design with one Lyapunov
matrix over the polytope of operating points ``v ∈ [0.8 v, 1.2 v]`` (the nominal speed ±20 %),
``|β_r| <= 10°`` (:func:`pfjax.synthesis.polytopic_mixed`), ``paper_k`` the state feedback with the source's published gain (no synthesis). The synthesis is imported only when a design is made (cvxpy takes seconds to import), and
a design once made is read back from disk by later processes (:func:`pfjax.cache.memoized_design`:
keyed by its arguments, the synthesis code and the solver versions).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

from pfjax.cache import memoized_design
from pfjax.controllers.registry import reserve


class DesignEntry(NamedTuple):
    """One design: ``make(v, L, alpha, beta) -> scalar gains`` of ``controller`` (a registry name).
    ``fixed``: its gains do not depend on the operating point (``paper_k``, the source's published
    gain), so a study scaled to another vehicle scales them as it scales a registered controller's."""

    name: str
    controller: str
    cli_name: str
    make: Callable[..., dict]
    style: dict
    fixed: bool = False


def _mixed(v: float, L: float, alpha: float = 10.0, beta: float = 1.0) -> dict:
    def compute():
        from pfjax.synthesis import mixed_h2_hinf, slip_design_plant

        K = mixed_h2_hinf(slip_design_plant(v, L), alpha=alpha, beta=beta).K.ravel()
        return {"k_d": float(K[0]), "k_theta": float(K[1])}

    return memoized_design("lmi", dict(v=v, L=L, alpha=alpha, beta=beta), compute)


def _paper_k(v: float, L: float, alpha: float = 10.0, beta: float = 1.0) -> dict:
    from pfjax.controllers.linear import PAPER_K

    return {"k_d": PAPER_K[0], "k_theta": PAPER_K[1]}


def _integral_gains(K) -> dict:
    """The integral controller's scalar gains from an augmented-plant gain ``K = [k_d, k_θ, k_i]``."""
    K = K.ravel()
    return {"k_d": float(K[0]), "k_theta": float(K[1]), "k_i": float(K[2])}


def _integral(v: float, L: float, alpha: float = 10.0, beta: float = 1.0) -> dict:
    def compute():
        from pfjax.synthesis import integral_mixed

        return _integral_gains(integral_mixed(v, L, alpha=alpha, beta=beta).K)

    return memoized_design("integral_lmi", dict(v=v, L=L, alpha=alpha, beta=beta), compute)


#: The polytope of :func:`_polytopic_integral`: speeds ``v (1 ± POLYTOPE_SPEED)``, ``|β_r| <= POLYTOPE_SLIP_DEG``.
POLYTOPE_SPEED = 0.2
POLYTOPE_SLIP_DEG = 10.0


def _polytopic_integral(v: float, L: float, alpha: float = 10.0, beta: float = 1.0) -> dict:
    args = dict(v_range=(v * (1 - POLYTOPE_SPEED), v * (1 + POLYTOPE_SPEED)), beta_r_max_deg=POLYTOPE_SLIP_DEG, L=L)

    def compute():
        from pfjax.synthesis import polytopic_mixed

        return _integral_gains(polytopic_mixed(**args, integral=True, alpha=alpha, beta=beta).K)

    return memoized_design("polytopic_integral_lmi", dict(args, alpha=alpha, beta=beta), compute)


def design_gains(d: DesignEntry, v: float, L: float, key: str, *, operating=("v", "L"), **kw) -> dict:
    """``d.make(v, L, **kw)`` for a controller a study, command or API call asks for under ``key``: a
    synthesis that fails (infeasible, ill-conditioned, a solver error) is a
    :class:`~pfjax.errors.NoDesignError` (an ``InputError`` and a ``SynthesisError``) naming ``key``,
    with the solver's status and the operating point, in one line (the controller cannot be built,
    so nothing is run; :func:`pfjax.api.design.synthesized` names the operating point instead, for
    a design asked for by its values). The operating point
    is checked first: ``v`` (m/s) and ``L`` (m) finite and positive, an
    :class:`~pfjax.errors.InputError` naming ``v`` or ``L`` by the caller's names ``operating``."""
    from pfjax import errors
    from pfjax.errors import NoDesignError, SynthesisError

    errors.numbers(operating[0], v, positive=True, unit=" m/s")
    errors.numbers(operating[1], L, positive=True, unit=" m")
    try:
        return d.make(v, L, **kw)
    except SynthesisError as e:
        given = "".join(f", {k} {val:g}" for k, val in kw.items() if val is not None)
        raise NoDesignError(
            f"{key}: {e} (the {d.name} design at speed {v:g} m/s, wheelbase {L:g} m{given})", key, e.status
        ) from None


#: name -> design.
DESIGNS: dict[str, DesignEntry] = {
    "lmi": DesignEntry(
        "lmi", "state_feedback", "mixed", _mixed, {"color": "#1f77b4", "lw": 1.8, "label": "mixed H2/H∞ (pfjax LMI)"}
    ),
    "paper_k": DesignEntry(
        "paper_k",
        "state_feedback",
        "paper-k",
        _paper_k,
        {"color": "#17becf", "lw": 1.2, "ls": "--", "label": "mixed H2/H∞ (source K)"},
        fixed=True,
    ),
    "integral_lmi": DesignEntry(
        "integral_lmi",
        "integral",
        "integral-mixed",
        _integral,
        {"color": "#ff7f0e", "lw": 1.6, "label": "mixed H2/H∞ with integral action (LMI)"},
    ),
    "polytopic_integral_lmi": DesignEntry(
        "polytopic_integral_lmi",
        "integral",
        "polytopic-integral",
        _polytopic_integral,
        {"color": "#8c564b", "lw": 1.6, "label": "polytopic mixed H2/H∞ with integral action (LMI)"},
    ),
}


# A design is resolved before the registry (pfjax.controllers.entry): register keeps its names free.
for _d in DESIGNS.values():
    reserve((_d.name, _d.cli_name), f"the {_d.name} design")


def controller_types() -> list[str]:
    """Every name a study's controller ``type`` may take: the registry's and the designs'."""
    from pfjax.controllers.registry import REGISTRY

    return list(REGISTRY) + list(DESIGNS)


def cli_names() -> list[str]:
    """Every command-line controller name: the designs' then the registry's."""
    from pfjax.controllers.registry import REGISTRY

    return [d.cli_name for d in DESIGNS.values()] + [e.cli_name for e in REGISTRY.values()]


def design(name: str) -> DesignEntry | None:
    """The design called ``name`` (config or command-line name), None if it is not a design."""
    return DESIGNS.get(name) or next((d for d in DESIGNS.values() if d.cli_name == name), None)


def resolve(name: str, key: str = "controller"):
    """``(registry entry, design or None)`` of any controller name (registry, design, config or
    command-line spelling); :class:`~pfjax.errors.InputError` naming ``key`` if unknown."""
    from pfjax import errors
    from pfjax.controllers.registry import REGISTRY, entry

    d = design(name)
    if d is not None:
        return REGISTRY[d.controller], d
    if name in REGISTRY or any(e.cli_name == name for e in REGISTRY.values()):
        return entry(name, key), None
    raise errors.InputError(f"{key}: unknown controller {name!r}; expected one of {', '.join(controller_types())}", key)


def style(name: str) -> dict:
    """The plot style (matplotlib ``color``, ``lw``, ``ls``, ``label``) of any controller name;
    grey for an unknown one."""
    try:
        e, d = resolve(name)
    except ValueError:
        return {"color": "#7f7f7f", "lw": 1.0, "label": name}
    return dict((d or e).style)
