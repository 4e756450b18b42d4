"""The Numba reference of the benchmark problem: ``prange`` over runs, a scalar loop per run
(the algorithm is described in :mod:`pfjax.bench.references`). It computes in the dtype of its
arguments: one compiled specialisation per dtype, cached on disk (``cache=True``).
"""

from __future__ import annotations

import numba
import numpy as np

#: order of the constants vector ``c`` passed to :func:`kernel`
CONSTANTS = (
    "dt",
    "half",
    "sixth",
    "v",
    "vl",
    "k0",
    "k1",
    "dmax",
    "umin",
    "umax",
    "pi",
    "twopi",
    "one",
    "zero",
    "c001",
    "c025",
    "four",
)


@numba.njit(inline="always", cache=True)
def newton(u, x, y, one, c001, c025, umin, umax):
    su, cu = np.sin(u), np.cos(u)
    ex, ey = u - x, su - y
    speed2 = one + cu * cu
    g = ex + ey * cu
    gp = speed2 - ey * su
    if not gp > c001 * speed2:
        gp = speed2
    step = -g / gp
    m = max(np.sqrt(ex * ex + ey * ey), c025) / np.sqrt(speed2)
    step = min(max(step, -m), m)
    return min(max(u + step, umin), umax)


@numba.njit(parallel=True, cache=True)
def kernel(x0, y0, th0, u0, br, bf, c, n_steps):
    dt, half, sixth, v, vl, k0, k1, dmax = c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7]
    umin, umax, pi, twopi, one, zero, c001, c025, four = c[8], c[9], c[10], c[11], c[12], c[13], c[14], c[15], c[16]
    n = x0.shape[0]
    out = np.empty_like(x0)
    for i in numba.prange(n):
        x, y, th, u = x0[i], y0[i], th0[i], u0[i]
        tbr = np.tan(br[i])
        for _ in range(8):
            u = newton(u, x, y, one, c001, c025, umin, umax)
        iae = zero
        for k in range(n_steps + 1):
            if k > 0:
                for _ in range(3):
                    u = newton(u, x, y, one, c001, c025, umin, umax)
            th_p = np.arctan2(np.cos(u), one)
            d = -(x - u) * np.sin(th_p) + (y - np.sin(u)) * np.cos(th_p)
            w_k = half if (k == 0 or k == n_steps) else one
            iae += w_k * dt * abs(d)
            if k == n_steps:
                break
            te = pi - np.mod(pi - (th - th_p), twopi)
            delta = min(max(k0 * d + k1 * te, -dmax), dmax)
            w = vl * (np.tan(delta - bf[i]) - tbr)
            s1, c1 = np.sin(th), np.cos(th)
            th2 = th + half * dt * w
            s2, c2 = np.sin(th2), np.cos(th2)
            th4 = th + dt * w
            s4, c4 = np.sin(th4), np.cos(th4)
            x = x + sixth * v * ((c1 - tbr * s1) + four * (c2 - tbr * s2) + (c4 - tbr * s4))
            y = y + sixth * v * ((s1 + tbr * c1) + four * (s2 + tbr * c2) + (s4 + tbr * c4))
            th = th4
        out[i] = iae
    return out
