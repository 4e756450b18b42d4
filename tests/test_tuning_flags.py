"""``pfjax tune``'s and ``pfjax.tune``'s settings checked as a whole: the final step against the
dynamic model's stable RK4 step, a study's slip drawn for the final horizon, flags the chosen
method does not read refused, errors named by the caller's argument; ``pfjax synth``'s weights
checked whatever the method. Every refusal here comes before anything is compiled or simulated."""

import math
import re
from pathlib import Path

import numpy as np
import pytest

import pfjax
from pfjax.cli import main
from pfjax.errors import InputError
from pfjax.sim import SimConfig
from pfjax.tuning.problem import make_problem

#: A one-path study of the ST model at a stable 10 ms step (its own sim.dt is accepted).
ST_STUDY = """
name = "st_small"
n_runs = 4
seed = 1
[sim]
dt = 0.01
horizon = 3.0
steady_window = 1.0
[success]
from_s = 2.0
[vehicle]
model = "st"
speed = 1.0
[margin]
enabled = false
[[paths]]
kind = "line"
[[controllers]]
name = "k"
type = "state_feedback"
"""
#: A one-path kinematic study with OU slip over a 3 s horizon (sequences sampled every 50 ms).
OU_STUDY = """
name = "ou_small"
n_runs = 4
seed = 1
[sim]
dt = 0.01
horizon = 3.0
steady_window = 1.0
[success]
from_s = 2.0
[vehicle]
speed = 1.0
L = 0.2
[slip]
kind = "ou"
ou_sigma_deg = 3.0
ou_tau_s = 1.0
[[paths]]
kind = "line"
[[controllers]]
name = "k"
type = "state_feedback"
"""


def _refused_cli(argv, flag, capsys) -> str:
    assert main(argv) == 2
    err = capsys.readouterr()
    assert err.out == "" and err.err.startswith(f"pfjax {argv[0]}: error: {flag}: "), err.err
    assert err.err.count("\n") == 1, err.err
    return err.err


def test_tune_refuses_a_step_beyond_the_dynamic_models_stable_step(tmp_path, capsys):
    """--dt (and the API's config) go through the stable-step check of `pfjax simulate` and the
    study config: the robot's ST model at mu 1.05 and 1 m/s needs dt <= 0.0222 s, on a paper set
    and on a study whose own sim.dt is fine, from the CLI and from Python."""
    study = tmp_path / "st.toml"
    study.write_text(ST_STUDY)
    paper = ["tune", "--check", "39.5204,1.639,11.6124,0.023", "--controller", "pi", "--model", "st"]
    err = _refused_cli([*paper, "--dt", "0.05", "--horizon", "2", "--json"], "--dt", capsys)
    assert "needs dt <= 0.0222 s for a stable RK4 step, got 0.05" in err, err
    _refused_cli(["tune", "--check=-5,-2", "--controller", "state-feedback", "--scenario", str(study)]
                 + ["--n-runs", "2", "--dt", "0.05", "--json"], "--dt", capsys)  # fmt: skip
    with pytest.raises(InputError, match=r"^config\.dt: the ST model at mu = 1\.0489 .* needs dt <= 0\.0222 s"):
        pfjax.tune("state_feedback", "paper-line", model="st", check=[-5, -2], config={"dt": 0.05, "horizon": 2.0})
    with pytest.raises(InputError, match=r"^config\.dt: the ST model") as e:
        make_problem("state_feedback", str(study), n_runs=2, config=SimConfig(dt=0.05))
    assert e.value.key == "config.dt"
    with pytest.raises(InputError, match=r"^config\.dt: the STD model"):
        make_problem("pi", "paper-line", model="std", config={"dt": 0.05})
    assert make_problem("state_feedback", str(study), n_runs=2, config={"dt": 0.02}).config.dt == 0.02  # stable
    assert make_problem("state_feedback", "paper-line", config={"dt": 0.05}).config.dt == 0.05  # kinematic: no bound


