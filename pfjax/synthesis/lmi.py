"""State-feedback H-infinity, H2 and mixed H2/H-infinity synthesis by LMIs (source eq. 8-13).

Formulation of the MATLAB LMI Control Toolbox ``msfsyn`` (Chilali & Gahinet 1996; Scherer,
Gahinet & Chilali 1997): static state feedback ``u = K x``, one common Lyapunov matrix
``X = P^-1 > 0`` for every specification, and the change of variables ``Y = K X`` that makes all
conditions linear in ``(X, Y, gamma_inf^2, W)``. Solved with cvxpy + Clarabel. NumPy in, NumPy
out; never traced or jitted.

Strict inequalities. An LMI ``F < 0`` is imposed as ``F <= -eps I`` and ``X > 0`` as
``X >= eps I`` (``eps`` = 1e-7 by default). With the solver at ``optimal`` the margin makes every
reported bound a strict, guaranteed bound on the true closed-loop norm; it moves the optimum by
O(eps) only. At a status short of optimal (``optimal_inaccurate``) a bound can fall below the true
norm: the design warns of the status, and the norms recomputed from K are checked against the
bounds and warned of where one is exceeded.
"""

from __future__ import annotations

import dataclasses

import cvxpy as cp
import numpy as np

from pfjax.synthesis.norms import closed_loop, h2_norm, hinf_norm
from pfjax.synthesis.plant import Plant, slip_design_plant
from pfjax.synthesis.regions import PoleRegion, region_constraints
from pfjax.synthesis.solver import (
    SOLVER,
    Design,
    SynthesisError,
    bound_warnings,
    gain_from,
    solve_or_raise,
    solved,
    sym,
)

__all__ = [
    "MAX_POLE_RATIO",
    "SOURCE_WEIGHTS",
    "Design",
    "SynthesisError",
    "gain_warnings",
    "h2_state_feedback",
    "hinf_state_feedback",
    "mixed_bounds_for_gain",
    "mixed_h2_hinf",
    "synthesize",
]

#: The mixed design's weights when not given: the source's (``alpha`` on ``gamma_inf^2``, ``beta`` on
#: ``gamma_2^2``; docs/reproductions/path-following.md §4).
SOURCE_WEIGHTS = {"alpha": 10.0, "beta": 1.0}


def hinf_lmi(plant: Plant, X, Y, g_sq, eps: float):
    """Bounded-real lemma with the substitution ``Y = K X`` (source Theorems 1-3, eq. 8-11)::

        [[A X + X A' + Bu Y + Y' Bu',  Bw,    (Cinf X + Dinf_u Y)'],
         [Bw',                        -I,      0                  ],
         [Cinf X + Dinf_u Y,           0,     -gamma_inf^2 I      ]]  < 0

    implies ``||T_{w->z_inf}||_inf < gamma_inf``. ``gamma_inf^2`` enters linearly (msfsyn form).
    """
    n_x, n_w = plant.Bw.shape
    n_z = plant.Cinf.shape[0]
    M = plant.A @ X + plant.Bu @ Y
    Z = plant.Cinf @ X + plant.Dinf_u @ Y
    F = cp.bmat(
        [
            [M + M.T, plant.Bw, Z.T],
            [plant.Bw.T, -np.eye(n_w), np.zeros((n_w, n_z))],
            [Z, np.zeros((n_z, n_w)), -g_sq * np.eye(n_z)],
        ]
    )
    return [sym(F) << -eps * np.eye(n_x + n_w + n_z)]


def _h2_lmis(plant: Plant, X, Y, W, eps: float):
    """H2 conditions with ``Y = K X`` (source Theorems 2-3, eq. 8-11)::

        A X + X A' + Bu Y + Y' Bu' + Bw Bw' < 0
        [[W, C2 X + D2u Y], [(C2 X + D2u Y)', X]] > 0,   gamma_2^2 = trace W

    imply ``||T_{w->z2}||_2 < gamma_2`` (``X`` bounds the controllability Gramian).
    """
    n_x = plant.A.shape[0]
    n_z = plant.C2.shape[0]
    M = plant.A @ X + plant.Bu @ Y
    Z = plant.C2 @ X + plant.D2u @ Y
    lyap = M + M.T + plant.Bw @ plant.Bw.T
    F = cp.bmat([[W, Z], [Z.T, X]])
    return [
        sym(lyap) << -eps * np.eye(n_x),
        sym(F) >> eps * np.eye(n_z + n_x),
    ]


