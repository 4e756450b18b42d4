"""Independent NumPy/SciPy references for the tests (shares no code with pfjax).

Paths are written from their closed forms, the closest point is found by a dense grid plus
a bounded scalar minimisation, and the closed loop is integrated by ``solve_ivp`` with the
controller evaluated continuously (as in the source's Simulink model).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import minimize_scalar

# name -> (f, f', f'') of a graph y = f(x); travel direction +x.
GRAPHS = {
    "line": (lambda x: x, lambda x: np.ones_like(x), lambda x: np.zeros_like(x)),
    "parabola": (lambda x: x**2, lambda x: 2 * x, lambda x: 2 * np.ones_like(x)),
    "sine": (np.sin, np.cos, lambda x: -np.sin(x)),
}


def closest_x(name: str, qx: float, qy: float, window: float = 4.0, n: int = 4001) -> float:
    f = GRAPHS[name][0]
    xs = np.linspace(qx - window, qx + window, n)
    i = int(np.argmin((xs - qx) ** 2 + (f(xs) - qy) ** 2))
    h = xs[1] - xs[0]
    res = minimize_scalar(
        lambda x: (x - qx) ** 2 + (f(x) - qy) ** 2,
        bounds=(xs[i] - h, xs[i] + h),
        method="bounded",
        options={"xatol": 1e-14},
    )
    return float(res.x)


def errors(name: str, x: float, y: float, theta: float):
    """(d, theta_e, kappa) of a pose against the graph ``name``."""
    f, f1, f2 = GRAPHS[name]
    xp = closest_x(name, x, y)
    tp = math.atan2(float(f1(xp)), 1.0)
    d = -(x - xp) * math.sin(tp) + (y - float(f(xp))) * math.cos(tp)
    te = (theta - tp + math.pi) % (2 * math.pi) - math.pi
    kappa = float(f2(xp)) / (1 + float(f1(xp)) ** 2) ** 1.5
    return d, te, kappa


def closed_loop(
    name,
    pose0,
    beta_r,
    beta_f,
    *,
    K=None,
    pi=None,
    v=1.0,
    L=0.2,
    delta_max=math.radians(30),
    T=20.0,
    t_eval=None,
    rtol=1e-11,
    atol=1e-12,
):
    """Reference closed loop: ``K`` = (k_d, k_theta) state feedback, or ``pi`` = (kp_d, ki_d, kp_th, ki_th)."""

    def rhs(t, z):
        x, y, th = z[:3]
        d, te, _ = errors(name, x, y, th)
        if K is not None:
            cmd = K[0] * d + K[1] * te
            dz = []
        else:
            kp_d, ki_d, kp_t, ki_t = pi
            cmd = -kp_d * d - kp_t * te + z[3] + z[4]
            dz = [-ki_d * d, -ki_t * te]
        delta = min(max(cmd, -delta_max), delta_max)
        tb = math.tan(beta_r)
        return [
            v * (math.cos(th) - tb * math.sin(th)),
            v * (math.sin(th) + tb * math.cos(th)),
            (v / L) * (math.tan(delta - beta_f) - tb),
            *dz,
        ]

    z0 = list(pose0) + ([] if K is not None else [0.0, 0.0])
    return solve_ivp(rhs, (0.0, T), z0, method="DOP853", t_eval=t_eval, rtol=rtol, atol=atol)
