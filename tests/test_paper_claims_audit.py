"""The paper reproduction's prose and verdicts follow its numbers: the report's conclusions on the
design, the controller's sampling, the PI's reading, its drift and the equilibrium are computed
from the summary (made-up summaries here, no simulation); the sine claim gives "no verdict" when
no median exists; the PI's steering row names both of its bases; docs/reproductions/path-following.md
states the boundary rule of §7."""

from __future__ import annotations

import copy
import math
import sys
from pathlib import Path

import pandas as pd
import pytest
from paper_inputs import run_rows

from pfjax.report.document import to_markdown
from pfjax.reproduce import path_following
from pfjax.reproduce.paper_config import PaperStudy
from pfjax.reproduce.paper_report import PI_COLUMNS, report
from pfjax.reproduce.verdict import Verdict, verdict_cells

ROOT = Path(__file__).resolve().parents[1]
FILTERED, CONVENTION = "chosen by filters from the source", "used to choose the convention"

#: pfjax's design and the source's K checked by pfjax, α = 10, β = 1 (the default: a flat optimum)
FLAT = dict(
    ours=dict(K=[-2.7826, -2.0819], gamma_inf=1.1008, gamma_2=4.0670, hinf_norm=1.0820, h2_norm=3.5954),
    checked=dict(gamma_inf_certified=1.1023, gamma_2_certified=4.0632, hinf_norm=1.0842, h2_norm=3.5940),
    objectives=(28.659409, 28.660237),
    rel=dict(K_d=0.0162, K_theta=0.0023, gamma_inf=0.0008, gamma_2=0.0007),
)
#: the same with α = 1, β = 10: the source's K is 9.8 % worse, pfjax's ‖T∞‖∞ exceeds the published 1.1
STEEP = dict(
    ours=dict(K=[-1.0784, -1.3168], gamma_inf=2.6694, gamma_2=3.4576, hinf_norm=1.2128, h2_norm=3.3647),
    checked=dict(gamma_inf_certified=2.2791, gamma_2_certified=3.6593, hinf_norm=1.0842, h2_norm=3.5940),
    objectives=(126.677, 139.096),
    rel=dict(K_d=0.6061, K_theta=0.3661, gamma_inf=1.4267, gamma_2=0.1505),
)


def _summary(design=FLAT, control_every=0, settle_time_s=151.0, alpha=10.0, beta=1.0) -> dict:
    """A complete summary for :func:`report`, every number made up or copied from a study run."""
    cfg = PaperStudy().model_dump(mode="json")
    cfg["sim"]["control_every"] = control_every
    cfg["synthesis"].update(alpha=alpha, beta=beta)
    ours = dict(design["ours"], objective=design["objectives"][0])
    checked = dict(design["checked"], objective=design["objectives"][1])
    em = dict(grid_max_deg=89.9, n=11, max_re_slow=-1.3182, max_re_slow_at=[0.0, -89.9], source_max_re_slow=-1.3185)
    em.update(max_re_fast=-5.193, max_re_fast_at=[-89.9, -6.7], source_max_re_fast=-5.193, hurwitz_fraction=1.0)
    reading = dict(crossover_fraction=0.8, costs=[0.29], median_cost=0.29, best_gains={"kp_d": 1.0}, n_rollouts=8)
    return dict(
        pfjax_version="0",
        config_sha256="0" * 64,
        machine="test",
        wall_s=1.0,
        config=cfg,
        verdicts=[],
        runs=[],
        synthesis=dict(
            ours=ours,
            source_published=dict(K=[-2.7381, -2.0772], gamma_inf=1.1, gamma_2=4.07),
            source_K_checked_by_pfjax=checked,
            rel_diff=design["rel"],
        ),
        pi_filters=dict(
            thresholds={"sat": 0.05, "delta_deg": 0.5, "ss_factor": 3.0},
            passing={"converges on all three paths": 3},
            consistent=1,
            consistent_readings=["r"],
            adopted_reading="r",
            sensitivity_unique=4,
            sensitivity_cases=6,
        ),
        stability=dict(
            grid_deg=[-60.0, 60.0, 31],
            source_hurwitz_fraction=1.0,
            equilibrium_exists_fraction=0.43,
            hurwitz_where_exists_fraction=1.0,
            sim_converged_fraction=0.43,
            sim_agrees_with_analysis_fraction=1.0,
            paper_case=dict(
                d_star=0.00246, theta_e_star=-math.radians(5), delta_star=math.radians(10), eig=[[-1.55, 0], [-8.9, 0]]
            ),
            eigen_maxima=em,
        ),
        pi_long_horizon=dict(
            horizon_s=300.0, steady_abs_d_mm=1.22, final_d_mm=1.22, settle_time_s=settle_time_s, status="ok"
        ),
        ga_crossover_readings=dict(
            scenario="paper-line", cost="IAE", crossover=reading, none=reading, gain_change="none"
        ),
    )