def _solve(
    method: str,
    plant: Plant,
    *,
    use_hinf: bool,
    use_h2: bool,
    region: PoleRegion | None,
    eps: float,
    alpha: float | None = None,
    beta: float | None = None,
    gamma_inf_max: float | None = None,
    gamma_2_max: float | None = None,
) -> Design:
    plant = Plant(*(np.asarray(m, dtype=float) for m in plant))
    n_x = plant.A.shape[0]
    n_u = plant.Bu.shape[1]
    X = cp.Variable((n_x, n_x), symmetric=True)
    Y = cp.Variable((n_u, n_x))
    cons = [X >> eps * np.eye(n_x)]
    objective = 0
    g_sq = W = None
    if use_hinf:
        g_sq = cp.Variable(nonneg=True)  # gamma_inf^2
        cons += hinf_lmi(plant, X, Y, g_sq, eps)
        if gamma_inf_max is not None:
            cons.append(g_sq <= float(gamma_inf_max) ** 2)
        objective = objective + (1.0 if alpha is None else float(alpha)) * g_sq
    if use_h2:
        n_z2 = plant.C2.shape[0]
        W = cp.Variable((n_z2, n_z2), symmetric=True)
        cons += _h2_lmis(plant, X, Y, W, eps)
        if gamma_2_max is not None:
            cons.append(cp.trace(W) <= float(gamma_2_max) ** 2)
        objective = objective + (1.0 if beta is None else float(beta)) * cp.trace(W)
    if region is not None:
        cons += region_constraints(region, plant.A @ X + plant.Bu @ Y, X, eps)

    status = solve_or_raise(cp.Problem(cp.Minimize(objective), cons), f"{method} synthesis")

    K, cond = gain_from(X.value, Y.value, f"{method} synthesis")  # K = Y X^-1
    Acl, Bw, Cinf_cl, C2_cl = closed_loop(plant, K)
    gamma_inf = float(np.sqrt(max(float(solved(g_sq)), 0.0))) if use_hinf else None
    gamma_2 = float(np.sqrt(max(float(np.trace(solved(W))), 0.0))) if use_h2 else None
    hn, h2n = hinf_norm(Acl, Bw, Cinf_cl), h2_norm(Acl, Bw, C2_cl)
    return Design(
        method=method,
        K=K,
        gamma_inf=gamma_inf,
        gamma_2=gamma_2,
        hinf_norm=hn,
        h2_norm=h2n,
        closed_loop_poles=np.linalg.eigvals(Acl).astype(complex),
        solver=SOLVER,
        solver_status=status,
        alpha=None if alpha is None else float(alpha),
        beta=None if beta is None else float(beta),
        warnings=bound_warnings(gamma_inf, gamma_2, hn, h2n, cond) + _status_warnings(status, method),
    )


def _status_warnings(status: str, method: str) -> tuple:
    """A solver status short of ``optimal`` (``optimal_inaccurate``, which :func:`solve_or_raise`
    accepts) as one message, also issued as a ``RuntimeWarning``; empty for ``optimal``."""
    import warnings

    if status == "optimal":
        return ()
    msg = (
        f"{method} synthesis: solver {SOLVER} status {status!r}, not 'optimal': it stopped short of its accuracy "
        "tolerances, so K and the LMI bounds are approximate (the true norms are those of K as returned)"
    )
    warnings.warn(msg, RuntimeWarning, stacklevel=4)
    return (msg,)


def hinf_state_feedback(plant: Plant, region: PoleRegion | None = None, eps: float = 1e-7) -> Design:
    """H-infinity-optimal state feedback (bounded-real lemma, source eq. 8-11).

    Minimises ``gamma_inf^2`` subject to the bounded-real-lemma LMI of :func:`hinf_lmi`,
    ``X > 0`` and the optional pole-region LMIs; ``K = Y X^-1``.

    For the slip plant ``z_inf = x`` carries no control penalty, so the problem is singular and
    the infimum is approached with growing gains; the reported bound is still guaranteed.

    Args:
        plant: generalised plant.
        region: optional LMI region for the closed-loop poles.
        eps: strictness margin of the LMIs.

    Raises:
        SynthesisError: the LMIs are infeasible or the solver fails.
    """
    return _solve("hinf", plant, use_hinf=True, use_h2=False, region=region, eps=eps)


def h2_state_feedback(plant: Plant, region: PoleRegion | None = None, eps: float = 1e-7) -> Design:
    """H2-optimal state feedback (Lyapunov/trace conditions, source eq. 8-11).

    Minimises ``gamma_2^2 = trace W`` subject to the H2 LMIs of :func:`_h2_lmis`, ``X > 0`` and
    the optional pole-region LMIs; ``K = Y X^-1``. Without a region this is the LQR gain for
    ``Q = C2' C2``, ``R = D2u' D2u`` (here ``Q = I2``, ``R = 1``).

    Raises:
        SynthesisError: the LMIs are infeasible or the solver fails.
    """
    return _solve("h2", plant, use_hinf=False, use_h2=True, region=region, eps=eps)