def test_tune_on_a_study_draws_its_slip_for_the_final_horizon(tmp_path):
    """A horizon beyond a study's (3 s, OU slip every 50 ms) draws the sequences for the whole run
    instead of holding the last sample from 3.1 s on; a shorter one keeps the study's draws."""
    study = tmp_path / "ou.toml"
    study.write_text(OU_STUDY)
    own = make_problem("state_feedback", str(study), n_runs=2)
    for config in ({"horizon": 30.0}, SimConfig(horizon=30.0)):
        pr = make_problem("state_feedback", str(study), n_runs=2, config=config)
        slip = pr.scenarios[0].slip
        assert pr.config.horizon == 30.0
        assert (slip.seq.shape[1] - 1) * float(np.asarray(slip.seq_dt).reshape(-1)[0]) >= 30.0, slip.seq.shape
    short = make_problem("state_feedback", str(study), n_runs=2, config={"horizon": 2.0})
    np.testing.assert_array_equal(short.scenarios[0].slip.seq, own.scenarios[0].slip.seq)


@pytest.mark.parametrize(
    "argv,flag",
    [
        (["--method", "ga", "--from-default"], "--from-default"),
        (["--method", "ga", "--screen", "3", "--smoothing", "0.5"], "--screen"),
        (["--method", "ga+gradient", "--from-default"], "--from-default"),  # the GA takes no start
        (["--method", "gradient", "--from-default"], "--from-default"),  # always screened
        (["--method", "gradient", "--generations", "7"], "--generations"),
        (["--method", "gradient-plain", "--population", "6"], "--population"),
        (["--method", "ga", "--steps", "4"], "--steps"),
        (["--method", "ga+gradient", "--starts", "2"], "--starts"),
        (["--method", "ga", "--lr", "0.3"], "--lr"),
        (["--check=-5,-2", "--generations", "7", "--lr", "0.3", "--steps", "4"], "--generations"),
        (["--check=-5,-2", "--lr", "0.3"], "--lr"),
        (["--check=-5,-2", "--from-default"], "--from-default"),
        (["--check=-5,-2", "--seed", "0"], "--seed"),  # a given 0 is given
        (["--method", "ga", "--smoothing", "0"], "--smoothing"),
        (["--check=-5,-2", "--n-runs", "5"], "--n-runs"),
        (["--method", "ga", "--scenario", "paper-all", "--n-runs", "5"], "--n-runs"),
        (["--method", "ga", "--level", "0.5"], "--level"),  # --aggregate mean reads no level
        (["--method", "gradient", "--smoothing", "1e6"], "--smoothing"),  # box units: at most 1
        (["--method", "gradient", "--smoothing", "1.01"], "--smoothing"),
    ],
)
def test_tune_cli_refuses_flags_the_method_does_not_read(argv, flag, capsys):
    _refused_cli(["tune", "--controller", "state-feedback", *argv, "--json"], flag, capsys)


def test_multistart_smoothing_is_at_most_the_box_width():
    from pfjax.tuning import MultistartOptions

    assert MultistartOptions(smoothing=1.0).check().smoothing == 1.0
    with pytest.raises(InputError, match=r"^smoothing: must be <= 1, got 1e\+06$"):
        MultistartOptions(smoothing=1e6).check()