def _readings(adopted_consistent=True, n_consistent=1) -> pd.DataFrame:
    """24 readings, the first adopted; ``n_consistent`` of them pass every filter."""
    df = pd.DataFrame({c: [0.0] * 24 for c in PI_COLUMNS})
    df["reading"] = [f"r{i}" for i in range(24)]
    start = 0 if adopted_consistent else 1
    df["consistent"] = [start <= i < start + n_consistent for i in range(24)]
    df["is_default"] = [i == 0 for i in range(24)]
    return df


def _md(s: dict, pi_df: pd.DataFrame | None = None) -> str:
    return " ".join(to_markdown(report(s, {"pi_readings": _readings() if pi_df is None else pi_df})).split())


# ------------------------------------------------------------ the design's prose


def test_flat_optimum_and_bounds_stated_only_when_the_numbers_show_them():
    """α = 1, β = 10: the source's K certifies an objective 12.4 (9.8 %) above pfjax's optimum and
    pfjax's true ‖T∞‖∞ 1.2128 exceeds the published γ∞ 1.1; the report says so, not "flat"."""
    flat = _md(_summary())
    assert "within the 0.1 % tolerance for a flat optimum" in flat and "the objective is flat along K_d" in flat
    assert "The true norms of both gains are below both sets of bounds" in flat and "all 8 hold" in flat
    assert "a flat LMI optimum (objective within 0.1 %)" in flat

    steep = _md(_summary(STEEP, alpha=1.0, beta=10.0))
    assert "flat along" not in steep and "flat LMI optimum" not in steep and "Both true" not in steep
    assert "1.24e+01 (9.8 %) above pfjax's optimum, beyond the 0.1 % tolerance for a flat optimum" in steep
    assert "not equally good for this objective (α = 1, β = 10)" in steep
    assert "7 hold; pfjax's K's true ‖T∞‖∞ 1.2128 is not below the source's γ∞ 1.1." in steep
    assert "not a flat optimum (the source's K certifies an objective 9.8 % above pfjax's optimum)" in steep


@pytest.mark.parametrize(
    "every, text",
    [
        (0, "the controller is evaluated continuously inside every RK4 step, as in the source's Simulink model"),
        (1, "the controller is sampled every step (5 ms) and held in between, not evaluated continuously"),
        (4, "the controller is sampled every 4 steps (20 ms) and held in between, not evaluated continuously"),
    ],
)
def test_controller_evaluation_follows_control_every(every, text):
    md = _md(_summary(control_every=every))
    assert text in md
    assert ("controller continuous" in md) == (every == 0)


@pytest.mark.parametrize(
    "consistent, n, text, absent",
    [
        (True, 1, "the adopted reading is the only one of 24 that passes the four filters above", "NOT consistent"),
        (True, 3, "the adopted reading is one of 3 of 24 that pass the four filters above", "NOT consistent"),
        (False, 0, "the adopted reading does not pass the four filters above in this run (0 of 24 do)", "only one"),
    ],
)
def test_pi_bullet_follows_whether_the_adopted_reading_is_consistent(consistent, n, text, absent):
    md = _md(_summary(), _readings(consistent, n))
    assert text in md and "evidence-based" not in md
    assert absent not in md.split("**PI gains**")[1]
    assert ("is NOT consistent" in md) == (not consistent)


