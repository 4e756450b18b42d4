"""Continuous-time generalised plant for the path-following LMI designs (source eq. 7, 12).

Everything here is plain NumPy (float64); nothing is traced or jitted.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


class Plant(NamedTuple):
    """Generalised plant for static state feedback ``u = K x``.

    ::

        x'    = A x + Bw w + Bu u
        z_inf = Cinf x + Dinf_u u        (H-infinity channel, no direct w -> z_inf term)
        z2    = C2 x + D2u u             (H2 channel, no direct w -> z2 term)

    Shapes use ``n_x`` states, ``n_w`` disturbances, ``n_u`` controls, ``n_zinf`` and ``n_z2``
    performance outputs. For :func:`slip_design_plant` ``n_x = 2``, ``n_w = 3``, ``n_u = 1``,
    ``n_zinf = 2``, ``n_z2 = 3``.
    """

    A: np.ndarray  # (n_x, n_x) 1/s; x = [d (m), theta_e (rad)] for the slip plant
    Bw: np.ndarray  # (n_x, n_w); w = [beta_r (rad), beta_f (rad), kappa (1/m)]
    Bu: np.ndarray  # (n_x, n_u); u = [delta (rad)]
    Cinf: np.ndarray  # (n_zinf, n_x)
    Dinf_u: np.ndarray  # (n_zinf, n_u)
    C2: np.ndarray  # (n_z2, n_x)
    D2u: np.ndarray  # (n_z2, n_u)


def slip_design_plant(v: float = 1.0, L: float = 0.2) -> Plant:
    """Linear design model of the path-following errors with slip (source eq. 7, 12).

    Linearisation of the Frenet error model at ``d = theta_e = 0`` with zero slip and curvature::

        d'       = v theta_e + v beta_r
        theta_e' = (v / L) (delta - beta_r - beta_f) - v kappa

    so, with ``x = [d, theta_e]``, ``u = delta``, ``w = [beta_r, beta_f, kappa]``::

        A   = [[0, v], [0, 0]]                  Bu = [[0], [v/L]]
        Bw  = [[v, 0, 0], [-v/L, -v/L, -v]]
        z_inf = x      (Cinf = I2, Dinf_u = 0)
        z2    = [x; u] (C2 = [I2; 0], D2u = [0; 0; 1])

    Args:
        v: longitudinal speed, m/s.
        L: wheelbase, m.

    Returns:
        The :class:`Plant` (float64 arrays).
    """
    v = float(v)
    L = float(L)
    if not (np.isfinite(v) and np.isfinite(L)) or L <= 0.0:
        raise ValueError(f"slip_design_plant needs finite v and L > 0, got v={v}, L={L}")
    A = np.array([[0.0, v], [0.0, 0.0]])
    Bu = np.array([[0.0], [v / L]])
    Bw = np.array([[v, 0.0, 0.0], [-v / L, -v / L, -v]])
    Cinf = np.eye(2)
    Dinf_u = np.zeros((2, 1))
    C2 = np.vstack([np.eye(2), np.zeros((1, 2))])
    D2u = np.array([[0.0], [0.0], [1.0]])
    return Plant(A=A, Bw=Bw, Bu=Bu, Cinf=Cinf, Dinf_u=Dinf_u, C2=C2, D2u=D2u)
