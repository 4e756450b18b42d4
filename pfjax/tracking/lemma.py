"""Lemma 8.1 checked directly (geometry) and the controller's zero dynamics on a straight leader.

**Geometry.** ``z~ = 0`` means ``w = R(theta)(z_d - P_ref) = l (cos p gamma, sin p gamma)``. With the
connection angle ``phi`` in ``(-pi/2, pi/2]`` (:func:`pfjax.tracking.geometry.connection`) the line
through ``P_ref`` and ``z_d`` has angle ``phi = p gamma`` when ``|p gamma| < pi/2`` and
``phi = p gamma -+ pi`` when ``pi/2 < |p gamma| < 3 pi/2`` (the same line, the other half). Hence:

* ``z~ = 0  =>  phi = p gamma`` holds for every state iff ``|p| gamma_max < pi/2``, i.e. the lemma's
  ``|p| < pi/(2 gamma_max)``; outside it, states with ``|p gamma| > pi/2`` and ``z~ = 0`` have
  ``|phi - p gamma| = pi`` (counterexamples).
* ``phi = p gamma  =>  z~ = 0`` needs the distance too: ``z~ = 0`` iff ``phi = p gamma`` **and**
  ``f d = l``. A leader on the focus direction at another distance has ``phi = p gamma`` and
  ``|z~| = |f d - l|`` — so the lemma's "if" direction holds only when the connection length is
  regulated to ``l`` as well (:func:`sample_geometry` returns both kinds of sample).

**Zero dynamics** (pfjax's controller, not the source's). With ``z = z_d`` moving at constant
velocity ``V (cos h, sin h)`` and the follower driving at ``v ~ sigma V`` (``sigma = +1`` forward
motion, ``-1`` reversing), the internal state ``(dtheta, dpsi)`` (heading and focus-direction
deviations, ``gamma = (dpsi - dtheta)/p``) obeys, linearised::

    [dtheta' ; dpsi'] = sigma V [[-1/(a p), 1/(a p)], [-(p - c_f)/(l p), -c_f/(l p)]]

with ``trace = -sigma V (l + c_f a) / (a l p)`` and ``det = V^2 / (a l p)``: stable iff ``l p > 0``
and ``sigma (l + c_f a) / (l p) > 0`` (backward tracking while reversing: ``l < 0`` and ``p < 0``).
"""

from __future__ import annotations

import math
from functools import partial

import jax
import jax.numpy as jnp
import numpy as np
import pandas as pd

from pfjax.tracking.geometry import connection, focus_point, tracking_error
from pfjax.tracking.model import Follower, FollowerParams, as_arrays


def zero_dynamics_matrix(V: float, sigma: float, params: FollowerParams) -> np.ndarray:
    """Linearised internal dynamics on a straight leader at speed ``V`` (m/s), 2x2, 1/s.

    Derived from ``z' = v (e_theta + c_f tan(gamma) n_theta) + l psi' n_psi = V e_h`` projected on
    ``n_psi`` (``psi = theta + p gamma``), with ``theta' = v tan(gamma) / a`` and ``v ~ sigma V``::

        l dpsi'  = -sigma V dpsi + sigma V (p - c_f) gamma = sigma V (-c_f dpsi - (p - c_f) dtheta) / p
        dtheta'  = sigma V gamma / a                        = sigma V (dpsi - dtheta) / (a p)
    """
    a, l, p = float(params.a), float(params.l), float(params.p)
    cf = 0.5 * (1.0 + float(params.f))
    k = (p - cf) / (l * p)  # coefficient of dtheta in dpsi' (over sigma V)
    return sigma * V * np.array([[-1.0 / (a * p), 1.0 / (a * p)], [-k, -cf / (l * p)]])


def zero_dynamics_stable(V: float, sigma: float, params: FollowerParams) -> bool:
    """All eigenvalues of :func:`zero_dynamics_matrix` in the open left half-plane."""
    return bool(np.max(np.linalg.eigvals(zero_dynamics_matrix(V, sigma, params)).real) < 0)