def test_tune_api_names_its_own_arguments():
    """The GA's population_size is pfjax.tune's population; a SimConfig field is config's."""
    with pytest.raises(InputError, match=r"^population: must be >= 2, got 0$") as e:
        pfjax.tune("pi", "paper-line", "ga", population=0)
    assert e.value.key == "population"
    with pytest.raises(InputError, match=r"^config\.dt: expected a finite number, got nan$") as e:
        pfjax.tune("pi", "paper-line", "ga", config={"dt": math.nan})
    assert e.value.key == "config.dt"
    with pytest.raises(InputError, match=r"^config\.horizon: must be > 0"):
        pfjax.tune("pi", "paper-line", "ga", config={"horizon": 0.0})
    with pytest.raises(InputError, match=r"^config\.dt: "):
        make_problem("pi", "paper-line", config={"dt": -1.0})
    from pfjax.tuning.cost import CostSpec

    # as --level with --aggregate mean: a level the mean would not read is refused, not ignored
    with pytest.raises(InputError, match=r"^level: not with aggregate mean") as e:
        pfjax.tune("pi", "paper-line", "ga", cost=CostSpec(level=0.5))
    assert e.value.key == "level"
    assert CostSpec(aggregate="cvar").check().quantile_level == 0.9


def test_a_horizon_too_short_for_the_scenario_sets_windows_names_the_flag(capsys):
    toml = str(Path(__file__).resolve().parents[1] / "studies" / "tuning_heldout.toml")
    argv = ["tune", "--controller", "pi", "--method", "ga", "--scenario", toml, "--horizon", "5", "--json"]
    _refused_cli(argv, "--horizon", capsys)


def test_too_many_steps_names_the_flag_given(capsys):
    """A run of more integrator steps than a run may take names the two flags together on the
    command line (--horizon/--dt, as pfjax simulate and pfjax track); the API names the setting the
    caller gave (config.horizon when only it was given, config.dt when the step was given too)."""
    base = ["tune", "--controller", "pi", "--method", "ga", "--horizon", "1e7"]
    _refused_cli(base, "--horizon/--dt", capsys)
    _refused_cli([*base, "--dt", "0.001"], "--horizon/--dt", capsys)
    _refused_cli(["tune", "--controller", "pi", "--method", "ga", "--dt", "1e-9"], "--horizon/--dt", capsys)
    # the API names its config fields as the command line names its flags
    for config, key in (({"horizon": 1e7}, "config.horizon"), ({"horizon": 1e7, "dt": 0.001}, "config.dt")):
        with pytest.raises(InputError, match=rf"^{key}: horizon / dt"):
            pfjax.tune("pi", "paper-line", "ga", config=config)
    toml = str(Path(__file__).resolve().parents[1] / "studies" / "tuning_heldout.toml")
    with pytest.raises(InputError, match=r"^config\.horizon: 4 s is too short for the scenario set"):
        pfjax.tune("pi", toml, "ga", config={"horizon": 4.0})


@pytest.mark.parametrize(
    "argv,flag",
    [
        (["--method", "h2", "--alpha", "nan"], "--alpha"),
        (["--method", "hinf", "--alpha", "-3", "--json"], "--alpha"),
        (["--method", "h2", "--beta", "inf"], "--beta"),
        (["--method", "hinf", "--beta", "-1"], "--beta"),
    ],
)
def test_synth_checks_alpha_and_beta_whatever_the_method(argv, flag, capsys):
    _refused_cli(["synth", *argv], flag, capsys)


@pytest.mark.parametrize(
    ("method", "kwargs", "name"),
    [
        ("gradient", {"generations": 5}, "generations"),
        ("ga", {"steps": 4}, "steps"),
        ("ga", {"learning_rate": 0.1}, "learning_rate"),
        ("gradient-plain", {"multistart": object()}, "multistart"),
        ("ga+gradient", {"n_starts": 2}, "n_starts"),
        ("gradient", {"from_default": True}, "from_default"),
        ("ga", {"from_default": True}, "from_default"),
    ],
)
def test_tune_api_refuses_a_setting_its_method_does_not_read(method, kwargs, name):
    """As ``pfjax tune`` refuses the flag (pfjax.tuning.problem.METHOD_SETTINGS, one table for both),
    before any problem is built."""
    with pytest.raises(InputError, match=rf"^{name}: not with method {re.escape(method)} \(only with method "):
        pfjax.tune("pi", "paper-line", method, **kwargs)
    with pytest.raises(InputError, match=rf"^{name}: not with a check "):
        pfjax.tune("pi", "paper-line", check=[39.5204, 1.639, 11.6124, 0.023], **kwargs)


