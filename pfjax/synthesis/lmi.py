"""State-feedback H-infinity, H2 and mixed H2/H-infinity synthesis by LMIs (source eq. 8-13).

Formulation of the MATLAB LMI Control Toolbox ``msfsyn`` (Chilali & Gahinet 1996; Scherer,
Gahinet & Chilali 1997): static state feedback ``u = K x``, one common Lyapunov matrix
``X = P^-1 > 0`` for every specification, and the change of variables ``Y = K X`` that makes all
conditions linear in ``(X, Y, gamma_inf^2, W)``. Solved with cvxpy + Clarabel. NumPy in, NumPy
out; never traced or jitted.

Strict inequalities. An LMI ``F < 0`` is imposed as ``F <= -eps I`` and ``X > 0`` as
``X >= eps I`` (``eps`` = 1e-7 by default). The margin makes every reported bound a strict,
guaranteed bound on the true closed-loop norm; it moves the optimum by O(eps) only.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cvxpy as cp
import numpy as np

from pfjax.synthesis.norms import closed_loop, h2_norm, hinf_norm
from pfjax.synthesis.plant import Plant, slip_design_plant
from pfjax.synthesis.regions import PoleRegion, region_constraints

__all__ = [
    "Design",
    "SynthesisError",
    "h2_state_feedback",
    "hinf_state_feedback",
    "mixed_bounds_for_gain",
    "mixed_h2_hinf",
    "synthesize",
]

_SOLVER = "CLARABEL"
_ACCEPTED = ("optimal", "optimal_inaccurate")


class SynthesisError(ValueError):
    """An LMI synthesis problem was infeasible, unbounded, numerically ill-conditioned or the solver
    failed. ``status`` carries the solver's status (``"infeasible"``, ``"unbounded"``,
    ``"infeasible_inaccurate"``, ``"solver_error"``, ...) or ``"ill_conditioned"``."""

    def __init__(self, message: str, status: str | None = None):
        super().__init__(message)
        self.status = status


#: ``cond(X)`` above which ``K = Y X^-1`` is not trusted (SynthesisError "ill_conditioned");
#: above ``_COND_WARN`` the design carries a warning.
_COND_MAX = 1e14
_COND_WARN = 1e9
#: relative tolerance of the bound check (true norm <= LMI bound), covering solver accuracy.
_BOUND_RTOL = 1e-5


def bound_warnings(gamma_inf, gamma_2, hinf_true, h2_true, cond_X=None) -> tuple:
    """Disagreements between LMI bounds and the independently computed true norms.

    A valid design has ``||T_inf||_inf <= gamma_inf`` and ``||T_2||_2 <= gamma_2``; a true norm
    above its bound by more than ``_BOUND_RTOL`` (relative) means the solver's answer is not a
    certificate. Returns one message per disagreement (empty when all agree); each is also
    issued as a ``RuntimeWarning``.
    """
    import warnings

    out = []
    for name, bound, true in (("H-inf", gamma_inf, hinf_true), ("H2", gamma_2, h2_true)):
        if bound is not None and not (true <= bound * (1 + _BOUND_RTOL) + 1e-9):
            out.append(f"true {name} norm {true:.6g} exceeds its LMI bound {bound:.6g}")
    if cond_X is not None and cond_X > _COND_WARN:
        out.append(f"Lyapunov matrix ill-conditioned: cond(X) = {cond_X:.3g}")
    for msg in out:
        warnings.warn(msg, RuntimeWarning, stacklevel=3)
    return tuple(out)


@dataclass(frozen=True)
class Design:
    """Result of a state-feedback LMI synthesis.

    Attributes:
        method: ``"hinf"``, ``"h2"`` or ``"mixed"``.
        K: (n_u, n_x) gain of ``u = K x`` (for the slip plant (1, 2), rad/m and rad/rad).
        gamma_inf: LMI bound ``gamma_inf > ||T_{w->z_inf}||_inf`` (None for pure H2).
        gamma_2: LMI bound ``gamma_2 = sqrt(trace W) > ||T_{w->z2}||_2`` (None for pure H-inf).
        hinf_norm: true closed-loop ``||T_{w->z_inf}||_inf`` (:func:`norms.hinf_norm`).
        h2_norm: true closed-loop ``||T_{w->z2}||_2`` (:func:`norms.h2_norm`).
        closed_loop_poles: (n_x,) complex eigenvalues of ``A + Bu K``, 1/s.
        solver: the conic solver used.
        solver_status: cvxpy status (``"optimal"`` or ``"optimal_inaccurate"``).
        alpha: weight on ``gamma_inf^2`` in the mixed objective (None otherwise).
        beta: weight on ``gamma_2^2`` in the mixed objective (None otherwise).
        warnings: disagreements of the true norms with the LMI bounds, conditioning
            (:func:`bound_warnings`; empty for a clean design).
    """

    method: str
    K: np.ndarray
    gamma_inf: float | None
    gamma_2: float | None
    hinf_norm: float
    h2_norm: float
    closed_loop_poles: np.ndarray
    solver: str
    solver_status: str
    alpha: float | None
    beta: float | None
    warnings: tuple = ()

    def to_dict(self) -> dict:
        """JSON-serialisable view: lists and floats, poles as ``[[re, im], ...]``.

        Non-finite norms (never produced by a successful synthesis) become ``None``.
        """

        def num(x):
            if x is None:
                return None
            x = float(x)
            return x if math.isfinite(x) else None

        return {
            "method": self.method,
            "K": np.asarray(self.K, dtype=float).tolist(),
            "gamma_inf": num(self.gamma_inf),
            "gamma_2": num(self.gamma_2),
            "hinf_norm": num(self.hinf_norm),
            "h2_norm": num(self.h2_norm),
            "closed_loop_poles": [[float(p.real), float(p.imag)] for p in np.asarray(self.closed_loop_poles)],
            "solver": self.solver,
            "solver_status": self.solver_status,
            "alpha": num(self.alpha),
            "beta": num(self.beta),
            "warnings": list(self.warnings),
        }


def _sym(M):
    """Symmetric part, so that cvxpy accepts the expression in a semidefinite constraint."""
    return 0.5 * (M + M.T)


def _solve_or_raise(prob: cp.Problem, what: str) -> str:
    """Solve with Clarabel; return the cvxpy status or raise a one-line :class:`SynthesisError`.

    ``optimal`` and ``optimal_inaccurate`` are accepted (the status is recorded in the
    :class:`Design`); ``infeasible``, ``unbounded``, their ``_inaccurate`` variants and solver
    errors raise.
    """
    try:
        prob.solve(solver=_SOLVER)
    except cp.error.SolverError as exc:
        msg = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
        raise SynthesisError(f"{what} failed: solver {_SOLVER} status 'solver_error' ({msg})", "solver_error") from exc
    status = str(prob.status)
    if status not in _ACCEPTED or any(v.value is None for v in prob.variables()):
        raise SynthesisError(f"{what} failed: solver {_SOLVER} status '{status}'", status)
    return status


def solved(v) -> np.ndarray:
    """The value of a cvxpy variable or expression after a successful solve, as an array."""
    if v is None or v.value is None:
        raise RuntimeError("solved: no value (the problem was not solved)")
    return np.asarray(v.value, dtype=float)


def gain_from(X, Y, what: str) -> tuple[np.ndarray, float]:
    """``K = Y X^-1`` and ``cond(X)``; raises ``SynthesisError("ill_conditioned")`` beyond ``_COND_MAX``."""
    Xv = 0.5 * (X + X.T)
    cond = float(np.linalg.cond(Xv))
    if not np.isfinite(cond) or cond > _COND_MAX:
        raise SynthesisError(
            f"{what} failed: Lyapunov matrix ill-conditioned (cond(X) = {cond:.3g})", "ill_conditioned"
        )
    return np.linalg.solve(Xv.T, np.asarray(Y).T).T, cond


def _hinf_lmi(plant: Plant, X, Y, g_sq, eps: float):
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
    return [_sym(F) << -eps * np.eye(n_x + n_w + n_z)]


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
        _sym(lyap) << -eps * np.eye(n_x),
        _sym(F) >> eps * np.eye(n_z + n_x),
    ]


def _solve(
    method: str,
    plant: Plant,
    *,
    use_hinf: bool,
    use_h2: bool,
    alpha: float | None,
    beta: float | None,
    region: PoleRegion | None,
    gamma_inf_max: float | None,
    gamma_2_max: float | None,
    eps: float,
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
        cons += _hinf_lmi(plant, X, Y, g_sq, eps)
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

    status = _solve_or_raise(cp.Problem(cp.Minimize(objective), cons), f"{method} synthesis")

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
        solver=_SOLVER,
        solver_status=status,
        alpha=None if alpha is None else float(alpha),
        beta=None if beta is None else float(beta),
        warnings=bound_warnings(gamma_inf, gamma_2, hn, h2n, cond),
    )


def hinf_state_feedback(plant: Plant, region: PoleRegion | None = None, eps: float = 1e-7) -> Design:
    """H-infinity-optimal state feedback (bounded-real lemma, source eq. 8-11).

    Minimises ``gamma_inf^2`` subject to the bounded-real-lemma LMI of :func:`_hinf_lmi`,
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
    return _solve(
        "hinf",
        plant,
        use_hinf=True,
        use_h2=False,
        alpha=None,
        beta=None,
        region=region,
        gamma_inf_max=None,
        gamma_2_max=None,
        eps=eps,
    )


