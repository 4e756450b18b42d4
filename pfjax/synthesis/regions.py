"""LMI regions for closed-loop pole placement (Chilali & Gahinet 1996).

A region ``D = {s : L_D + M_D s + M_D' conj(s) < 0}`` contains every eigenvalue of ``A_cl`` iff
some ``X > 0`` satisfies ``L_D (x) X + M_D (x) (A_cl X) + M_D' (x) (A_cl X)' < 0`` (``(x)`` the
Kronecker product). With state feedback ``A_cl X = A X + Bu Y``, which is linear in ``(X, Y)``,
and the same ``X`` as the performance LMIs (``msfsyn``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cvxpy as cp
import numpy as np

__all__ = ["PoleRegion", "region_constraints", "region_contains"]


@dataclass(frozen=True)
class PoleRegion:
    """Intersection of LMI regions for the closed-loop poles; ``None`` fields are not imposed.

    Attributes:
        max_real: half-plane ``Re(s) < max_real``, 1/s (e.g. -0.5 for a decay rate of 0.5).
        disk_center: centre ``c`` (real, 1/s) of the disk ``|s - c| < r``.
        disk_radius: radius ``r`` (1/s) of that disk; set both disk fields or neither.
        sector_angle: half-angle ``theta`` (rad, in (0, pi/2]) of the conic sector with apex 0
            around the negative real axis, ``|Im s| < -Re(s) tan(theta)``; damping ratio
            ``>= cos(theta)``.
    """

    max_real: float | None = None
    disk_center: float | None = None
    disk_radius: float | None = None
    sector_angle: float | None = None

    def __post_init__(self):
        """Checks the fields (:class:`~pfjax.errors.InputError` naming the field)."""
        from pfjax import errors

        if (self.disk_center is None) != (self.disk_radius is None):
            raise errors.InputError("disk_radius: give disk_center and disk_radius together, or neither")
        for name in ("max_real", "disk_center"):
            if getattr(self, name) is not None:
                errors.number(name, getattr(self, name), unit=" 1/s")
        if self.disk_radius is not None:
            errors.number("disk_radius", self.disk_radius, positive=True, unit=" 1/s")
        if self.sector_angle is not None:
            errors.number("sector_angle", self.sector_angle, positive=True, high=math.pi / 2, unit=" rad")


def region_contains(region: PoleRegion, poles, tol: float = 0.0) -> bool:
    """True when every pole lies in the (open) region, up to the slack ``tol`` (1/s)."""
    for s in np.atleast_1d(np.asarray(poles, dtype=complex)):
        if region.max_real is not None and not s.real < region.max_real + tol:
            return False
        if region.disk_radius is not None and not abs(s - region.disk_center) < region.disk_radius + tol:
            return False
        if region.sector_angle is not None:
            th = region.sector_angle
            # sin(th) Re(s) < 0 and |cos(th) Im(s)| < -sin(th) Re(s)
            if not abs(s.imag) * math.cos(th) < -s.real * math.sin(th) + tol:
                return False
    return True


def region_constraints(region: PoleRegion, AclX, X, eps: float) -> list:
    """cvxpy constraints placing the eigenvalues of ``A_cl`` in ``region``.

    With ``M = A_cl X = A X + Bu Y``:

    - half-plane ``Re s < h``:   ``M + M' - 2 h X < 0``
    - disk ``|s - c| < r``:      ``[[-r X, M - c X], [(M - c X)', -r X]] < 0``
    - sector of half-angle ``t``: ``[[sin t (M + M'), cos t (M - M')],
      [cos t (M' - M), sin t (M + M')]] < 0``

    Each strict inequality is imposed with margin ``eps`` (``<= -eps I``).
    """
    n = X.shape[0]
    M = AclX
    out = []
    if region.max_real is not None:
        F = M + M.T - 2.0 * float(region.max_real) * X
        out.append(0.5 * (F + F.T) << -eps * np.eye(n))
    if region.disk_radius is not None:
        r = float(region.disk_radius)
        c = float(region.disk_center or 0.0)
        F = cp.bmat([[-r * X, M - c * X], [(M - c * X).T, -r * X]])
        out.append(0.5 * (F + F.T) << -eps * np.eye(2 * n))
    if region.sector_angle is not None:
        s, co = math.sin(region.sector_angle), math.cos(region.sector_angle)
        F = cp.bmat([[s * (M + M.T), co * (M - M.T)], [co * (M.T - M), s * (M + M.T)]])
        out.append(0.5 * (F + F.T) << -eps * np.eye(2 * n))
    return out
