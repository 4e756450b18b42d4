"""Designs beyond the source: integral action, a polytope of operating points, bounded steering.

All three are the mixed H2/H-inf problem of :func:`pfjax.synthesis.lmi.mixed_h2_hinf`
(``minimise alpha gamma_inf^2 + beta gamma_2^2``, ``Y = K X``, one ``X``) with additions:

**Integral action** (:func:`integral_plant`, :func:`integral_mixed`). The state is augmented with
``x_3 = int d dt`` (m s), so ``u = K [d, theta_e, int d]`` (:mod:`pfjax.controllers.integral`)::

    A = [[0, v, 0], [0, 0, 0], [1, 0, 0]],  Bu = [0, v/L, 0]',  Bw = [[v, 0, 0], [-v/L, -v/L, -v], [0, 0, 0]]
    z_inf = x_a,   z2 = [x_a; u]

A Hurwitz ``A + Bu K`` forces ``d -> 0`` under any constant slip (``x_3' = d = 0`` at rest).

**Polytope of operating points** (:func:`polytopic_mixed`). Linearised at the true equilibrium
under constant rear slip ``beta_r`` (:mod:`pfjax.analysis.stability`, source convention), the
error dynamics are ``d' = v sec(beta_r) theta_e``, ``theta_e' = (v/L) sec^2(beta_r) delta + ...``:
``A = [[0, a]]``, ``Bu = [0, b]'`` with ``a = v sec beta_r``, ``b = (v/L) sec^2 beta_r``, and ``Bw``
affine in ``v``. For ``v in [v_lo, v_hi]``, ``|beta_r| <= beta_max`` the triple ``(a, b, v)`` lies
in a box whose 8 vertices give 8 plants. Every LMI is imposed at every vertex with one common
``X``, ``Y`` (quadratic stability and performance): the H-inf LMI and the H2 Lyapunov LMI in its
Schur form ``[[A X + X A' + Bu Y + Y' Bu', Bw], [Bw', -I]] < 0`` are affine in ``(A, Bu, Bw)``, so
they hold on the whole box (hence for every ``(v, beta_r)`` in range) and ``gamma_inf``,
``gamma_2`` bound the norms at every operating point.

**Bounded steering from a given initial error** (``x0s``, ``delta_max`` arguments). The
performance LMIs imply ``(A + Bu K) X + X (A + Bu K)' < 0``, so every ellipsoid
``E_mu = {x : x' (mu X)^-1 x <= 1}``, ``mu > 0``, is invariant for the undisturbed linear loop. The
scale is free: ``X`` itself is sized by the disturbance (it bounds the loop's controllability
Gramian), and fixing ``mu = 1`` would ask the steering bound to hold on the states a unit
disturbance reaches, whatever the initial errors. With ``nu = 1 / mu`` a variable::

    X - nu x0 x0' >= 0                  (x0 in E_mu, for each given initial error x0)
    [[delta_max^2 nu, Y], [Y', X]] >= 0   (|K x| <= delta_max on E_mu: mu K X K' <= delta_max^2)

both affine in ``(X, Y, nu)``, so from any such ``x0`` the command never exceeds ``delta_max`` (an
optional :class:`~pfjax.synthesis.regions.PoleRegion` can be added as well).

Every result is checked independently: the true norms (:mod:`pfjax.synthesis.norms`) at every
vertex must not exceed the LMI bounds (``Design.warnings`` / a ``RuntimeWarning`` otherwise).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import cvxpy as cp
import numpy as np

from pfjax.synthesis.lmi import hinf_lmi
from pfjax.synthesis.norms import closed_loop, h2_norm, hinf_norm
from pfjax.synthesis.plant import Plant, slip_design_plant
from pfjax.synthesis.regions import PoleRegion, region_constraints
from pfjax.synthesis.solver import bound_warnings, gain_from, solve_or_raise, solved, sym


@dataclass(frozen=True)
class RobustDesign:
    """A gain designed over one or several vertex plants.

    Attributes:
        method: ``"integral"``, ``"polytopic"`` or ``"mixed"`` (+ ``"+steer"`` with the steering bound).
        K: (1, n_x) gain of ``u = K x``.
        gamma_inf, gamma_2: LMI bounds valid at every vertex (and, for a polytope, in between).
        hinf_norm, h2_norm: the largest true closed-loop norms over the vertices.
        vertex_poles: (n_vertices, n_x) closed-loop eigenvalues at each vertex, 1/s.
        steer_bound: guaranteed ``max |K x|`` on the invariant ellipsoid (rad), None if not imposed.
        solver_status: cvxpy status.
        warnings: bound / conditioning disagreements (empty for a clean design).
    """

    method: str
    K: np.ndarray
    gamma_inf: float
    gamma_2: float
    hinf_norm: float
    h2_norm: float
    vertex_poles: np.ndarray
    steer_bound: float | None
    solver_status: str
    warnings: tuple = ()

    def to_dict(self) -> dict:
        return {
            "method": self.method,
            "K": np.asarray(self.K).tolist(),
            "gamma_inf": self.gamma_inf,
            "gamma_2": self.gamma_2,
            "hinf_norm": self.hinf_norm,
            "h2_norm": self.h2_norm,
            "max_vertex_pole_real": float(np.max(np.real(self.vertex_poles))),
            "steer_bound": self.steer_bound,
            "solver_status": self.solver_status,
            "warnings": list(self.warnings),
        }


def integral_plant(v: float = 1.0, L: float = 0.2) -> Plant:
    """The slip plant augmented with ``int d dt`` (module docstring)."""
    p = slip_design_plant(v, L)
    A = np.zeros((3, 3))
    A[:2, :2] = p.A
    A[2, 0] = 1.0
    Bu = np.vstack([p.Bu, [[0.0]]])
    Bw = np.vstack([p.Bw, np.zeros((1, 3))])
    return Plant(
        A=A,
        Bw=Bw,
        Bu=Bu,
        Cinf=np.eye(3),
        Dinf_u=np.zeros((3, 1)),
        C2=np.vstack([np.eye(3), np.zeros((1, 3))]),
        D2u=np.array([[0.0], [0.0], [0.0], [1.0]]),
    )


def operating_point_plant(v: float, L: float, beta_r: float, integral: bool = False) -> Plant:
    """Linearisation at the true equilibrium under constant rear slip ``beta_r`` (rad)."""
    p = integral_plant(v, L) if integral else slip_design_plant(v, L)
    A, Bu = p.A.copy(), p.Bu.copy()
    A[0, 1] = v / math.cos(beta_r)
    Bu[1, 0] = (v / L) / math.cos(beta_r) ** 2
    return p._replace(A=A, Bu=Bu)


def polytope_vertices(v_range, beta_r_max: float, L: float = 0.2, integral: bool = False) -> list[Plant]:
    """The 8 vertex plants of the box over ``(v sec beta_r, (v/L) sec^2 beta_r, v)`` (module docstring)."""
    v_lo, v_hi = (float(x) for x in v_range)
    if not 0 < v_lo <= v_hi or not 0 <= beta_r_max < math.pi / 2:
        raise ValueError(
            f"v_range/beta_r_max: need 0 < v_lo <= v_hi and 0 <= beta_r_max < pi/2, got {v_range}, {beta_r_max}"
        )
    sec = 1.0 / math.cos(beta_r_max)
    a_range, b_range = (v_lo, v_hi * sec), (v_lo / L, v_hi * sec**2 / L)
    out = []
    for a, b, v in itertools.product(a_range, b_range, (v_lo, v_hi)):
        p = integral_plant(v, L) if integral else slip_design_plant(v, L)
        A, Bu = p.A.copy(), p.Bu.copy()
        A[0, 1], Bu[1, 0] = a, b
        out.append(p._replace(A=A, Bu=Bu))
    return out


def robust_mixed(
    plants,
    *,
    alpha=10.0,
    beta=1.0,
    x0s=None,
    delta_max=None,
    region: PoleRegion | None = None,
    method="mixed",
    eps=1e-7,
) -> RobustDesign:
    """Mixed H2/H-inf with one ``X``, ``Y`` over all ``plants`` (vertices), optional steering bound.

    Args:
        plants: vertex plants (same shapes).
        alpha: weight of the H-infinity bound, ``gamma_inf^2`` (source: 10).
        beta: weight of the H2 bound, ``gamma_2^2`` (source: 1).
        x0s: (m, n_x) initial errors that must lie in the invariant ellipsoid (with ``delta_max``).
        delta_max: steering limit, rad, enforced on the ellipsoid.
        region: optional pole region, imposed at every vertex.
        method: label of the result.

    Raises:
        SynthesisError: infeasible / unbounded / ill-conditioned (``.status`` says which).
    """
    plants = [Plant(*(np.asarray(m, float) for m in p)) for p in plants]
    n_x, n_u = plants[0].Bu.shape
    X = cp.Variable((n_x, n_x), symmetric=True)
    Y = cp.Variable((n_u, n_x))
    g_sq = cp.Variable(nonneg=True)
    n_z2 = plants[0].C2.shape[0]
    W = cp.Variable((n_z2, n_z2), symmetric=True)
    cons = [X >> eps * np.eye(n_x)]
    for p in plants:
        cons += hinf_lmi(p, X, Y, g_sq, eps)
        M = p.A @ X + p.Bu @ Y
        n_w = p.Bw.shape[1]
        cons.append(sym(cp.bmat([[M + M.T, p.Bw], [p.Bw.T, -np.eye(n_w)]])) << -eps * np.eye(n_x + n_w))
        Z = p.C2 @ X + p.D2u @ Y
        cons.append(sym(cp.bmat([[W, Z], [Z.T, X]])) >> eps * np.eye(n_z2 + n_x))
        if region is not None:
            cons += region_constraints(region, M, X, eps)
    nu = cp.Variable(nonneg=True)  # 1 / mu, the steering ellipsoid's scale (module docstring)
    if delta_max is not None:
        if x0s is None:
            raise ValueError("x0s: required with delta_max")
        for x0 in np.atleast_2d(np.asarray(x0s, float)):
            c = x0.reshape(n_x, 1)
            cons.append(sym(X - nu * (c @ c.T)) >> 0)
        cons.append(sym(cp.bmat([[cp.reshape(float(delta_max) ** 2 * nu, (1, 1), order="C"), Y], [Y.T, X]])) >> 0)
        method = method + "+steer"
    prob = cp.Problem(cp.Minimize(float(alpha) * g_sq + float(beta) * cp.trace(W)), cons)
    status = solve_or_raise(prob, f"{method} synthesis")
    K, cond = gain_from(X.value, Y.value, f"{method} synthesis")
    gi, g2 = float(np.sqrt(max(float(solved(g_sq)), 0.0))), float(np.sqrt(max(float(np.trace(solved(W))), 0.0)))
    hn, h2n, poles = [], [], []
    for p in plants:
        Acl, Bw, Ci, C2 = closed_loop(p, K)
        hn.append(hinf_norm(Acl, Bw, Ci))
        h2n.append(h2_norm(Acl, Bw, C2))
        poles.append(np.linalg.eigvals(Acl))
    steer = None
    if delta_max is not None:
        # max of |K x| over the smallest invariant ellipsoid E_mu that holds every start:
        # mu = max x0' X^-1 x0, max |K x| = sqrt(mu K X K') (<= delta_max; nu is not unique where the
        # limit does not bind, so the solver's 1 / nu is not used)
        Xv = 0.5 * (solved(X) + solved(X).T)
        mu = max(float(x0 @ np.linalg.solve(Xv, x0)) for x0 in np.atleast_2d(np.asarray(x0s, float)))
        steer = float(np.sqrt(mu * np.squeeze(K @ Xv @ K.T)))
    warns = bound_warnings(gi, g2, max(hn), max(h2n), cond)
    return RobustDesign(method, K, gi, g2, float(max(hn)), float(max(h2n)), np.asarray(poles), steer, status, warns)


def integral_mixed(v=1.0, L=0.2, *, alpha=10.0, beta=1.0, **kw) -> RobustDesign:
    """Mixed design with integral action on ``d`` at one operating point (zero slip)."""
    return robust_mixed([integral_plant(v, L)], alpha=alpha, beta=beta, method="integral", **kw)


def polytopic_mixed(
    v_range=(0.7, 1.3), beta_r_max_deg=10.0, L=0.2, *, integral=False, alpha=10.0, beta=1.0, **kw
) -> RobustDesign:
    """Mixed design with one Lyapunov matrix over the speed x slip polytope (module docstring)."""
    plants = polytope_vertices(v_range, math.radians(beta_r_max_deg), L, integral)
    return robust_mixed(plants, alpha=alpha, beta=beta, method="polytopic" + ("-integral" if integral else ""), **kw)
