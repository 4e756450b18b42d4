"""The conic solver's edge for pfjax's LMI syntheses: solving, reading values, the gain, the result.

Every synthesis (:mod:`pfjax.synthesis.lmi`, :mod:`pfjax.synthesis.robust`) poses its LMIs in cvxpy
and goes through these: :func:`solve_or_raise` (Clarabel; a failed solve is a one-line
:class:`SynthesisError` with the solver's status), :func:`solved` (a variable's value),
:func:`gain_from` (``K = Y X^-1`` with a conditioning check), :func:`bound_warnings` (the LMI bounds
against the true norms) and :class:`Design`, the result of a state-feedback synthesis.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cvxpy as cp
import numpy as np

from pfjax.errors import SynthesisError  # its home: a light module, so callers catch it without cvxpy

__all__ = ["SOLVER", "Design", "SynthesisError", "bound_warnings", "gain_from", "solve_or_raise", "solved", "sym"]

SOLVER = "CLARABEL"
_ACCEPTED = ("optimal", "optimal_inaccurate")

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
            (:func:`bound_warnings`), a solver status short of ``optimal``, and from
            :func:`pfjax.synthesis.synthesize` a gain too large to use
            (:func:`pfjax.synthesis.lmi.gain_warnings`); empty for a clean design.
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


def sym(M):
    """Symmetric part, so that cvxpy accepts the expression in a semidefinite constraint."""
    return 0.5 * (M + M.T)


def solve_or_raise(prob: cp.Problem, what: str) -> str:
    """Solve with Clarabel; return the cvxpy status or raise a one-line :class:`SynthesisError`.

    ``optimal`` and ``optimal_inaccurate`` are accepted (the status is recorded in the
    :class:`Design`, so cvxpy's own two-line warning for an inaccurate solution is not printed);
    ``infeasible``, ``unbounded``, their ``_inaccurate`` variants and solver errors raise.
    """
    import warnings

    try:
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", message="Solution may be inaccurate", category=UserWarning)
            prob.solve(solver=SOLVER)
    except cp.error.SolverError as exc:
        msg = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
        raise SynthesisError(f"{what} failed: solver {SOLVER} status 'solver_error' ({msg})", "solver_error") from exc
    status = str(prob.status)
    if status not in _ACCEPTED or any(v.value is None for v in prob.variables()):
        raise SynthesisError(f"{what} failed: solver {SOLVER} status '{status}'", status)
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