def h2_state_feedback(plant: Plant, region: PoleRegion | None = None, eps: float = 1e-7) -> Design:
    """H2-optimal state feedback (Lyapunov/trace conditions, source eq. 8-11).

    Minimises ``gamma_2^2 = trace W`` subject to the H2 LMIs of :func:`_h2_lmis`, ``X > 0`` and
    the optional pole-region LMIs; ``K = Y X^-1``. Without a region this is the LQR gain for
    ``Q = C2' C2``, ``R = D2u' D2u`` (here ``Q = I2``, ``R = 1``).

    Raises:
        SynthesisError: the LMIs are infeasible or the solver fails.
    """
    return _solve(
        "h2",
        plant,
        use_hinf=False,
        use_h2=True,
        alpha=None,
        beta=None,
        region=region,
        gamma_inf_max=None,
        gamma_2_max=None,
        eps=eps,
    )


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
    ``(1.1023, 4.0632)``, an objective 3e-5 above the optimum.

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
    if alpha < 0 or beta < 0 or (alpha == 0 and beta == 0):
        raise ValueError(f"mixed_h2_hinf needs alpha, beta >= 0, not both 0; got {alpha}, {beta}")
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
    cons += _hinf_lmi(plant, X, Y, g_sq, eps) + _h2_lmis(plant, X, Y, W, eps)
    objective = cp.Minimize(float(alpha) * g_sq + float(beta) * cp.trace(W))
    _solve_or_raise(cp.Problem(objective, cons), "mixed bounds for gain")
    return float(np.sqrt(max(float(solved(g_sq)), 0.0))), float(np.sqrt(max(float(np.trace(solved(W))), 0.0)))


