"""Pacejka's magic-formula tyre (the subset CommonRoad's single-track drift model uses), pure JAX.

CommonRoad's ``vehiclemodels.utils.tire_model`` (``commonroad-vehicle-models`` 3.0.2, after
H. B. Pacejka, *Tire and Vehicle Dynamics*, 3rd ed., 2012, ch. 4.3.2: the MF-Tyre 5.2 steady-state
equations with turn slip neglected and every scaling factor ``lambda = 1``), at zero camber
(``gamma = 0``, as the drift model calls it, so the camber terms ``p_dx3``, ``p_dy3``, ``p_hy*``,
``p_vy*``, ``r_vy3`` drop out). Forces in N, slip ``kappa`` dimensionless, slip angle ``alpha`` in rad,
vertical load ``F_z`` in N. The magic formula is ``MF(B, C, E, x) = C atan(B x - E (B x - atan(B x)))``.

Pure longitudinal slip (CommonRoad's sign convention ``kappa -> -kappa``; its vertical shift ``S_vx``
sits inside the sine, as in the reference)::

    F0_x = D_x sin(MF(B_x, p_cx1, p_ex1, p_hx1 - kappa) + S_vx),
    D_x = mu_x F_z,  B_x = p_kx1 F_z / (p_cx1 D_x),  S_vx = p_vx1 F_z

Pure lateral slip::

    F0_y = D_y sin(MF(B_y, p_cy1, p_ey1, alpha)),   D_y = mu_y F_z,  B_y = p_ky1 F_z / (p_cy1 D_y)

Combined slip (cosine weighting functions)::

    F_x = F0_x cos(MF(B_xa, r_cx1, r_ex1, alpha + r_hx1)) / cos(MF(B_xa, r_cx1, r_ex1, r_hx1)),
          B_xa = r_bx1 cos(atan(r_bx2 kappa))
    F_y = F0_y cos(MF(B_yk, r_cy1, r_ey1, kappa + r_hy1)) / cos(MF(B_yk, r_cy1, r_ey1, r_hy1)) + S_vyk,
          B_yk = r_by1 cos(atan(r_by2 (alpha - r_by3))),
          S_vyk = mu_y F_z r_vy1 cos(atan(r_vy4 alpha)) sin(r_vy5 atan(r_vy6 kappa))

The friction coefficients ``mu_x``, ``mu_y`` are arguments: CommonRoad's are ``p_dx1`` and ``p_dy1``;
the drift model scales both by ``mu / p_dy1`` so that ``mu`` is its friction coefficient.
"""

from __future__ import annotations

from typing import Any, NamedTuple

from jax import Array

from pfjax.numerics import elementary as E


class PacejkaParams(NamedTuple):
    """Magic-formula coefficients (CommonRoad's names; all dimensionless). A pytree."""

    p_cx1: Array | float  # longitudinal shape factor C_x
    p_dx1: Array | float  # longitudinal friction coefficient mu_x at the nominal load
    p_ex1: Array | float  # longitudinal curvature factor E_x
    p_kx1: Array | float  # longitudinal slip stiffness per unit load K_x / F_z
    p_hx1: Array | float  # longitudinal horizontal shift
    p_vx1: Array | float  # longitudinal vertical shift per unit load
    r_bx1: Array | float  # combined-slip longitudinal weighting: stiffness factor
    r_bx2: Array | float  # its variation with kappa
    r_cx1: Array | float  # its shape factor
    r_ex1: Array | float  # its curvature factor
    r_hx1: Array | float  # its horizontal shift
    p_cy1: Array | float  # lateral shape factor C_y
    p_dy1: Array | float  # lateral friction coefficient mu_y at the nominal load
    p_ey1: Array | float  # lateral curvature factor E_y
    p_ky1: Array | float  # cornering stiffness per unit load K_y / F_z, 1/rad
    r_by1: Array | float  # combined-slip lateral weighting: stiffness factor
    r_by2: Array | float  # its variation with alpha
    r_by3: Array | float  # its alpha shift, rad
    r_cy1: Array | float  # its shape factor
    r_ey1: Array | float  # its curvature factor
    r_hy1: Array | float  # its horizontal shift
    r_vy1: Array | float  # kappa-induced lateral force per unit load
    r_vy4: Array | float  # its variation with alpha
    r_vy5: Array | float  # its variation with kappa
    r_vy6: Array | float  # its variation with atan(kappa)