@pytest.mark.parametrize(
    "settle, text",
    [
        (151.0, "At the 20 s horizon the PI's line error is still drifting."),
        (12.0, "At the 20 s horizon the PI's line error has settled."),
        (math.inf, "At the 20 s horizon the PI's line error is still drifting. Run for 300 s, |d| does not settle"),
        (None, "At the 20 s horizon the PI's line error is still drifting. Run for 300 s, |d| does not settle"),
    ],
)
def test_pi_drift_follows_the_settling_time(settle, text):
    assert text in _md(_summary(settle_time_s=settle))


def test_equilibrium_sentences_follow_d_star():
    """d* ≠ 0: not the source's [0, −β_r]; d* = 0 (zero slip): it is; δ* beyond δ_max: none; δ* on
    δ_max: an equilibrium, not locally stable."""
    s = _summary()
    md = _md(s)
    assert "— not the source's [0, −β_r]" in md and "**The equilibrium error is not zero**" in md
    zero = copy.deepcopy(s)
    zero["stability"]["paper_case"].update(d_star=0.0, theta_e_star=0.0, delta_star=0.0)
    md = _md(zero)
    assert "— the source's [0, −β_r]" in md and "**The equilibrium error d* is zero**" in md
    assert "not the source's [0" not in md
    beyond = copy.deepcopy(s)
    beyond["stability"]["paper_case"].update(delta_star=math.radians(40.0))
    md = _md(beyond)
    assert "there is no equilibrium: it needs |δ*| = 40.000° > δ_max = 30°" in md
    assert "**The source's K has no equilibrium**" in md
    limit = copy.deepcopy(s)
    limit["stability"]["paper_case"].update(delta_star=math.radians(30.0))
    md = _md(limit)
    assert (
        "δ* = 30.000°" in md
        and "It lies on the steering limit, where the steering saturates and the point is not locally stable." in md
    )


def test_stability_band_includes_its_boundary():
    md = _md(_summary())
    assert "|β_r + β_f| < δ_max" not in md
    assert "the band |β_r + β_f| ≤ δ_max between the dashed lines, its boundary included" in md
    assert "a point on the boundary has the steering at its limit and is not locally stable" in md


@pytest.mark.parametrize(
    "consistent, names, text",
    [
        (
            1,
            ["r"],
            "All four: 1 (r). With each threshold halved or doubled (the others kept), that reading stays the "
            "only one in 4 of 6 settings.",
        ),
        (0, [], "All four: none. No single reading passes all four, so there is no choice whose sensitivity to test."),
        (2, ["a", "b"], "All four: 2 (a, b). No single reading passes all four, so there is no choice whose"),
    ],
)
def test_filter_paragraph_follows_the_number_of_consistent_readings(consistent, names, text):
    """--quick: no reading passes all four filters; the report does not speak of "that reading"."""
    s = _summary()
    s["pi_filters"].update(consistent=consistent, consistent_readings=names)
    md = _md(s)
    assert text in md
    assert ("that reading stays" in md) == (consistent == 1) and "()" not in md


def test_limit_equilibrium_names_its_eigenvalues_as_the_unsaturated_loops():
    s = _summary()
    s["stability"]["paper_case"].update(delta_star=math.radians(30.0))
    md = _md(s)
    assert "with the unsaturated loop's eigenvalues -1.550, -8.900 1/s (which do not apply there)" in md
    assert "with eigenvalues -1.550, -8.900 1/s" in _md(_summary())


