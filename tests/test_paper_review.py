"""The path-following verdicts' criteria and bases (made-up runs, no simulation): a run counts as
settled only if it stays in the band over the final steady window; a comparison the Table 3 filter
alone decides is labelled chosen by filters; rows resting on the assumed horizon or steering limit
say so; docs/reproductions/path-following.md says which verdicts the assumed values move."""

from __future__ import annotations

import math
from pathlib import Path

import pandas as pd
import pytest
from paper_inputs import RUN

from pfjax.reproduce import path_following
from pfjax.reproduce.paper_config import PaperStudy
from pfjax.reproduce.verdict import BASES

ROOT = Path(__file__).resolve().parents[1]
FILTERED, ASSUMED = BASES[2], BASES[4]
PI_FILTERS = dict(
    thresholds={"sat": 0.05, "delta_deg": 0.5, "ss_factor": 3.0},
    passing={"converges on all three paths": 2},
    consistent=1,
    consistent_readings=["r"],
    adopted_reading="r",
    sensitivity_unique=4,
    sensitivity_cases=6,
)
STAB = dict(
    grid_deg=[-60.0, 60.0, 31],
    equilibrium_exists_fraction=0.43,
    hurwitz_where_exists_fraction=1.0,
    sim_agrees_with_analysis_fraction=1.0,
    paper_case=dict(d_star=0.00246),
    eigen_maxima=dict(
        grid_max_deg=89.9,
        n=11,
        hurwitz_fraction=1.0,
        max_re_slow=-1.3182,
        max_re_slow_at=[0.0, -89.9],
        source_max_re_slow=-1.3185,
        max_re_fast=-5.193,
        max_re_fast_at=[-89.9, -6.7],
        source_max_re_fast=-5.193,
    ),
)


def _verdicts(runs: dict) -> list:
    """``path_following.verdicts`` with the default config (20 s horizon, 5 s window, 5 cm band);
    ``runs[(path, controller)]`` overrides that run's metrics."""
    cfg = PaperStudy().model_dump(mode="json")
    rows = [
        {"path": p, "controller": c, **RUN, **runs.get((p, c), {})}
        for p in ("line", "parabola", "sine")
        for c in ("mixed", "paper-k", "pi")
    ]
    pi_df = pd.DataFrame({"reading": ["r"]})
    pi_df.attrs["filters"] = PI_FILTERS
    sine = {"peak_x": [1.0], "median_peak_to_kappa_max_m": 0.49, "median_peak_to_dkappa_max_m": 0.08}
    long_pi = dict(horizon_s=300.0, steady_abs_d_mm=1.22, settle_time_s=150.6, status="ok")
    reading = dict(costs=[0.29], median_cost=0.29)
    ga = dict(scenario="paper-line", cost="IAE", crossover=reading, none=reading, gain_change="none")
    return path_following.verdicts(cfg, rows, STAB, pi_df, sine, long_pi, ga)


def _rows(vs, claim: str) -> dict:
    return {(v.path, v.subject): v for v in vs if v.claim.startswith(claim)}


def test_a_run_settling_inside_the_final_window_has_not_settled():
    """The sine test's mixed |d| peaks periodically just above the band: its last exit from the band
    within a 20 s run comes at 18.36 s, 1.64 s before the end, and the next peak leaves it again.
    Settled means staying in the band over at least the final 5 s window."""
    late = {("sine", "mixed"): dict(settling_time=18.36), ("sine", "pi"): dict(settling_time=0.32)}
    vs = _verdicts(late)
    conv = _rows(vs, "Both controllers bring")
    sine_mixed = conv[("sine", "mixed H2/H∞ (pfjax's K)")]
    assert sine_mixed.verdict == "does not hold"
    assert sine_mixed.pfjax == "18.36 s, later than 15 s"
    assert "over at least the final 5 s (settling time ≤ 15 s: the 20 s horizon, assumed)" in sine_mixed.criterion
    assert conv[("line", "mixed H2/H∞ (pfjax's K)")].verdict == "holds"
    assert conv[("sine", "PI (Table 3)")].verdict == "holds"
    fast = _rows(vs, "The mixed design converges faster")[("sine", "mixed vs PI")]
    assert (fast.pfjax, fast.verdict) == ("never vs 0.32 s", "does not hold")
    # a run settling exactly at horizon - window has settled
    ok = _rows(_verdicts({("sine", "mixed"): dict(settling_time=15.0)}), "Both controllers bring")
    assert ok[("sine", "mixed H2/H∞ (pfjax's K)")].verdict == "holds"


def test_faster_gives_no_verdict_when_neither_settled():
    late = {("line", c): dict(settling_time=19.0) for c in ("mixed", "pi")}
    fast = _rows(_verdicts(late), "The mixed design converges faster")[("line", "mixed vs PI")]
    assert (fast.pfjax, fast.verdict) == ("never vs never", "no verdict")
    nan = _rows(_verdicts({("line", "mixed"): dict(settling_time=math.nan)}), "The mixed design converges faster")
    assert nan[("line", "mixed vs PI")].verdict == "no verdict"