def pacejka_from_commonroad(tire: Any) -> PacejkaParams:
    """:class:`PacejkaParams` from CommonRoad's ``TireParameters`` (``p.tire``), as Python floats."""
    return PacejkaParams(*(float(getattr(tire, name)) for name in PacejkaParams._fields))


#: The tyre of CommonRoad's vehicles 1-3 (all three share it), as ``commonroad-vehicle-models`` 3.0.2
#: stores it (the tests check it against the package).
COMMONROAD_TYRE = PacejkaParams(
    p_cx1=1.6411,
    p_dx1=1.1739,
    p_ex1=0.46403,
    p_kx1=22.303,
    p_hx1=0.0012297,
    p_vx1=-8.8098e-06,
    r_bx1=13.276,
    r_bx2=-13.778,
    r_cx1=1.2568,
    r_ex1=0.65225,
    r_hx1=0.0050722,
    p_cy1=1.3507,
    p_dy1=1.0489,
    p_ey1=-0.0074722,
    p_ky1=-21.92,
    r_by1=7.1433,
    r_by2=9.1916,
    r_by3=-0.027856,
    r_cy1=1.0719,
    r_ey1=-0.27572,
    r_hy1=5.7448e-06,
    r_vy1=-0.027825,
    r_vy4=12.12,
    r_vy5=1.9,
    r_vy6=-10.704,
)


def _cos_atan(z) -> Array:
    """``cos(atan z) = 1 / sqrt(1 + z^2)``."""
    return E.rsqrt(1 + z * z)


def magic(b, c, e, x) -> Array:
    """``C atan(B x - E (B x - atan(B x)))``, rad (the argument of the magic formula's sine or cosine)."""
    bx = b * x
    return c * E.atan(bx - e * (bx - E.atan(bx)))


def longitudinal(kappa, f_z, mu_x, t: PacejkaParams) -> Array:
    """Pure-slip longitudinal force ``F0_x`` (N) at longitudinal slip ``kappa`` and load ``f_z`` (N)."""
    d = mu_x * f_z
    b = t.p_kx1 * f_z / (t.p_cx1 * d)
    return d * E.sin(magic(b, t.p_cx1, t.p_ex1, t.p_hx1 - kappa) + f_z * t.p_vx1)


def lateral(alpha, f_z, mu_y, t: PacejkaParams) -> Array:
    """Pure-slip lateral force ``F0_y`` (N) at slip angle ``alpha`` (rad) and load ``f_z`` (N)."""
    d = mu_y * f_z
    b = t.p_ky1 * f_z / (t.p_cy1 * d)
    return d * E.sin(magic(b, t.p_cy1, t.p_ey1, alpha))


def longitudinal_combined(kappa, alpha, f0_x, t: PacejkaParams) -> Array:
    """Combined-slip longitudinal force ``F_x`` (N) from the pure-slip ``f0_x`` (N)."""
    b = t.r_bx1 * _cos_atan(t.r_bx2 * kappa)
    return f0_x * E.cos(magic(b, t.r_cx1, t.r_ex1, alpha + t.r_hx1)) / E.cos(magic(b, t.r_cx1, t.r_ex1, t.r_hx1))


def lateral_combined(kappa, alpha, f0_y, f_z, mu_y, t: PacejkaParams) -> Array:
    """Combined-slip lateral force ``F_y`` (N) from the pure-slip ``f0_y`` (N)."""
    b = t.r_by1 * _cos_atan(t.r_by2 * (alpha - t.r_by3))
    weight = E.cos(magic(b, t.r_cy1, t.r_ey1, kappa + t.r_hy1)) / E.cos(magic(b, t.r_cy1, t.r_ey1, t.r_hy1))
    s_v = mu_y * f_z * t.r_vy1 * _cos_atan(t.r_vy4 * alpha) * E.sin(t.r_vy5 * E.atan(t.r_vy6 * kappa))
    return f0_y * weight + s_v
