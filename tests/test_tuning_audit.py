"""Tuning settings a run would not read or would name wrongly: smoothing with one round, the restart
chains' memory, a step longer than the horizon, a cost that is never finite, and the study's rounds
when only its steps are given."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import pfjax
from pfjax.cli import main
from pfjax.errors import InputError
from pfjax.tuning.gradient import gradient_tune
from pfjax.tuning.multistart import MultistartOptions


def test_smoothing_with_one_round_is_refused_not_ignored(capsys):
    """Smoothing acts on the first of several rounds; with one round it would change nothing."""
    with pytest.raises(InputError, match=r"^smoothing: smooths the first of several rounds") as e:
        MultistartOptions(rounds=1, smoothing=0.5).check()
    assert e.value.key == "smoothing"
    assert MultistartOptions(rounds=2, smoothing=0.5).check().smoothing == 0.5
    assert MultistartOptions(rounds=1, smoothing=0.0).check().rounds == 1
    argv = ["tune", "--method", "gradient", "--controller", "state-feedback", "--rounds", "1", "--smoothing", "0.5"]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("pfjax tune: error: --smoothing: ") and err.count("\n") == 1


def test_the_restart_chains_memory_is_named_by_the_restarts(capsys):
    with pytest.raises(InputError, match=r"^multistart\.n_restarts: 1000001 restart chains") as e:
        pfjax.tune("pi", "paper-line", "gradient", key=0, multistart=MultistartOptions(n_restarts=1_000_000))
    assert e.value.key == "multistart.n_restarts"
    assert main(["tune", "--method", "gradient", "--controller", "pi", "--restarts", "1000000"]) == 2
    assert capsys.readouterr().err.startswith("pfjax tune: error: --restarts: 1000001 restart chains")


def test_a_step_longer_than_the_horizon_names_the_step(capsys):
    with pytest.raises(InputError, match=r"^config\.dt: must be <= horizon \(20 s\), got 100$") as e:
        pfjax.tune("pi", "paper-line", "ga", config={"dt": 100.0})
    assert e.value.key == "config.dt"
    assert main(["tune", "--method", "ga", "--controller", "pi", "--dt", "100"]) == 2
    err = capsys.readouterr().err
    assert err == "pfjax tune: error: --dt: must be <= --horizon (20 s), got 100\n"


@pytest.mark.parametrize("n_starts", [1, 4])
def test_a_cost_never_finite_gives_one_point(n_starts):
    r = gradient_tune(
        lambda t: jnp.nan * t[0], np.zeros(2), np.ones(2), key=jax.random.PRNGKey(0), steps=3, n_starts=n_starts
    )
    assert np.shape(r.theta) == (2,) and not np.isfinite(r.cost)


def test_the_studys_rounds_follow_its_steps_when_not_given():
    from pfjax.tuning.study_config import TuneMultistart

    assert TuneMultistart().rounds == 3 and TuneMultistart(steps=2).rounds == 2 and TuneMultistart(steps=1).rounds == 1
    assert TuneMultistart(steps=2, rounds=1).rounds == 1
    with pytest.raises(ValueError, match=r"rounds: must be <= steps \(2\), got 3"):
        TuneMultistart(steps=2, rounds=3)


def test_check_names_a_field_mixed_with_gains_by_name(capsys):
    argv = ["tune", "--controller", "state-feedback", "--check", '{"K": [-2.7381, -2.0772], "feedforward": 0.0}']
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("pfjax tune: error: --check: mixes the field K with gains by name (feedforward)")
    assert err.count("\n") == 1


def test_a_scenario_tomls_contents_enter_the_config_hash(tmp_path, capsys):
    """The same --scenario path with other contents is another config: its SHA-256 is recorded."""
    import json
    from pathlib import Path

    text = (Path(__file__).resolve().parents[1] / "studies" / "tuning_heldout.toml").read_text()
    toml = tmp_path / "h.toml"
    out = []
    for seed in (404, 405):
        toml.write_text(text.replace("seed = 404", f"seed = {seed}"))
        argv = ["tune", "--check", "10,0,2,0", "--controller", "pi", "--scenario", str(toml), "--n-runs", "1"]
        assert main([*argv, "--json"]) == 0
        out.append(json.loads(capsys.readouterr().out))
    assert "seed = 404" in text
    assert out[0]["arguments"]["scenario"] == out[1]["arguments"]["scenario"] == str(toml)
    assert out[0]["arguments"]["scenario_sha256"] != out[1]["arguments"]["scenario_sha256"]
    assert out[0]["config_sha256"] != out[1]["config_sha256"] and out[0]["cost"] != out[1]["cost"]


def test_on_bound_names_the_tuned_gains_the_box_stopped():
    """``on_bound``: the tuned gains (scalar names, the box's order) at a bound of the tuning box;
    none inside it, every one at a corner, one where only it is clipped."""
    import numpy as np

    from pfjax.controllers import entry, gain_names
    from pfjax.tuning.problem import make_problem, on_bound

    problem = make_problem("pi", "paper-line")
    names = gain_names(entry("pi"), problem.tunable.fields)
    assert len(names) == problem.lower.size >= 2
    mid = (problem.lower + problem.upper) / 2
    assert on_bound("pi", problem, mid) == []
    assert on_bound("pi", problem, problem.lower) == names == on_bound("pi", problem, problem.upper)
    one = mid.copy()
    one[1] = problem.upper[1]
    assert on_bound("pi", problem, one) == [names[1]]
    assert on_bound("pi", problem, np.clip(one + 1e9, problem.lower, problem.upper)) == names
