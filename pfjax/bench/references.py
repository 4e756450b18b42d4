"""Reference implementations of the benchmark problem (:mod:`pfjax.bench.problem`), written
independently of pfjax's JAX code: NumPy vectorised over the batch, Numba (``prange`` over runs,
a scalar loop per run) and SciPy ``solve_ivp`` (one run at a time).

Each returns the per-run IAE (m s). Per step ``k`` (``t_k = k dt``), exactly as the simulator:

1. closest point: 3 safeguarded Newton steps on ``g(u) = (p(u) - q) . p'(u)`` for ``p(u) = (u, sin u)``
   from the previous ``u`` (Gauss-Newton where ``g' < 0.01 |p'|^2``, step at most
   ``max(|p - q|, 0.25) / |p'|``, ``u`` clipped to ``[-10, 60]``); the start polishes ``u0`` by 8;
2. ``d = (q - p) . n``, ``theta_e = wrap(theta - atan2(cos u, 1))``;
3. ``delta = clip(K [d, theta_e], +-delta_max)``, held over the step;
4. IAE += ``w_k dt |d|`` (``w = 1/2`` at ``k = 0`` and ``k = N``);
5. RK4 step of ``x' = v (cos th - tan b_r sin th)``, ``y' = v (sin th + tan b_r cos th)``,
   ``th' = (v/L)(tan(delta - b_f) - tan b_r)`` (SciPy: ``solve_ivp`` DOP853 over the step instead).

The float32 versions compute in float32 throughout (inputs, constants and arithmetic).

Numba is optional (the ``bench`` extra): without it :func:`numba_available` is False and the
benchmark skips the Numba reference with the note :data:`NUMBA_MISSING`.
"""

from __future__ import annotations

import numpy as np

from pfjax.bench import problem as P

#: The note of a benchmark run without Numba (its output and report carry it).
NUMBA_MISSING = "numba not installed: pip install 'pfjax[bench]'"


def numba_available() -> bool:
    """Whether the Numba reference can run: ``numba`` imports (it is the ``bench`` extra)."""
    try:
        import numba  # noqa: F401
    except ImportError:
        return False
    return True


def _consts(dtype):
    f = np.dtype(dtype).type
    return dict(
        dt=f(P.DT),
        half=f(0.5),
        sixth=f(P.DT / 6.0),
        v=f(P.V),
        vl=f(P.V / P.L),
        k0=f(P.K[0]),
        k1=f(P.K[1]),
        dmax=f(P.DELTA_MAX),
        umin=f(P.U_MIN),
        umax=f(P.U_MAX),
        pi=f(np.pi),
        twopi=f(2 * np.pi),
        one=f(1.0),
        zero=f(0.0),
        c001=f(0.01),
        c025=f(0.25),
        four=f(4.0),
    )


# ------------------------------------------------------------------------------------------- NumPy


def _np_newton(u, x, y, c):
    su, cu = np.sin(u), np.cos(u)
    ex, ey = u - x, su - y
    speed2 = c["one"] + cu * cu
    g = ex + ey * cu
    gp = speed2 - ey * su
    gp = np.where(gp > c["c001"] * speed2, gp, speed2)
    step = -g / gp
    max_step = np.maximum(np.sqrt(ex * ex + ey * ey), c["c025"]) / np.sqrt(speed2)
    return np.clip(u + np.clip(step, -max_step, max_step), c["umin"], c["umax"])


def _np_measure(u, x, y, th, c):
    th_p = np.arctan2(np.cos(u), c["one"])
    d = -(x - u) * np.sin(th_p) + (y - np.sin(u)) * np.cos(th_p)
    te = c["pi"] - np.mod(c["pi"] - (th - th_p), c["twopi"])
    return d, te