def test_why_readings_fail_only_with_rear_slip():
    s = _summary()
    assert "Why readings fail: with rear slip" in _md(s)
    s["config"]["model"]["beta_r_deg"] = 0.0
    md = _md(s)
    assert "Why readings fail" not in md and "(The 8 best of 24; all in `pi_readings.csv`.) The reading pfjax" in md


def test_tracker_note_only_with_trackers():
    s = _summary()
    assert "Stanley" in _md(s)
    s["config"]["trackers"] = False
    assert "Stanley" not in _md(s)


# ------------------------------------------------------------ verdicts


def _verdicts(sine=None, filters=None, **run) -> list[Verdict]:
    """``path_following.verdicts`` on made-up runs (the sine analysis and run metrics overridable)."""
    cfg = PaperStudy().model_dump(mode="json")
    rows = run_rows(**run)
    s = _summary()
    pi_df = pd.DataFrame({"reading": ["r"]})
    pi_df.attrs["filters"] = {**s["pi_filters"], **(filters or {})}
    long_pi = s["pi_long_horizon"]
    sine = sine or {"peak_x": [1.0], "median_peak_to_kappa_max_m": 0.49, "median_peak_to_dkappa_max_m": 0.08}
    return path_following.verdicts(cfg, rows, s["stability"], pi_df, sine, long_pi, s["ga_crossover_readings"])


@pytest.mark.parametrize("missing", [math.nan, None])
def test_sine_without_peaks_gives_no_verdict_with_the_reason(missing):
    """--quick: no |d| peak after 5 s, both medians NaN (None once read back from JSON)."""
    sine = {"peak_x": [], "median_peak_to_kappa_max_m": missing, "median_peak_to_dkappa_max_m": missing}
    rows = [v for v in _verdicts(sine) if v.claim.startswith("Sine")]
    assert len(rows) == 2
    assert all(v.verdict == "no verdict" and v.pfjax == "no |d| peak after 5 s (no median)" for v in rows)
    assert not any("nan" in v.pfjax for v in rows)
    # peaks, but no |dκ/ds| maximum to measure to: the first row decides, the second does not
    sine = {"peak_x": [1.0], "median_peak_to_kappa_max_m": 0.49, "median_peak_to_dkappa_max_m": math.nan}
    first, second = (v for v in _verdicts(sine) if v.claim.startswith("Sine"))
    assert first.verdict == "holds" and first.pfjax == "median distance 0.49 m"
    assert second.verdict == "no verdict" and second.pfjax == "no |dκ/ds| maximum in x after 5 s (no median)"


def test_nan_metric_gives_no_verdict():
    """A run with no value (NaN) for a compared metric decides nothing: 'no verdict', not 'does not hold'."""
    rows = [v for v in _verdicts(steady_abs_d=math.nan) if "more accurately" in v.claim]
    assert len(rows) == 3
    assert all(v.verdict == "no verdict" and v.pfjax == "no value for mixed (NaN)" for v in rows)


def test_a_failed_run_gives_no_verdict_on_its_metrics():
    """A run that diverged stops there: its steady errors, steering, effort and final angles describe
    it up to its failure, so every claim compared on them says "no verdict" with the status. The
    claims on convergence decide on the status itself: a run that never settled did not converge,
    nor converge faster ("does not hold")."""
    rows = _verdicts(status="diverged")
    on_mixed = [v for v in rows if v.subject.startswith("mixed H2/H∞ (pfjax") or v.subject == "mixed vs PI"]
    on_status = ("bring the robot onto", "converges faster", "steering limit")
    compared = [v for v in on_mixed if not any(c in v.claim for c in on_status)]
    assert compared and all(v.verdict == "no verdict" for v in compared), [
        (v.claim, v.verdict) for v in compared if v.verdict != "no verdict"
    ]
    assert all("status diverged" in v.pfjax for v in compared if not v.claim.startswith("Sine")), compared
    converge = [v for v in on_mixed if "bring the robot onto" in v.claim]
    assert converge and all(v.verdict == "does not hold" for v in converge)
    # the same runs ended ok: verdicts again
    ok = [v for v in _verdicts() if v.subject == "mixed vs PI" and not any(c in v.claim for c in on_status)]
    equal = [v for v in ok if v.pfjax.endswith(", equal")]  # effort values both clipped alike: no order
    assert all(v.verdict == "no verdict" for v in equal)
    assert all(v.verdict != "no verdict" for v in ok if v not in equal)