def check_weights(alpha, beta) -> None:
    """The mixed objective's weights ``alpha gamma_inf^2 + beta gamma_2^2``: finite, at least 0, not
    both 0 (the objective would be empty); :class:`~pfjax.errors.InputError` naming ``alpha`` or ``beta``."""
    from pfjax import errors

    errors.number("alpha", alpha, nonnegative=True)
    errors.number("beta", beta, nonnegative=True)
    if alpha + beta == 0:
        raise errors.InputError("alpha: must not be 0 together with beta (the mixed objective would be empty)", "alpha")


def mixed_h2_hinf(
    plant: Plant,
    alpha: float = 10.0,
    beta: float = 1.0,
    region: PoleRegion | None = None,
    gamma_inf_max: float | None = None,
    gamma_2_max: float | None = None,
    eps: float = 1e-7,
) -> Design:
    """Mixed H2/H-infinity state feedback, ``msfsyn`` convention (source eq. 13).

    ::

        minimise   alpha gamma_inf^2 + beta trace W        over X > 0, Y, gamma_inf^2, W
        subject to H-inf LMI and H2 LMIs (eq. 8-11) with one common X,
                   gamma_inf <= gamma_inf_max, sqrt(trace W) <= gamma_2_max  (if given),
                   pole-region LMIs (if given);             K = Y X^-1

    i.e. ``msfsyn(P, r, [gamma_inf_max, gamma_2_max, alpha, beta], region)`` with 0 meaning
    "no bound". The returned ``gamma_inf`` and ``gamma_2 = sqrt(trace W)`` are the guaranteed
    bounds (the toolbox's "guaranteed H-inf / H2 performance").

    Reproduction (docs/reproductions/path-following.md §4, ``v = 1 m/s``, ``L = 0.2 m``, ``alpha = 10``, ``beta = 1``):
    ``K = [-2.7826, -2.0819]``, ``gamma_inf = 1.1008``, ``gamma_2 = 4.0670`` (true norms 1.0820
    and 3.5954) against the source's ``K = [-2.7381, -2.0772]``, 1.1 and 4.07. The objective is
    flat along ``k1``: the source gain is certified by :func:`mixed_bounds_for_gain` at
    ``(1.1023, 4.0632)``, an objective 8.3e-4 (3e-5 relative) above the optimum.

    Args:
        plant: generalised plant.
        alpha: weight on ``gamma_inf^2`` (source: 10).
        beta: weight on ``gamma_2^2`` (source: 1).
        region: optional LMI region for the closed-loop poles.
        gamma_inf_max: optional hard bound on ``gamma_inf``.
        gamma_2_max: optional hard bound on ``gamma_2``.
        eps: strictness margin of the LMIs.

    Raises:
        SynthesisError: the LMIs are infeasible (e.g. ``gamma_inf_max`` too small) or the solver
            fails.
    """
    check_weights(alpha, beta)
    return _solve(
        "mixed",
        plant,
        use_hinf=True,
        use_h2=True,
        alpha=alpha,
        beta=beta,
        region=region,
        gamma_inf_max=gamma_inf_max,
        gamma_2_max=gamma_2_max,
        eps=eps,
    )


def mixed_bounds_for_gain(
    plant: Plant, K, alpha: float = 10.0, beta: float = 1.0, eps: float = 1e-7
) -> tuple[float, float]:
    """Best ``msfsyn`` mixed bounds certified for a *given* gain ``K``.

    Solves the mixed problem of :func:`mixed_h2_hinf` with ``Y = K X`` fixed by ``K`` (an LMI in
    ``X``, ``gamma_inf^2``, ``W`` only). Used to compare a published gain with our optimum: a
    gain whose objective ``alpha gamma_inf^2 + beta gamma_2^2`` is close to the optimal one is a
    legitimate output of an optimiser stopped at that relative accuracy.

    Args:
        plant: generalised plant.
        K: (n_u, n_x) gain.
        alpha: weight on ``gamma_inf^2``.
        beta: weight on ``gamma_2^2``.
        eps: strictness margin of the LMIs.

    Returns:
        ``(gamma_inf, gamma_2)``, the guaranteed bounds for that ``K``.

    Raises:
        SynthesisError: no common ``X`` certifies ``K`` (e.g. ``A + Bu K`` not Hurwitz).
    """
    plant = Plant(*(np.asarray(m, dtype=float) for m in plant))
    n_x = plant.A.shape[0]
    K = np.asarray(K, dtype=float).reshape(plant.Bu.shape[1], n_x)
    X = cp.Variable((n_x, n_x), symmetric=True)
    g_sq = cp.Variable(nonneg=True)
    W = cp.Variable((plant.C2.shape[0],) * 2, symmetric=True)
    Y = K @ X
    cons = [X >> eps * np.eye(n_x)]
    cons += hinf_lmi(plant, X, Y, g_sq, eps) + _h2_lmis(plant, X, Y, W, eps)
    objective = cp.Minimize(float(alpha) * g_sq + float(beta) * cp.trace(W))
    solve_or_raise(cp.Problem(objective, cons), "mixed bounds for gain")
    return float(np.sqrt(max(float(solved(g_sq)), 0.0))), float(np.sqrt(max(float(np.trace(solved(W))), 0.0)))