def iae_numpy(batch: P.Batch, dtype=np.float64, n_steps: int | None = None) -> np.ndarray:
    """Per-run IAE by NumPy, vectorised over the batch (a Python loop over the steps)."""
    c = _consts(dtype)
    n_steps = P.n_steps() if n_steps is None else n_steps
    x, y, th, u, br, bf = (np.asarray(a, dtype) for a in batch)
    tbr = np.tan(br)
    for _ in range(8):
        u = _np_newton(u, x, y, c)
    iae = np.zeros_like(x)
    dt, v, vl = c["dt"], c["v"], c["vl"]

    def rhs(th, tfront):
        s, co = np.sin(th), np.cos(th)
        return v * (co - tbr * s), v * (s + tbr * co)

    for k in range(n_steps + 1):
        if k:
            for _ in range(P.NEWTON_ITERS):
                u = _np_newton(u, x, y, c)
        d, te = _np_measure(u, x, y, th, c)
        iae += (c["half"] if k in (0, n_steps) else c["one"]) * dt * np.abs(d)
        if k == n_steps:
            break
        delta = np.clip(c["k0"] * d + c["k1"] * te, -c["dmax"], c["dmax"])
        w = vl * (np.tan(delta - bf) - tbr)  # yaw rate, constant over the step (constant slip)
        x1, y1 = rhs(th, None)
        x2, y2 = rhs(th + c["half"] * dt * w, None)
        x4, y4 = rhs(th + dt * w, None)
        x = x + c["sixth"] * (x1 + 4 * x2 + x4)  # stages 2 and 3 coincide: theta' does not depend on the state
        y = y + c["sixth"] * (y1 + 4 * y2 + y4)
        th = th + dt * w
    return iae


# ------------------------------------------------------------------------------------------- Numba


def iae_numba(batch: P.Batch, dtype=np.float64, n_steps: int | None = None) -> np.ndarray:
    """Per-run IAE by :func:`pfjax.bench.numba_ref.kernel` in ``dtype`` (compiled, or loaded from Numba's
    on-disk cache, on first use)."""
    n_steps = P.n_steps() if n_steps is None else n_steps
    c = _consts(dtype)
    try:
        from pfjax.bench import numba_ref
    except ImportError as e:
        raise ImportError(NUMBA_MISSING) from e

    consts = np.array([c[k] for k in numba_ref.CONSTANTS], dtype)
    return numba_ref.kernel(*(np.ascontiguousarray(a, dtype) for a in batch), consts, n_steps)


# ------------------------------------------------------------------------------------------- SciPy


def iae_scipy(batch: P.Batch, index: int, n_steps: int | None = None, rtol=1e-12, atol=1e-12) -> float:
    """IAE of run ``index`` with ``solve_ivp`` (DOP853) integrating each held-steering step (float64)."""
    from scipy.integrate import solve_ivp

    c = _consts(np.float64)
    n_steps = P.n_steps() if n_steps is None else n_steps
    x, y, th, u, br, bf = (float(a[index]) for a in batch)
    tbr = np.tan(br)
    for _ in range(8):
        u = float(_np_newton(u, x, y, c))
    iae = 0.0
    for k in range(n_steps + 1):
        if k:
            for _ in range(P.NEWTON_ITERS):
                u = float(_np_newton(u, x, y, c))
        d, te = (float(a) for a in _np_measure(u, x, y, th, c))
        iae += (0.5 if k in (0, n_steps) else 1.0) * P.DT * abs(d)
        if k == n_steps:
            break
        delta = min(max(P.K[0] * d + P.K[1] * te, -P.DELTA_MAX), P.DELTA_MAX)
        w = P.V / P.L * (np.tan(delta - bf) - tbr)

        def rhs(t, s):
            return [P.V * (np.cos(s[2]) - tbr * np.sin(s[2])), P.V * (np.sin(s[2]) + tbr * np.cos(s[2])), w]

        sol = solve_ivp(rhs, (0.0, P.DT), [x, y, th], method="DOP853", rtol=rtol, atol=atol)
        x, y, th = sol.y[:, -1]
    return iae