def test_an_error_in_a_study_file_keeps_the_files_words(tmp_path, capsys):
    """``--scenario: sim.dt: ...`` is about the study file's keys: its words (model, dt) are not
    turned into the command's flags (--model, --dt)."""
    study = tmp_path / "st.toml"
    study.write_text(ST_STUDY.replace("dt = 0.01", "dt = 0.05"))
    assert main(["tune", "--check=-5,-2", "--controller", "state-feedback", "--scenario", str(study)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("pfjax tune: error: --scenario: sim.dt: the ST model at ") and "needs dt <= " in err, err


def test_tune_api_refuses_a_method_with_a_check_and_defaults_to_gradient(monkeypatch):
    """As ``pfjax tune`` refuses ``--method`` with ``--check`` (a check runs no method); without
    either, the API tunes by the multi-start gradient method."""
    from pfjax.tuning import problem

    with pytest.raises(InputError, match=r"^check: checks given gains; give method or check, not both$"):
        pfjax.tune("pi", "paper-line", "ga", check=[39.5204, 1.639, 11.6124, 0.023])

    class Reached(Exception):
        pass

    def record(p, method, **kw):
        raise Reached(method)

    monkeypatch.setattr(problem, "tune", record)
    with pytest.raises(Reached, match="^gradient$"):
        pfjax.tune("pi", "paper-line", config={"horizon": 1.0})


@pytest.mark.parametrize(
    ("box", "key"),
    [((("k_x",), (0.0,), (1.0,)), "box.fields"), ((("kp_d",), (2.0,), (1.0,)), "box.lower[0]")],
)
def test_make_problem_checks_a_given_box_as_register_does(box, key):
    """A box given to make_problem is checked like a registered one (controllers.check_box), before
    tuning would fail inside JAX or the GA."""
    from pfjax.tuning.problem import make_problem

    with pytest.raises(InputError, match=rf"^{re.escape(key)}: "):
        make_problem("pi", "paper-line", box=box)


def _fake_result(D: int):
    from pfjax.tuning.gradient import TuneResult

    h = np.asarray([1.0])
    return TuneResult(np.zeros(D), 1.0, h, np.asarray([1]), h, 1, 0.0, 0, 1, 0.0)


def test_rounds_are_checked_against_the_final_steps_in_the_cli_and_the_api(monkeypatch, capsys):
    """``--rounds`` is checked once, after ``--steps`` is applied (70 rounds of 80 steps run), and
    rounds above the steps are refused, not cut to them, an explicit 3 among them; the API alike,
    naming its argument. Rounds not given (3) fall to ``steps`` below 3."""
    from pfjax.tuning import MultistartOptions, problem

    seen = []

    def fake_tune(pr, method, **kw):
        seen.append(problem.check_options(method, kw["ga_options"], kw["steps"], None, None, kw["multistart"]))
        return _fake_result(pr.lower.size)

    monkeypatch.setattr(problem, "tune", fake_tune)
    argv = ["tune", "--method", "gradient", "--controller", "pi", "--json"]
    assert main([*argv, "--rounds", "70", "--steps", "80"]) == 0
    assert (seen[-1].rounds, seen[-1].steps) == (70, 80)
    capsys.readouterr()
    err = _refused_cli([*argv, "--rounds", "50", "--steps", "30"], "--rounds", capsys)
    assert "--rounds: must be <= --steps (30), got 50" in err, err
    with pytest.raises(InputError, match=r"^multistart\.rounds: must be <= steps \(30\), got 50$") as e:
        pfjax.tune("pi", steps=30, multistart=MultistartOptions(rounds=50))
    assert e.value.key == "multistart.rounds"
    with pytest.raises(InputError, match=r"^rounds: must be <= steps \(30\), got 50$"):
        problem.check_options("gradient", problem.GAOptions(), 30, None, None, MultistartOptions(rounds=50))
    assert problem.check_options("gradient", problem.GAOptions(), 2, None, None, None).rounds == 2
    assert main([*argv, "--steps", "2"]) == 0 and seen[-1].rounds == 2
    capsys.readouterr()
    assert "--rounds: must be <= --steps (2), got 3" in _refused_cli(
        [*argv, "--rounds", "3", "--steps", "2"], "--rounds", capsys
    )
    with pytest.raises(InputError, match=r"^multistart\.rounds: must be <= steps \(2\), got 3$"):
        pfjax.tune("pi", steps=2, multistart=MultistartOptions(rounds=3))
    assert MultistartOptions(steps=2).check().rounds == 2 and MultistartOptions().check().rounds == 3


def test_tune_api_refuses_what_the_cli_refuses(capsys):
    """``n_runs`` with a paper set (one run per path) and ``key`` with ``check`` (a check draws
    nothing) are refused as ``--n-runs`` and ``--seed`` are, before any problem is built."""
    with pytest.raises(InputError, match=r"^n_runs: not with scenario paper-line \(it samples the runs of a study"):
        pfjax.tune("pi", "paper-line", "ga", n_runs=7, population=4, generations=1, config={"horizon": 1.0})
    _refused_cli(["tune", "--method", "ga", "--controller", "pi", "--n-runs", "7"], "--n-runs", capsys)
    with pytest.raises(InputError, match=r"^key: not with a check \(only with method ga, gradient, "):
        pfjax.tune("pi", check="39.5204,1.639,11.6124,0.023", key=5)
    _refused_cli(
        ["tune", "--check", "39.5204,1.639,11.6124,0.023", "--controller", "pi", "--seed", "5"], "--seed", capsys
    )


@pytest.mark.parametrize(
    "argv, read, unread",
    [
        (["--method", "gradient"], {"seed": 0}, ("population", "generations", "n_runs")),
        (["--method", "ga"], {"seed": 0, "population": 50, "generations": 100}, ("n_runs", "steps")),
        (["--check", "10,0,2,0"], {}, ("seed", "population", "generations", "n_runs")),
    ],
    ids=["gradient", "ga", "check"],
)
def test_tune_json_records_only_the_arguments_the_run_read(monkeypatch, capsys, argv, read, unread):
    """``arguments`` (and the hash over it) holds the defaults of the flags the run reads and None
    for those it does not (the GA's sizes with the gradient tuner, --n-runs with a paper set): two
    runs that differ only in what they did not read would otherwise record different inputs."""
    import inspect
    import json

    from pfjax.cli import tune as cli_tune
    from pfjax.tuning import GAOptions, problem

    assert (cli_tune.DEFAULTS["population"], cli_tune.DEFAULTS["generations"]) == (
        GAOptions().population_size,
        GAOptions().generations,
    )
    assert cli_tune.DEFAULTS["n_runs"] == inspect.signature(problem.make_problem).parameters["n_runs"].default
    seen = []

    def fake_tune(pr, method, **kw):
        seen.append(kw["ga_options"])
        return _fake_result(pr.lower.size)

    monkeypatch.setattr(problem, "tune", fake_tune)
    assert main(["tune", "--controller", "pi", "--json", *argv]) == 0
    got = json.loads(capsys.readouterr().out)["arguments"]
    assert {k: got[k] for k in read} == read and all(got[k] is None for k in unread), got
    if seen:
        assert seen[-1] == GAOptions()


def test_from_default_starts_the_plain_descent_at_the_default_gains_in_the_cli_and_the_api(monkeypatch, capsys):
    """``pfjax tune --from-default`` and ``pfjax.tune(from_default=True)`` hand the tuner the
    controller's default gains as its first start; without it there is none."""
    from pfjax.tuning import problem

    seen = []

    def fake_tune(pr, method, **kw):
        seen.append(kw["theta0"])
        return _fake_result(pr.lower.size)

    monkeypatch.setattr(problem, "tune", fake_tune)
    assert main(["tune", "--controller", "pi", "--method", "gradient-plain", "--from-default", "--json"]) == 0
    capsys.readouterr()
    pfjax.tune("pi", "paper-line", "gradient-plain", from_default=True)
    pfjax.tune("pi", "paper-line", "gradient-plain")
    default = problem.make_problem("pi", "paper-line").tunable.flatten()
    np.testing.assert_array_equal(seen[0], default)
    np.testing.assert_array_equal(seen[1], default)
    assert seen[2] is None


def test_the_level_a_quantile_or_cvar_ran_at_is_recorded_given_or_not(monkeypatch, capsys):
    """``--aggregate cvar`` without ``--level`` runs at level 0.9 and records it, in ``arguments``
    and ``cost_spec``: the same run as ``--level 0.9``, with the same config hash."""
    import json

    from pfjax.tuning import problem

    monkeypatch.setattr(problem, "tune", lambda pr, method, **kw: _fake_result(pr.lower.size))
    outs = []
    for extra in ([], ["--level", "0.9"]):
        assert (
            main(["tune", "--controller", "pi", "--method", "gradient", "--aggregate", "cvar", "--json", *extra]) == 0
        )
        outs.append(json.loads(capsys.readouterr().out))
    assert [o["arguments"]["level"] for o in outs] == [0.9, 0.9]
    assert [o["cost_spec"]["level"] for o in outs] == [0.9, 0.9]
    assert outs[0]["config_sha256"] == outs[1]["config_sha256"]


def test_cli_and_api_report_the_same_gains_and_check_takes_them_back(capsys):
    """``pfjax tune --json`` and :func:`pfjax.tune` report every gain by its scalar name (what
    ``--gains`` and :func:`pfjax.simulate` take), and ``--check`` / ``check=`` take that dict back;
    an untuned gain given away from the problem's value, or a tuned one left out, is refused."""
    import json

    argv = ["tune", "--controller", "state-feedback", "--horizon", "16", "--dt", "0.01", "--json"]
    assert main([*argv, "--method", "gradient", "--steps", "2", "--screen", "2", "--starts", "1"]) == 0
    cli = json.loads(capsys.readouterr().out)
    api = pfjax.tune("state_feedback", config={"horizon": 16.0, "dt": 0.01}, steps=2, n_starts=1)
    assert set(cli["gains"]) == set(api["gains"]) == {"k_d", "k_theta", "feedforward"}
    given = json.dumps(cli["gains"])
    assert main([*argv, "--check", given]) == 0
    checked = json.loads(capsys.readouterr().out)
    assert checked["gains"] == cli["gains"]
    # the best probe's displacement is in each gain's own unit (span x box units), as the gains
    u = checked["units"]
    assert {g: u[f"check.best_probe.{g}"] for g in checked["check"]["best_probe"]} == {
        "K[0]": "rad/m",
        "K[1]": "rad/rad",
    }
    again = pfjax.tune("state_feedback", config={"horizon": 16.0, "dt": 0.01}, check=cli["gains"])
    assert again["gains"] == cli["gains"] and again["cost"] == pytest.approx(checked["cost"], rel=1e-6)
    for bad, text in (
        ({**cli["gains"], "feedforward": 0.5}, "feedforward is not tuned here"),
        ({"k_d": cli["gains"]["k_d"]}, "k_theta missing"),
    ):
        msg = _refused_cli([*argv, "--check", json.dumps(bad)], "--check", capsys)
        assert text in msg, msg
        with pytest.raises(InputError, match=f"^check: .*{text}"):
            pfjax.tune("state_feedback", config={"horizon": 16.0, "dt": 0.01}, check=bad)