_METHODS = ("hinf", "h2", "mixed")


#: A design whose fastest closed-loop pole exceeds this many times ``v / L`` is not a usable gain
#: (:func:`gain_warnings`).
MAX_POLE_RATIO = 100.0


def gain_warnings(poles, v: float, L: float) -> list[str]:
    """Whether K is too large to be a usable design, as a list of at most one message (also issued
    as a ``RuntimeWarning``): its fastest closed-loop pole faster than :data:`MAX_POLE_RATIO`
    times ``v / L``. ``v / L`` (1/s) is the yaw rate one radian of steering gives the slip plant
    (its input gain), and the closed loop's rates in units of ``v / L`` depend on the gain alone
    (``k_theta`` and ``k_d L``): a pole 100 times faster needs on the order of 100 rad of steering
    per unit of error, so the steering saturates on any error worth correcting and the linear design
    says nothing about the loop. The H-inf design of this plant is the limit of gains growing
    without bound (its optimum is approached, not reached), which this catches, as it catches a
    solve at a degenerate operating point."""
    import warnings

    import numpy as np

    fastest, scale = float(np.max(np.abs(np.asarray(poles)))), v / L
    if not fastest > MAX_POLE_RATIO * scale:
        return []
    msg = (
        f"K is not a usable design: its fastest closed-loop pole, {fastest:.3g} 1/s, is {fastest / scale:.3g} v/L, "
        f"beyond {MAX_POLE_RATIO:g} v/L = {MAX_POLE_RATIO * scale:.3g} 1/s (v/L: the yaw rate one radian of "
        "steering gives), so the loop needs steering far past any limit on all but vanishing errors (the gain "
        "grows without bound toward the optimum, or the operating point is degenerate); bound the poles with "
        "a pole region (pfjax synth --disk CENTER RADIUS)"
    )
    warnings.warn(msg, RuntimeWarning, stacklevel=3)
    return [msg]


def synthesize(
    method: str,
    v: float = 1.0,
    L: float = 0.2,
    alpha: float | None = None,
    beta: float | None = None,
    region: PoleRegion | None = None,
) -> Design:
    """Design a gain for the slip plant :func:`slip_design_plant` ``(v, L)`` (CLI entry point).

    Args:
        method: ``"hinf"``, ``"h2"`` or ``"mixed"``.
        v: speed, m/s.
        L: wheelbase, m.
        alpha: mixed-objective weight on ``gamma_inf^2`` (``"mixed"`` only, default 10:
            :data:`SOURCE_WEIGHTS`); refused with ``"hinf"`` and ``"h2"``, which do not read it.
        beta: mixed-objective weight on ``gamma_2^2`` (``"mixed"`` only, default 1).
        region: optional pole region.

    Returns:
        The design; its ``warnings`` also say when its gain is too large to use
        (:func:`gain_warnings`: the H-inf design without a pole region, a degenerate operating point).

    Raises:
        InputError: unknown ``method``, or a value out of range (the message names it).
        SynthesisError: the LMIs are infeasible or the solver fails.
    """
    from pfjax import errors

    if method not in _METHODS:
        raise errors.InputError(f"method: expected one of {', '.join(_METHODS)}, got {method!r}")
    errors.number("v", v, positive=True, unit=" m/s")
    errors.number("L", L, positive=True, unit=" m")
    for name, w in (("alpha", alpha), ("beta", beta)):
        if method != "mixed" and w is not None:
            raise errors.InputError(f"{name}: only the mixed design reads it, not method {method!r}", name)
    alpha = SOURCE_WEIGHTS["alpha"] if alpha is None else alpha
    beta = SOURCE_WEIGHTS["beta"] if beta is None else beta
    if method == "mixed":
        check_weights(alpha, beta)
    plant = slip_design_plant(v=v, L=L)
    if method == "hinf":
        design = hinf_state_feedback(plant, region=region)
    elif method == "h2":
        design = h2_state_feedback(plant, region=region)
    else:
        design = mixed_h2_hinf(plant, alpha=alpha, beta=beta, region=region)
    extra = gain_warnings(design.closed_loop_poles, v, L)  # a gain too large to use
    return dataclasses.replace(design, warnings=tuple(design.warnings) + tuple(extra)) if extra else design
