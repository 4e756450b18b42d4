"""The state-feedback loop's equilibrium on the steering-limit boundary ``|beta_r + beta_f| =
delta_max`` (docs/reproductions/path-following.md §7): it exists, with the steering at its limit, but
it is not locally stable, so :func:`pfjax.analysis.equilibrium` does not call it Hurwitz; checked by
simulating the line test from the equilibrium perturbed four ways (:func:`pfjax.simulate`)."""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np
import pytest

import pfjax
from pfjax import controllers as C
from pfjax.analysis import equilibrium, stability_map
from pfjax.models import SlipParams

GRID_DEG = np.array([-25.0, -15.0, -5.0, 0.0, 5.0, 15.0, 25.0])  # |beta_r + beta_f| = 30 deg on 6 points
DELTA_MAX_DEG = 30.0  # SlipParams()'s
#: perturbations of the equilibrium: d by +-1 cm, theta_e by +-0.5 deg (all four sign pairs)
PERTURBATIONS = [(sd * 0.01, st * 0.5) for sd in (1, -1) for st in (1, -1)]


@pytest.fixture(scope="module")
def grid():
    assert SlipParams().delta_max == pytest.approx(math.radians(DELTA_MAX_DEG))
    eq, _ = stability_map(jnp.asarray(C.PAPER_K), jnp.radians(GRID_DEG), jnp.radians(GRID_DEG), SlipParams())
    BR, BF = np.meshgrid(GRID_DEG, GRID_DEG, indexing="ij")
    return BR, BF, eq


def test_the_boundary_exists_but_is_not_hurwitz(grid):
    BR, BF, eq = grid
    exists, hurwitz = np.asarray(eq.exists), np.asarray(eq.hurwitz)
    on = np.abs(BR + BF) == DELTA_MAX_DEG
    inside, beyond = np.abs(BR + BF) < DELTA_MAX_DEG, np.abs(BR + BF) > DELTA_MAX_DEG
    assert on.sum() == 6 and exists[on].all() and not hurwitz[on].any()
    # off the boundary: Hurwitz where the eigenvalues say so (everywhere inside, for K < 0), none beyond
    stable = (np.asarray(eq.eig).real < 0).all(-1)
    assert (hurwitz[inside] == stable[inside]).all() and hurwitz[inside].all()
    assert not exists[beyond].any() and not hurwitz[beyond].any()
    # one point as a single call, each side of the boundary by 1e-6 rad
    p = SlipParams()
    for beta_f, expected in ((math.radians(25.0) - 1e-6, True), (math.radians(25.0), False)):
        e = equilibrium(jnp.asarray(C.PAPER_K), math.radians(5.0), beta_f, p)
        assert bool(e.exists) and bool(e.hurwitz) is expected


def _perturbed_runs(BR, BF, eq):
    """The line test from each equilibrium perturbed by each of :data:`PERTURBATIONS`, 60 s: the
    final ``d`` and ``theta_e``, shaped (points, perturbations)."""
    d_star = np.asarray(eq.d).ravel()
    th_star = np.asarray(eq.theta_e).ravel()
    n, m = d_star.size, len(PERTURBATIONS)
    dd = np.array([p[0] for p in PERTURBATIONS])
    dth = np.array([p[1] for p in PERTURBATIONS])
    sc = pfjax.scenarios(
        "line",
        n * m,
        beta_r_deg=np.repeat(BR.ravel(), m),
        beta_f_deg=np.repeat(BF.ravel(), m),
        lateral_offset=(d_star[:, None] + dd).ravel(),
        heading_error_deg=(np.degrees(th_star)[:, None] + dth).ravel(),
    )
    sim = pfjax.simulate(
        sc, "state_feedback", gains=dict(zip(("k_d", "k_theta"), C.PAPER_K)), config={"horizon": 60.0, "dt": 0.01}
    )
    assert (sim.table.status == "ok").all()
    return np.asarray(sim.result.final.d).reshape(n, m), np.asarray(sim.result.final.theta_e).reshape(n, m)


def test_simulation_returns_to_a_hurwitz_equilibrium_and_drifts_from_the_boundary(grid):
    BR, BF, eq = grid
    d_fin, th_fin = _perturbed_runs(BR, BF, eq)
    d_star, th_star = np.asarray(eq.d).ravel()[:, None], np.asarray(eq.theta_e).ravel()[:, None]
    back = ((np.abs(d_fin - d_star) < 1e-3) & (np.abs(th_fin - th_star) < math.radians(0.1))).all(-1)
    drifts = (np.abs(d_fin - d_star) > 0.1).any(-1)  # some small perturbation ends 10 cm away or more
    hurwitz = np.asarray(eq.hurwitz).ravel()
    on = (np.abs(BR + BF) == DELTA_MAX_DEG).ravel()
    assert back[hurwitz].all()
    assert drifts[on].all() and not back[on].any()