def test_accuracy_on_the_line_decided_by_the_filter_is_labelled_so():
    """The filter 'line steady |d| within a factor 3 of 8 mm' admits only PI readings with at least
    8/3 = 2.67 mm, so against a mixed error of 2.57 mm the line row holds by construction."""
    runs = {(p, "mixed"): dict(steady_abs_d=0.00257) for p in ("line", "parabola", "sine")}
    vs = _verdicts({**runs, ("line", "pi"): dict(steady_abs_d=0.0176)})
    acc = _rows(vs, "The mixed design converges more accurately")
    line = acc[("line", "mixed vs PI")]
    assert (line.verdict, line.basis, line.also) == ("holds", FILTERED, ASSUMED)
    assert "of the 20 s horizon, assumed" in line.criterion
    assert (acc[("sine", "mixed vs PI")].basis, acc[("sine", "mixed vs PI")].also) == (ASSUMED, "")
    # a mixed error inside the filter's range [2.67, 24] mm: the filter does not decide the row
    inside = _rows(_verdicts({("line", "mixed"): dict(steady_abs_d=0.004)}), "The mixed design converges more")
    assert (inside[("line", "mixed vs PI")].basis, inside[("line", "mixed vs PI")].also) == (ASSUMED, "")


def test_rows_resting_on_the_assumed_horizon_or_limit_say_so():
    vs = _verdicts({})
    pi20 = next(v for v in vs if "about 8 mm" in v.claim and "horizon (assumed" in v.criterion)
    assert (pi20.basis, pi20.also) == (FILTERED, ASSUMED)
    eq = next(v for v in vs if v.claim.startswith("Theorem 4") and "true equilibrium" in v.criterion)
    assert eq.basis == ASSUMED and "δ_max (assumed)" in eq.criterion


def test_docs_say_which_verdicts_the_assumed_values_move():
    doc = " ".join((ROOT / "docs" / "reproductions" / "path-following.md").read_text().split())
    section = doc[doc.index("### Which verdicts rest on the assumed values") :]
    for key in (
        "model.delta_max_deg",
        "sim.horizon",
        "model.direction",
        "sim.settle_band",
        "sim.steady_window",
        "ga.cost",
    ):
        assert f"`{key}" in section, key
    assert "python studies/paper_reproduction.py --set sim.horizon=40" in section


class _Bar:
    def update(self, n: int = 1) -> None:
        pass


def test_the_table3_convergence_filter_uses_the_same_settling_rule():
    """The filter "converges on all three paths" counts a reading as converged only where the
    verdicts would (settled by horizon - window), not wherever a settling time is finite."""
    from pfjax.reproduce import paper_runs
    from pfjax.reproduce.paper_config import load

    cfg = load(None, quick=True).model_dump(mode="json")
    cfg["sim"]["steady_window"] = 5.1  # quick horizon 6 s: settled by 0.9 s
    by = cfg["sim"]["horizon"] - cfg["sim"]["steady_window"]
    rows = [{"path": t, "controller": "mixed", "iae": 1.0} for t in ("line", "parabola", "sine")]
    df, _ = paper_runs.part_pi_readings(cfg, rows, _Bar())
    times = df[[f"{t}_settling_time" for t in ("line", "parabola", "sine")]]
    expected = (times <= by + 1e-9).all(axis=1)  # NaN (never settled) compares False
    assert (df.c_converges_all == expected).all()
    assert (times.notna().all(axis=1) & ~expected).any()  # a finite but late settling time fails


def test_the_assumed_tuning_cost_is_a_key_the_ga_readings_use(monkeypatch):
    """Eq. 15's cost is assumed: ``ga.cost`` selects it (default IAE), a bad one is named, and the
    Table 2 readings tune with it and name it."""
    from pfjax.config import ConfigError
    from pfjax.reproduce import paper_analysis
    from pfjax.reproduce.paper_config import load
    from pfjax.tuning import problem as tuning_problem

    assert load(None).ga.cost == "iae"
    cfg = load(None, ["ga.cost=ise"], quick=True).model_dump(mode="json")
    with pytest.raises(ConfigError, match="ga.cost"):
        load(None, ["ga.cost=l2"])
    seen = []

    class Stop(Exception):
        pass

    def make_problem(controller, scenario, cost):
        seen.append(cost.metric)
        raise Stop

    monkeypatch.setattr(tuning_problem, "make_problem", make_problem)
    with pytest.raises(Stop):
        paper_analysis.part_ga_readings(cfg)
    assert seen == ["ise"]
    assert "ISE" in paper_analysis.GA_COSTS["ise"] and "m²·s" in paper_analysis.GA_COSTS["ise"]