_METHODS = ("hinf", "h2", "mixed")


def synthesize(
    method: str,
    v: float = 1.0,
    L: float = 0.2,
    alpha: float = 10.0,
    beta: float = 1.0,
    region: PoleRegion | None = None,
) -> Design:
    """Design a gain for the slip plant :func:`slip_design_plant` ``(v, L)`` (CLI entry point).

    Args:
        method: ``"hinf"``, ``"h2"`` or ``"mixed"``.
        v: speed, m/s.
        L: wheelbase, m.
        alpha: mixed-objective weight on ``gamma_inf^2`` (``"mixed"`` only).
        beta: mixed-objective weight on ``gamma_2^2`` (``"mixed"`` only).
        region: optional pole region.

    Raises:
        InputError: unknown ``method``, or a value out of range (the message names it).
        SynthesisError: the LMIs are infeasible or the solver fails.
    """
    from pfjax import errors

    if method not in _METHODS:
        raise errors.InputError(f"method: expected one of {', '.join(_METHODS)}, got {method!r}")
    errors.number("v", v, positive=True, unit=" m/s")
    errors.number("L", L, positive=True, unit=" m")
    if method == "mixed":
        errors.number("alpha", alpha, nonnegative=True)
        errors.number("beta", beta, nonnegative=True)
        if alpha + beta == 0:
            raise errors.InputError("alpha: must not be 0 together with beta (the mixed objective would be empty)")
    plant = slip_design_plant(v=v, L=L)
    if method == "hinf":
        return hinf_state_feedback(plant, region=region)
    if method == "h2":
        return h2_state_feedback(plant, region=region)
    return mixed_h2_hinf(plant, alpha=alpha, beta=beta, region=region)
