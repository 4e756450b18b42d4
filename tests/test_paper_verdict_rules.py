"""The paper reproduction's verdict rules that need a counter-example: a long PI run that has not
settled gives no verdict on its settled error, the Table 3 verdict holds only for the reading the
study runs, and the GA readings' gain change is weighed against the seeds' spread."""

from __future__ import annotations

from test_paper_audit import _inputs

from pfjax.reproduce import path_following
from pfjax.reproduce.paper_analysis import gain_change


def _rows(long_pi=None, filters=None):
    cfg, rows, stab, pi_df, sine, lp, ga = _inputs()
    pi_df.attrs["filters"] = {**pi_df.attrs["filters"], **(filters or {})}
    return path_following.verdicts(cfg, rows, stab, pi_df, sine, {**lp, **(long_pi or {})}, ga)


def _settled_row(rows):
    (row,) = [v for v in rows if "once settled" in v.criterion]
    return row


def test_a_long_pi_run_still_drifting_at_its_end_gives_no_verdict():
    """At a 40 s horizon the PI's |d| is within 5 % of its final value only from 38.6 s: the final
    5 s window does not lie after it, so the run has not settled and its "settled" error is none."""
    row = _settled_row(_rows({"horizon_s": 40.0, "settle_time_s": 38.62, "steady_abs_d_mm": 8.29}))
    assert row.verdict == "no verdict" and "not settled by 35 s" in row.pfjax and "38.62 s" in row.pfjax
    assert "from 35 s at the latest" in row.criterion
    row = _settled_row(_rows({"horizon_s": 40.0, "settle_time_s": 30.0, "steady_abs_d_mm": 8.29}))
    assert row.verdict == "reproduced" and "settled from t = 30.00 s" in row.pfjax
    row = _settled_row(_rows({"status": "diverged"}))
    assert row.verdict == "no verdict" and "status diverged" in row.pfjax


def test_table3_holds_only_for_the_reading_the_study_runs():
    (row,) = [v for v in _rows() if v.claim.startswith("Table 3") and "exactly one" in v.criterion]
    assert row.verdict == "holds"
    other = _rows(filters={"consistent_readings": ["q"], "adopted_reading": "r"})
    (row,) = [v for v in other if v.claim.startswith("Table 3") and "exactly one" in v.criterion]
    assert row.verdict == "does not hold" and "the PI rows run another: r" in row.pfjax


def test_ga_gain_change_is_weighed_against_the_seeds_spread():
    """Three seeds per reading cannot show an effect at 5 % (the smallest exact Mann-Whitney p is
    2 / C(6, 3) = 0.1), and the text says so; six seeds each, separated, show one (p = 2 / C(12, 6) =
    0.0022); six each, interleaved, give no evidence."""
    seeds = lambda *k: [{"ki_theta": x, "kp_d": 1.0} for x in k]
    a = {"best_gains": {"ki_theta": 0.0095, "kp_d": 1.0}, "seed_gains": seeds(0.0095, 0.31, 0.0088)}
    b = {"best_gains": {"ki_theta": 0.0054, "kp_d": 1.0}, "seed_gains": seeds(0.0054, 0.0011, 0.0053)}
    text = gain_change(a, b)
    assert text.startswith("largest: ki_theta 0.0095 vs 0.0054 (43 %)"), text
    assert "0.0088 to 0.31" in text and "p = 0.1;" in text
    assert "3 and 3 seeds cannot show an effect at the 5 % level: the smallest p they allow is 0.1" in text
    a["seed_gains"] = seeds(0.0095, 0.31, 0.0088, 0.02, 0.03, 0.04)
    b["seed_gains"] = seeds(0.0054, 0.0011, 0.0053, 0.001, 0.002, 0.003)
    text = gain_change(a, b)
    assert "p = 0.0022" in text and "the reading moves it" in text and "no evidence" not in text
    b["seed_gains"] = seeds(0.0054, 0.5, 0.0053, 0.03, 0.002, 0.035)
    assert "no evidence that the reading moves it" in gain_change(a, b)


def test_a_config_built_in_python_is_checked_as_the_command_checks_a_file():
    """paper_study.run checks its config first, as load does a file: nothing runs, nothing is written
    (no output is given: the check comes before any use of it)."""
    import pytest

    from pfjax.config import ConfigError
    from pfjax.reproduce.paper_config import PaperStudy
    from pfjax.reproduce.paper_study import run

    with pytest.raises(ConfigError, match=r"^synthesis: no mixed H2/Hinf design at model.v = 1e\+06 m/s"):
        run(PaperStudy(model={"v": 1e6}), None, None)
    with pytest.raises(ConfigError, match=r"^stability\.eig_n"):
        run(PaperStudy(stability={"eig_n": 10**7}), None, None)


def test_the_study_runs_in_float64_whatever_the_caller_enabled(monkeypatch):
    """From Python without float64 the eigenvalue scan would round the slower eigenvalue's maximum to
    0 (a different verdict): run() enables float64 for the study, as its script does."""
    import jax

    from pfjax.reproduce import paper_study
    from pfjax.reproduce.paper_config import PaperStudy

    seen = []
    monkeypatch.setattr(paper_study, "_run", lambda config, output, pbar: seen.append(jax.config.jax_enable_x64))
    with jax.enable_x64(False):
        paper_study.run(PaperStudy(), None, None)
        assert not jax.config.jax_enable_x64
    assert seen == [True]