@partial(jax.jit, static_argnums=1)
def _geometry_samples(key, n: int, params: FollowerParams):
    """``gamma`` and, per kind, ``(phi, |z~|)`` of ``n`` random states (one compilation per ``n``)."""
    k1, k2, k3, k4, k5 = jax.random.split(key, 5)
    gm, l = params.gamma_max, params.l
    s = Follower(
        x=jax.random.uniform(k1, (n,), minval=-10, maxval=10),
        y=jax.random.uniform(k2, (n,), minval=-10, maxval=10),
        theta=jax.random.uniform(k3, (n,), minval=-math.pi, maxval=math.pi),
        gamma=jax.random.uniform(k4, (n,), minval=-gm, maxval=gm),
    )
    r = jax.random.uniform(k5, (n,), minval=0.2, maxval=1.0)

    def one(si, ri):
        zd_on = focus_point(si, params)
        zd_far = focus_point(si, params._replace(l=(1.0 + ri) * l))
        out = {}
        for name, zd in (("on_focus", zd_on), ("wrong_distance", zd_far)):
            c = connection(si, zd, params)
            e = tracking_error(si, zd, params)
            out[name] = (c.phi, jnp.hypot(e[0], e[1]))
        return out

    return s.gamma, jax.vmap(one)(s, r)


def sample_geometry(
    key, n: int, gamma_max: float, p: float, l: float = 1.0, f: int = 1, a: float = 1.0
) -> pd.DataFrame:
    """Random states with ``z~ = 0`` and with ``phi = p gamma`` at a wrong distance (see module doc).

    Returns a frame of ``n`` rows per ``kind``: ``"on_focus"`` (``z_d`` = the focus point) and
    ``"wrong_distance"`` (``z_d`` on the focus direction at ``(1 + r) l`` from ``P_ref``,
    ``r ~ U[0.2, 1]``), with ``gamma``, ``p_gamma``, ``phi``, ``phi_minus_pgamma``, ``z_err`` (m).
    """
    params = FollowerParams(a=a, f=float(f), l=l, p=p, gamma_max=gamma_max)
    g, res = _geometry_samples(key, n, as_arrays(params))
    g = np.asarray(g)
    rows = []
    for kind, (phi, zerr) in res.items():
        rows.append(
            pd.DataFrame(
                {
                    "kind": kind,
                    "gamma": g,
                    "p_gamma": p * g,
                    "phi": np.asarray(phi),
                    "phi_minus_pgamma": np.asarray(phi) - p * g,
                    "z_err": np.asarray(zerr),
                }
            )
        )
    return pd.concat(rows, ignore_index=True)


def outcomes(df: pd.DataFrame) -> dict[str, pd.Series]:
    """Boolean masks of the four outcomes ``(z~ -> 0, phi - p gamma -> 0)`` of finished runs, and ``failed``.

    ``df`` needs boolean ``converged``, ``phi_converged`` and a ``status`` column (``"ok"`` for a run
    that finished). Keys: ``both``, ``z_only``, ``phi_only``, ``neither``, ``failed``.
    """
    ok, z, phi = df["status"] == "ok", df["converged"].astype(bool), df["phi_converged"].astype(bool)
    return {
        "both": ok & z & phi,
        "z_only": ok & z & ~phi,
        "phi_only": ok & ~z & phi,
        "neither": ok & ~z & ~phi,
        "failed": ~ok,
    }


def read_at(df: pd.DataFrame, tol_z: float, tol_phi: float) -> pd.DataFrame:
    """``df`` with ``converged`` and ``phi_converged`` read again at the tolerances ``tol_z`` (m) and
    ``tol_phi`` (rad), as the simulator reads them (:class:`pfjax.tracking.simulate.TrackMetrics`):
    status ok and the largest value over the final window (``window_max_z``, ``window_max_phi_err``)
    at most the tolerance; the same runs judged tighter or looser than they were simulated."""
    ok = df["status"] == "ok"
    return df.assign(
        converged=ok & (df["window_max_z"] <= tol_z), phi_converged=ok & (df["window_max_phi_err"] <= tol_phi)
    )


def four_way(df: pd.DataFrame, by: list[str]) -> pd.DataFrame:
    """Counts of the :func:`outcomes` per group, with ``n`` and ``equivalence_holds`` (``z_only == phi_only == 0``)."""
    masks = pd.DataFrame(outcomes(df)).astype(int)
    g = pd.concat([df[by], masks], axis=1).groupby(by, dropna=False)
    out = g.size().rename("n").to_frame().join(g.sum()).reset_index()
    out["equivalence_holds"] = (out["z_only"] == 0) & (out["phi_only"] == 0)
    return out