def test_a_failed_pi_run_gives_no_verdict_on_the_comparisons_and_its_own_rows(monkeypatch):
    """Only the PI's runs diverge: the comparisons with the mixed design, the PI's line error and
    its line steering and yaw rows say "no verdict" with the PI's status; the mixed design's own
    rows still decide."""
    import paper_inputs

    real = paper_inputs.run_rows

    def pi_failed(**mixed):
        return [{**r, "status": "diverged"} if r["controller"] == "pi" else r for r in real(**mixed)]

    monkeypatch.setattr(sys.modules[__name__], "run_rows", pi_failed)
    rows = _verdicts()
    compared = [v for v in rows if v.subject == "mixed vs PI" and "converges faster" not in v.claim]
    assert compared and all(v.verdict == "no verdict" and "PI (Table 3): status diverged" in v.pfjax for v in compared)
    pi_line = [v for v in rows if v.subject == "PI (Table 3)" and v.claim.startswith("Line")]
    assert pi_line and all(v.verdict == "no verdict" for v in pi_line if "once settled" not in v.criterion), [
        (v.claim, v.verdict) for v in pi_line
    ]
    mixed_line = [v for v in rows if v.subject.startswith("mixed H2/H∞ (pfjax") and v.claim.startswith("Line")]
    assert mixed_line and all(v.verdict in ("holds", "does not hold") for v in mixed_line)


def test_table3_sensitivity_needs_a_chosen_reading():
    """--quick: no reading passes every filter, so there is no choice whose sensitivity to test."""
    rows = _verdicts(filters=dict(consistent=0, consistent_readings=[], sensitivity_unique=0))
    first, second = (v for v in rows if v.claim.startswith("Table 3"))
    assert first.verdict == "does not hold" and first.pfjax == "0 reading(s): none"
    assert second.verdict == "no verdict" and second.pfjax == "no single reading chosen (0 pass every filter)"
    chosen = [v for v in _verdicts() if v.claim.startswith("Table 3")][1]
    assert chosen.verdict == "does not hold" and chosen.pfjax == "unique in 4 of 6 threshold settings"


def test_pi_steering_row_names_both_bases():
    """The PI's final line steering is the filter "line steering within 0.5° of 10°" that chose its
    reading, on the same run (the stronger basis), and the angle that fixed the convention."""
    rows = {v.subject: v for v in _verdicts() if "steering settles" in v.claim}
    assert (rows["PI (Table 3)"].basis, rows["PI (Table 3)"].also) == (FILTERED, CONVENTION)
    assert (rows["mixed H2/H∞ (pfjax's K)"].basis, rows["mixed H2/H∞ (pfjax's K)"].also) == (CONVENTION, "")
    _, cells = verdict_cells([rows["PI (Table 3)"]._asdict()])
    assert cells[0][-1] == f"{FILTERED}; also {CONVENTION}"
    with pytest.raises(ValueError, match="^also:"):
        rows["PI (Table 3)"]._replace(also=FILTERED).check()


def test_docs_list_the_pi_steering_row_among_the_filtered_and_the_boundary_rule():
    doc = " ".join((ROOT / "docs" / "reproductions" / "path-following.md").read_text().split())
    assert "(its convergence on the three paths, its line error at 20 s, its final steering on the line)" in doc
    assert "locally stable wherever it has an equilibrium" not in doc
    assert r"exists only while $|\delta^*| \le \delta_{\max}$" in doc
    assert r"On the limit, $|\delta^*| = \delta_{\max}$" in doc and "not locally stable" in doc
