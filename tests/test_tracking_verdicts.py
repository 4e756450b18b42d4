"""The vehicle-tracking reproduction's verdict rows (pfjax.reproduce.tracking): each half of Lemma 8.1
decided by the data, the closed-loop row read at the configured and at tighter tolerances."""

from __future__ import annotations

import pandas as pd

from pfjax.reproduce.tracking import ROUNDING, TIGHTER, verdicts
from pfjax.tracking.study_config import TrackingStudy

GEOMETRY = {
    "n_states_z_err_0": 100,
    "max_abs_phi_minus_pgamma_when_abs_pgamma_lt_pi_2": 1e-15,
    "n_counterexamples_abs_pgamma_gt_pi_2": 7,
    "counterexample_abs_phi_minus_pgamma_range": [3.14159, 3.14159],
    "wrong_distance_min_z_err": 0.2,
}


def _runs(z, phi, status="ok", inside=True):
    """A grid run with its flags as the simulator sets them at the default config's tolerances."""
    sim = TrackingStudy().model_dump(mode="json")["sim"]
    ok = status == "ok"
    return {
        "inside_bound": inside,
        "status": status,
        "window_max_z": z,
        "window_max_phi_err": phi,
        "converged": ok and z <= sim["tol_z"],
        "phi_converged": ok and phi <= sim["tol_phi"],
    }


def _rows(runs, **geometry):
    cfg = TrackingStudy().model_dump(mode="json")
    return verdicts(cfg, {**GEOMETRY, **geometry}, pd.DataFrame(runs)), cfg


def test_each_half_is_decided_by_the_data():
    cfg = TrackingStudy().model_dump(mode="json")
    tz, tp = cfg["sim"]["tol_z"], cfg["sim"]["tol_phi"]
    runs = [_runs(tz / 100, tp / 100), _runs(1.0, 1.0), _runs(tz / 2, tp / 100), _runs(None, None, "singular")]
    runs.append(_runs(tz / 100, 1.0, inside=False))  # outside the bound: not claimed, not counted
    rows, _ = _rows(runs)
    only_if, outside, if_half, loop, tight = rows
    assert [r.verdict for r in rows] == ["holds", "holds", "holds", "holds", "does not hold"]
    assert only_if.basis == outside.basis == "used to choose the convention"
    assert outside.claim.startswith("pfjax's comparison, not a claim of the source")
    assert if_half.claim.startswith("pfjax's comparison, not a claim of the source")  # on states: pfjax's
    # the tolerances' reasons computed from the config, not written for its defaults
    assert "tol_z is 1 % of the Monte Carlo's |l| = 1 m" in loop.criterion and "5 time constants" in loop.criterion
    assert loop.basis == tight.basis == "assumed" and loop.subject == "4 runs inside the bound"
    assert loop.pfjax == "both 2, z̃ only 0, φ − pγ only 0, neither 1 of 3 (1 failed by status, testing neither half)"
    # at tolerances TIGHTER times smaller, the run at tol_z / 2 no longer has z~ -> 0: phi - p gamma only
    assert tight.pfjax.startswith("both 1, z̃ only 0, φ − pγ only 1") and f"{tz / TIGHTER:g} m" in tight.criterion
    rows, _ = _rows(runs, max_abs_phi_minus_pgamma_when_abs_pgamma_lt_pi_2=10 * ROUNDING, wrong_distance_min_z_err=0.0)
    assert rows[0].verdict == "does not hold" and rows[2].verdict == "does not hold"
    rows, _ = _rows(runs, counterexample_abs_phi_minus_pgamma_range=None)
    assert rows[1].verdict == "no verdict"
    rows, _ = _rows([*runs, _runs(tz / 100, 1.0)])  # z~ -> 0 without phi - p gamma -> 0 inside: refuted
    assert rows[3].verdict == "does not hold"
    rows, _ = _rows([_runs(None, None, "singular"), _runs(tz / 100, 1.0, inside=False)])  # none finished inside
    assert rows[3].verdict == rows[4].verdict == "no verdict"


def test_a_single_run_is_checked_against_the_lemma_and_the_check_can_fail():
    """pfjax.tracking.run (pfjax track): inside the bound a run that ends ok is consistent with the
    lemma when z~ -> 0 exactly when phi - p gamma -> 0. A follower held to half the leader's speed
    keeps phi = p gamma but falls behind (f d != l): the "if" half fails on that run."""
    import pfjax.tracking as T

    ok = T.run(horizon=20.0)
    assert ok["inside_lemma_bound"] and ok["converged"] and ok["lemma_consistent"] is True
    slow = T.run(leader="line", v_max=0.5, horizon=20.0)
    assert slow["status"] == "ok" and slow["phi_converged"] and not slow["converged"]
    assert slow["lemma_consistent"] is False
    outside = T.run(p=4.5, horizon=20.0)  # |p| >= pi / (2 gamma_max) at 30 deg: the lemma claims nothing
    assert not outside["inside_lemma_bound"] and outside["lemma_consistent"] is None


def test_the_geometric_test_covers_both_modes_and_every_focus_distance():
    import jax

    from pfjax.tracking import study_config
    from pfjax.tracking.study import geometry_part

    config = study_config.TrackingStudy(lemma={"n_geometry": 10, "p": [1.0, 3.5], "l_abs": [0.5, 1.5]})
    geo, summary = geometry_part(config.model_dump(mode="json"), jax.random.PRNGKey(0))
    assert set(geo["mode"]) == {"forward", "backward"} and set(geo["l"]) == {0.5, 1.5, -0.5, -1.5}
    assert summary["n_states_z_err_0"] == study_config.sizes(config)["geometry_states"]
    assert summary["wrong_distance_min_z_err"] >= 0.2 * 0.5 - 1e-9  # the smallest |l|'s 0.2 focus distances
