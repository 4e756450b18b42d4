"""Malformed input, table-driven: every case gives exit code 2, exactly one line on stderr that names
the flag or key and contains the expected message, nothing on stdout and nothing written.

Cases go through the command line entry point ``pfjax.cli.main`` in-process (argument parsing and
validation happen before anything is computed) and, for study configs, also through
``pfjax.montecarlo.config.load_study``. Feasibility problems that are not errors (a path sharper
than the steering limit allows, a user path shorter than the runs travel) are warnings.
"""

import copy
import re

import pytest

from pfjax.cli import main
from pfjax.config import ConfigError
from pfjax.montecarlo.checks import study_warnings
from pfjax.montecarlo.config import load_study

STUDY = """name = "v"
n_runs = 4
seed = 1
chunk_size = 4
[sim]
horizon = 2.0
steady_window = 1.0
[success]
from_s = 1.0
[margin]
enabled = false
[[paths]]
kind = "line"
[[controllers]]
name = "st"
type = "stanley"
"""
DATA = {
    "name": "v",
    "n_runs": 4,
    "seed": 1,
    "chunk_size": 4,
    "sim": {"horizon": 2.0, "steady_window": 1.0},
    "success": {"from_s": 1.0},
    "margin": {"enabled": False},
    "paths": [{"kind": "line"}],
    "controllers": [{"name": "st", "type": "stanley"}],
}
SPLINE = "paths[0]={kind='spline', points=%s}"
SIM = ["simulate", "--path", "line", "--controller", "pi"]

#: (argv after ``pfjax``, the message expected on the one stderr line). ``CFG`` is replaced by the
#: study file, ``FILE`` by an existing regular file.
CLI_CASES = [
    (["synth", "--speed", "0"], "--speed: must be > 0 m/s, got 0"),
    (["synth", "--wheelbase", "-0.2"], "--wheelbase: must be > 0 m, got -0.2"),
    (["synth", "--speed", "nan"], "--speed: expected a finite number, got nan"),
    (["synth", "--alpha", "-1"], "--alpha: must be >= 0, got -1"),
    (["synth", "--disk", "-5", "0"], "--disk: must be > 0 1/s, got 0"),
    (["synth", "--sector-deg", "90.5"], "--sector-deg: expected a half-angle in (0, 90], got 90.5"),
    (["synth", "--method", "lqg"], "argument --method: invalid choice: 'lqg'"),
    (SIM + ["--beta-r-deg", "90"], "--beta-r-deg: magnitude must be < 90 deg, got 90"),
    (SIM + ["--beta-f-deg", "-120"], "--beta-f-deg: magnitude must be < 90 deg, got -120"),
    (SIM + ["--delta-max-deg", "90"], "--delta-max-deg: must lie in (0, 90) deg, got 90"),
    (SIM + ["--delta-max-deg", "0"], "--delta-max-deg: must lie in (0, 90) deg, got 0"),
    (SIM + ["--speed", "-1"], "--speed: must be > 0 m/s, got -1"),
    (SIM + ["--wheelbase", "0"], "--wheelbase: must be > 0 m, got 0"),
    # a design controller is made at --speed and --wheelbase: they are checked before the synthesis
    (SIM[:-1] + ["mixed", "--speed", "nan"], "--speed: expected a finite number, got nan"),
    (SIM[:-1] + ["mixed", "--speed", "0"], "--speed: must be > 0 m/s, got 0"),
    (SIM[:-1] + ["polytopic-integral", "--wheelbase", "-1"], "--wheelbase: must be > 0 m, got -1"),
    (SIM + ["--dt", "0"], "--dt: must be > 0 s, got 0"),
    (SIM + ["--horizon", "inf"], "--horizon: expected a finite number, got inf"),
    (SIM + ["--dt", "2", "--horizon", "1"], "--horizon: must be >= --dt (2 s), got 1"),
    (SIM + ["--control-every", "0"], "--control-every: must be >= 1, got 0"),
    (SIM + ["--x0", "1", "nan", "0"], "--x0[1]: expected a finite number, got nan"),
    (SIM + ["--x0", "0", "0", "1e13"], "--x0[2]: expected a magnitude <= 1e+12 deg, got 1e+13"),  # THETA in deg
    (SIM + ["--gains", "1,2,3,4,5,6"], "--gains: expected all 5 gains of --controller pi in order"),
    (SIM + ["--gains", "kp_d=nan"], "--gains: kp_d: expected a finite number, got nan"),
    (SIM + ["--gains", "kp=1"], "--gains: unknown gain 'kp' for --controller pi"),
    (SIM + ["--gains", "kp_d=fast"], "--gains: kp_d='fast' is not a number"),
    (["simulate", "--path", "spiral", "--controller", "pi"], "argument --path: invalid choice: 'spiral'"),
    (SIM + ["--speed", "fast"], "argument --speed/--v: invalid float value: 'fast'"),
    (["study", "missing.toml"], "config: file not found: missing.toml"),
    (["study", "CFG", "--set", "n_runz=3"], "n_runz: unknown key (did you mean 'n_runs'?)"),
    # a design that cannot be made (infeasible LMIs): one line naming the controller, before --out is made
    (
        ["study", "CFG", "--set", 'controllers=[{name="m",type="lmi",alpha=1e12,beta=1e-12}]', "--out", "new/sub"],
        "controllers[0]: mixed synthesis failed: solver CLARABEL status 'infeasible'",
    ),
    (
        ["rare-event", "CFG", "--set", 'controllers=[{name="m",type="lmi",alpha=1e12,beta=1e-12}]'],
        "controllers[0]: mixed synthesis failed: solver CLARABEL status 'infeasible'",
    ),
    (
        ["simulate", "--path", "line", "--controller", "polytopic-integral", "--speed", "1e6", "--horizon", "1"],
        "--controller: polytopic-integral synthesis failed",
    ),
    (["study", "CFG", "--set", "nokey"], "--set: expected key=value, got 'nokey'"),
    (["study", "CFG", "--set", "n_runs=1.5"], "n_runs: Input should be a valid integer"),
    (["study", "CFG", "--set", "seed='x'"], "seed: Input should be a valid integer"),
    (["study", "CFG", "--set", "vehicle.L=0"], "vehicle.L: must be > 0 m, got 0"),
    (
        ["study", "CFG", "--set", "vehicle.speed={dist='uniform', low=-1, high=1}"],
        "vehicle.speed: must be > 0 over its whole range",
    ),
    (
        ["study", "CFG", "--set", "vehicle.delta_max_deg=90"],
        "vehicle.delta_max_deg: must lie in (0, 90) deg, got 90",
    ),
    (["study", "CFG", "--set", "slip.beta_r_deg=-90"], "slip.beta_r_deg: slip magnitudes must stay below 90 deg"),
    # a label in tables and reports: not blank, one line
    (["study", "CFG", "--set", 'controllers[0].name=""'], "controllers[0].name: expected a name shown in tables"),
    (["study", "CFG", "--set", 'paths[0].name="a\\nb"'], "paths[0].name: expected one line of at most 100"),
    # another profile's key: refused at any value but its default, as another path kind's or vehicle model's
    (["study", "CFG", "--set", "slip.ou_sigma_deg=-1"], 'slip.ou_sigma_deg: not with kind = "constant"'),
    (["study", "CFG", "--set", "slip.amp_r_deg=500"], 'slip.amp_r_deg: not with kind = "constant"'),
    (
        ["study", "CFG", "--set", "slip.beta_r_deg={dist='uniform', low=5, high=1}"],
        "slip.beta_r_deg: needs low < high, got low=5, high=1",
    ),
    (
        ["study", "CFG", "--set", "slip.beta_f_deg={dist='uniform', low=nan, high=1}"],
        "slip.beta_f_deg.low: expected a finite number, got nan",
    ),
    (
        ["study", "CFG", "--set", "initial.start_along_m={dist='choice', values=[]}"],
        "initial.start_along_m: 'values' must be a non-empty list",
    ),
    (["study", "CFG", "--set", "sim.dtt=0.1"], "sim.dtt: unknown key (did you mean 'sim.dt'?)"),
    (["study", "CFG", "--set", "paths[0].radus=3"], "paths[0].radus: unknown key (did you mean 'paths[0].radius'?)"),
    (
        ["study", "CFG", "--set", SPLINE % "[[0, 0], [1, 0]]"],
        "paths[0].points: a spline needs at least 4 points [x, y], got 2",
    ),
    (["study", "CFG", "--set", SPLINE % "[[0, 0], [1, 0], [1, 0], [2, 0]]"], "paths[0].points[2]: repeats point [1]"),
    (
        ["study", "CFG", "--set", SPLINE % "[[0, 0], [1, nan], [2, 0], [3, 0]]"],
        "paths[0].points[1][1]: expected a finite number, got nan",
    ),
    (
        ["study", "CFG", "--set", SPLINE % "[[0, 0], [1, 0], [0.5, 0], [2, 0]]"],
        "paths[0].points[2]: the path turns back",
    ),
    (
        ["study", "CFG", "--set", SPLINE % "[[0, 0], [1], [2, 0], [3, 0]]"],
        "paths[0].points[1]: expected a point [x, y]",
    ),
    (["study", "CFG", "--set", "paths[0]={kind='spline'}"], "paths[0].points: required for kind 'spline'"),
    (
        ["study", "CFG", "--set", "paths[0].points=[[0, 0], [1, 0], [2, 0], [3, 0]]"],
        "paths[0].points: not a key of a line path; its keys are kind, name (points is a key of kind 'spline')",
    ),
    (
        ["study", "CFG", "--set", "controllers[0]={name='k', type='state_feedback', K=[1.0]}"],
        "controllers[0]: state_feedback needs K = [k_d, k_theta]",
    ),
    (
        ["study", "CFG", "--set", "controllers[0].gains={k=nan}"],
        "controllers[0].gains.k: expected a finite number, got nan",
    ),
    (["study", "CFG", "--set", "controllers[3].K=[1, 2]"], "controllers[3]: no such list element"),
    (["study", "CFG", "--set", "f64_check_runs=-1"], "f64_check_runs: must be >= 0 (got -1)"),
    (["study", "CFG", "--out", "FILE"], "--out: FILE exists and is not a directory"),
    (["study", "CFG", "--out", "FILE/sub"], "a_file is not a directory (cannot create sub in it)"),
    (["report", "CFG", "--out", "EMPTY"], "--out: no finished study in EMPTY"),
    # the total slip over the distributions' support, not each term alone
    (
        ["study", "CFG", "--set", "slip.kind='sinusoid'", "--set", "slip.beta_r_deg=60", "--set", "slip.amp_r_deg=60"],
        "slip.amp_r_deg: the total slip must stay below 90 deg over the distributions' support, got max |beta_r_deg| + "
        "max |amp_r_deg| = 120 deg",
    ),
    (
        ["study", "CFG", "--set", "slip.kind='step'", "--set", "slip.beta_f_deg=50", "--set", "slip.step_f_deg=45"],
        "slip.step_f_deg: the total slip must stay below 90 deg",
    ),
    (
        ["study", "CFG", "--set", "slip.kind='ou'", "--set", "slip.ou_sigma_deg=1e6"],
        "slip.ou_sigma_deg: the total slip must stay below 90 deg over the distributions' support, got max |beta_r_deg| + 6",
    ),
    (
        ["study", "CFG", "--set", "initial.lateral_offset={dist='truncnormal', mean=5, std=1, low=-1, high=1}"],
        "initial.lateral_offset: needs low <= mean <= high",
    ),
    # numbers: booleans, strings, overflow, underflow, huge integers
    (["study", "CFG", "--set", "n_runs=true"], "n_runs: Input should be a valid integer (got True)"),
    (["study", "CFG", "--set", "seed=9223372036854775808"], "seed: must be <= 9223372036854775807"),
    (["study", "CFG", "--set", "seed=" + "9" * 400], "seed: must be <= 9223372036854775807 (got 99999"),
    (
        ["study", "CFG", "--set", "vehicle.speed=" + "9" * 400],
        "vehicle.speed: expected a number of magnitude <= 1e+12, got an integer of 400 digits",
    ),
    (["study", "CFG", "--set", "sim.dt=1e-300"], "sim.dt: must be >= 1e-12 (got 1e-300)"),
    (["study", "CFG", "--set", "sim.horizon=1e308"], "sim.horizon: expected a magnitude <= 1e+12, got 1e+308"),
    (["study", "CFG", "--set", "sim.horizon=inf"], "sim.horizon: expected a finite number, got inf"),
    (
        ["study", "CFG", "--set", "sim.dt=1e-9"],
        "sim.dt: horizon / dt (a run's integrator step count) may be at most 2e+06",
    ),
    (["study", "CFG", "--set", "noise.sigma_d=-0.1"], "noise.sigma_d: must be >= 0"),
    (["study", "CFG", "--set", "chunk_size=100000000"], "chunk_size: must be <= 10000000"),
    # names
    (["study", "CFG", "--set", "name='..'"], "name: expected 1-100 letters"),
    (["study", "CFG", "--set", "name='a/b'"], "name: expected 1-100 letters"),
    (["study", "CFG", "--set", "controllers[1]={name='st', type='pi'}"], "controllers[1]: no such list element"),
    # malformed --set keys
    (["study", "CFG", "--set", "controllers[abc].name=x"], "--set: malformed key 'controllers[abc].name'"),
    (["study", "CFG", "--set", "controllers[].name=x"], "--set: malformed key 'controllers[].name'"),
    (["study", "CFG", "--set", "n_runs[0]={dist='uniform'}"], "n_runs[0]: n_runs is not a list"),
    (["study", "CFG", "--set", "sim.dt[0]=1", "--quiet"], "sim.dt[0]: sim.dt is not a list"),
    (["study", "CFG", "--coordinator-timeout", "nan"], "--coordinator-timeout: expected a finite number, got nan"),
    (["study", "CFG", "--coordinator-timeout", "-5", "--quiet"], "--coordinator-timeout: must be > 0 s, got -5"),
    (
        ["study", "CFG", "--set", "slip.kind='ou'", "--set", "slip.seq_dt=1e-12"],
        "slip.seq_dt: sim.horizon / seq_dt (the slip samples per run) may be at most 2e+06",
    ),
    # flags that conflict, gains given partly or twice
    (SIM + ["--continuous", "--control-every", "2"], "--control-every: not with --continuous"),
    (SIM + ["--gains", "kp_d=1,kp_d=2"], "--gains: kp_d is given twice"),
    (SIM + ["--gains", "1,2"], "--gains: expected all 5 gains of --controller pi in order"),
    (SIM + ["--controller", "stanley", "--gains", "1,k_soft=2"], "--gains: mixes name=value pairs and bare numbers"),
    (
        ["tune", "--method", "gradient", "--controller", "pi", "--seed", "9223372036854775808"],
        "--seed: must be <= 9223372036854775807",
    ),
    (["tune", "--method", "ga", "--controller", "pi", "--population", "100000000"], "--population: must be <= 1000000"),
    (["bench", "--sizes", "1,0"], "--sizes: must be >= 1, got 0"),
    (
        [
            "study",
            "CFG",
            "--coordinator",
            "127.0.0.1:1",
            "--num-processes",
            "2",
            "--process-id",
            "1",
            "--coordinator-timeout",
            "0.5",
        ],
        "--coordinator: could not reach 127.0.0.1:1 within 0.5 s",
    ),
]


@pytest.fixture
def files(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "s.toml").write_text(STUDY)
    (tmp_path / "a_file").write_text("not a directory")
    return {"CFG": "s.toml", "FILE": "a_file", "EMPTY": "empty_dir"}


def _sub(arg: str, files: dict) -> str:
    for k, v in files.items():
        arg = arg.replace(k, v)
    return arg


@pytest.mark.parametrize("argv,expected", CLI_CASES, ids=[" ".join(a)[:60] for a, _ in CLI_CASES])
def test_cli_rejects_malformed_input(files, tmp_path, capsys, argv, expected):
    before = sorted(p.name for p in tmp_path.iterdir())
    argv = [_sub(a, files) for a in argv]
    try:
        code = main(argv)
    except SystemExit as e:  # argparse's own errors (invalid choice, not a number)
        code = e.code
    out, err = capsys.readouterr()
    assert code == 2, (argv, err)
    assert out == "", out
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith(f"pfjax {argv[0]}: error: "), lines[0]
    assert _sub(expected, files) in lines[0], lines[0]
    assert sorted(p.name for p in tmp_path.iterdir()) == before  # nothing written


def test_table_has_at_least_30_cases():
    assert len(CLI_CASES) >= 30


STUDY_CASES = [
    (a[3], e) for a, e in CLI_CASES if a[0] == "study" and len(a) == 4 and a[2] == "--set" and not e.startswith("--set")
]


@pytest.mark.parametrize("override,expected", STUDY_CASES, ids=[o[:50] for o, _ in STUDY_CASES])
def test_load_study_rejects_malformed_config(override, expected):
    with pytest.raises(ConfigError) as e:
        load_study(data=copy.deepcopy(DATA), overrides=[override])
    assert str(e.value).startswith(expected.split(":")[0] + ":"), str(e.value)
    assert expected in str(e.value) and "\n" not in str(e.value)


def test_malformed_toml_file(tmp_path):
    (tmp_path / "bad.toml").write_text("name = \n")
    with pytest.raises(ConfigError, match=r"^config: .*bad.toml: invalid TOML"):
        load_study(tmp_path / "bad.toml")


def test_a_value_nested_too_deeply_or_two_values_in_one_set_are_one_line_errors(tmp_path):
    """TOML's parser recurses per nesting level: thousands of brackets are a one-line error, not a
    RecursionError; a --set value that smuggles a second key in (a newline) is refused, not dropped."""
    deep = "[" * 5000 + "]" * 5000
    (tmp_path / "deep.toml").write_text(f'name = "x"\nn_runs = {deep}\n')
    with pytest.raises(ConfigError, match=r"^config: .*deep.toml: invalid TOML \(nested too deeply\)$"):
        load_study(tmp_path / "deep.toml")
    with pytest.raises(ConfigError, match=r"^--set: n_runs: the value is nested too deeply$"):
        load_study(data=copy.deepcopy(DATA), overrides=[f"n_runs={deep}"])
    with pytest.raises(ConfigError, match=r"^--set: n_runs: expected one value"):
        load_study(data=copy.deepcopy(DATA), overrides=["n_runs=16\nseed=5"])


def test_feasibility_warnings_name_the_path_and_the_numbers():
    """A circle tighter than the steering allows and a spline shorter than the runs travel are
    warnings, not errors; followable paths give none."""
    data = copy.deepcopy(DATA)
    data["paths"] = [
        {"kind": "line"},
        {"kind": "sine"},
        {"kind": "parabola"},
        {"kind": "circle", "radius": {"dist": "uniform", "low": 0.3, "high": 2.0}},
        {"kind": "spline", "name": "u", "points": [[0, 0], [0.5, 0.1], [1, 0], [1.5, 0.1]]},
    ]
    spec, _ = load_study(data=data)
    w = study_warnings(spec)
    assert len(w) == 2, w
    assert (
        w[0].startswith("paths[3] (circle): max curvature 3.333 1/m exceeds tan(delta_max)/L") and "2.887 1/m" in w[0]
    )
    assert w[1].startswith("paths[4] (u): 1.") and "status path_end" in w[1]
    # the parabola's vertex curvature (2 1/m) becomes unfollowable with a 20 deg steering limit: tan(20 deg)/0.2 = 1.82
    spec, _ = load_study(data=copy.deepcopy(DATA), overrides=["paths[0].kind='parabola'", "vehicle.delta_max_deg=20"])
    assert study_warnings(spec) == [
        "paths[0] (parabola): max curvature 2 1/m exceeds tan(delta_max)/L = tan(20 deg)/0.2 m = 1.82 1/m: "
        "the robot cannot follow it with its steering limit, even without slip"
    ]
    # start offsets beyond the failure band: runs that start there end as diverged at t = 0
    far = ["initial.lateral_offset={dist = 'uniform', low = -12.0, high = 12.0}", "sim.d_fail=3.0"]
    spec, _ = load_study(data=copy.deepcopy(DATA), overrides=far)
    assert study_warnings(spec) == [
        "initial.lateral_offset: starts up to 12 m from the path, beyond sim.d_fail = 3 m: runs that start "
        "beyond it end as diverged at t = 0"
    ]
    near = ["initial.lateral_offset={dist = 'normal', mean = 0.0, std = 0.05}", "sim.d_fail=3.0"]
    assert study_warnings(load_study(data=copy.deepcopy(DATA), overrides=near)[0]) == []  # unbounded: no reach


def test_a_config_that_is_not_utf8_is_one_line(files, tmp_path, capsys):
    (tmp_path / "latin1.toml").write_bytes(b'name = "caf\xe9"\n')
    assert main(["study", "latin1.toml"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["pfjax study: error: config: latin1.toml is not UTF-8 text (byte 11: invalid continuation byte)"]


def test_memory_guard_names_the_key(files, tmp_path, capsys, monkeypatch):
    """Sizes whose arrays exceed the memory budget are refused before anything is allocated."""
    monkeypatch.setenv("PFJAX_MEMORY_BUDGET", str(50 << 20))
    for argv, key in (
        (["study", "CFG", "--set", "chunk_size=4096", "--set", "n_runs=4096"], "chunk_size"),
        (["study", "CFG", "--set", "n_runs=1000000", "--set", "chunk_size=8"], "n_runs"),
        (["bench", "--sizes", "100000"], "--sizes"),
    ):
        assert main([_sub(a, files) for a in argv]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and f"error: {key}: " in err[0] and "memory budget of 50 MiB" in err[0], err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a_file", "s.toml"]


def test_the_python_api_rejects_what_the_cli_rejects():
    """The same checks from Python, with the argument's name where the CLI names its flag."""
    from pfjax import controllers as C
    from pfjax.errors import InputError
    from pfjax.sim import SimConfig, simulate_batch, stack
    from pfjax.sim.scenario import paper_scenario
    from pfjax.synthesis import synthesize

    pi = C.REGISTRY["pi"][1]()
    with pytest.raises(InputError, match=r"^beta_r_deg: magnitude must be < 90 deg, got 95$"):
        paper_scenario("line", pi, beta_r_deg=95)
    with pytest.raises(InputError, match=r"^gains: controller 'pi' takes PIParams, got StateFeedbackParams$"):
        simulate_batch(stack([paper_scenario("line", C.state_feedback_params())]), controller=C.pi, config=SimConfig())
    with pytest.raises(InputError, match=r"^gains\.kp_d: expected a finite number, got nan$"):
        C.REGISTRY["pi"][1](kp_d=float("nan"))
    with pytest.raises(InputError, match=r"^gains\.kp: unknown gain for controller 'pi'"):
        C.REGISTRY["pi"][1](kp=1.0)
    with pytest.raises(InputError, match=r"^horizon: expected a finite number, got inf$"):
        SimConfig(horizon=float("inf"))
    with pytest.raises(InputError, match=r"^v: must be > 0 m/s, got 0$"):
        synthesize("mixed", v=0.0)
    with pytest.raises(InputError, match=r"^pose0\[2\]: expected a finite number, got nan$"):
        paper_scenario("line", pi, pose0=(0.0, 0.0, float("nan")))


@pytest.mark.parametrize(
    "kwargs,flags,expected",
    [
        ({"speed": 5e-324}, ["--speed", "5e-324"], "must be at least 1e-12 m/s, got 4.94066e-324"),
        ({"L": 1e-13}, ["--wheelbase", "1e-13"], "must be at least 1e-12 m, got 1e-13"),
        ({"delta_max_deg": 95}, ["--delta-max-deg", "95"], "must lie in (0, 90) deg, got 95"),
        ({"delta_max_deg": 0}, ["--delta-max-deg", "0"], "must lie in (0, 90) deg, got 0"),
        ({"model": "st", "k_v": -1}, ["--model", "st", "--k-v", "-1"], "must be > 0 1/s, got -1"),
        ({"model": "st", "tau_delta_s": -1}, ["--model", "st", "--tau-delta", "-1"], "must be > 0 s, got -1"),
    ],
)
def test_scenarios_and_simulate_refuse_a_vehicle_setting_in_the_same_words(kwargs, flags, expected, capsys):
    """pfjax.scenarios (the study config's [vehicle] check) and pfjax simulate (the scenario
    builders) refuse the same values with one check's words, named by the argument or the flag: a
    speed of 5e-324 m/s, a robot that never moves, is not a run that succeeds."""
    import pfjax
    from pfjax.errors import InputError

    name = next(k for k in kwargs if k != "model")
    with pytest.raises(InputError) as e:
        pfjax.scenarios("sine", 2, **kwargs)
    assert str(e.value) == f"{name}: {expected}" and e.value.key == name
    assert main(SIM + flags) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"pfjax simulate: error: {flags[-2]}: {expected}"], err
    with pytest.raises(ConfigError, match=rf"^vehicle\.{name}: {re.escape(expected)}$"):
        load_study(data={**copy.deepcopy(DATA), "vehicle": kwargs})


def test_negative_numbers_in_exponent_form_are_values_not_options():
    """argparse's own pattern reads ``-1e-3`` as an option ("expected one argument"); pfjax's parser
    takes it, in single values and in lists of values, and still refuses a value that is not a number."""
    from pfjax.cli import build_parser

    p = build_parser()
    args = p.parse_args(SIM + ["--beta-r-deg", "-1e-3", "--x0", "0", "0", "-1e1"])
    assert args.beta_r_deg == -1e-3 and [float(v) for v in args.x0] == [0.0, 0.0, -10.0]
    assert p.parse_args(["track", "--offset", "-5e-1", "0.5"]).offset == [-0.5, 0.5]
    with pytest.raises(SystemExit):
        p.parse_args(SIM + ["--beta-r-deg", "-x"])


def test_a_sampling_period_longer_than_the_horizon_is_refused():
    """One command for the whole run (``control_every`` beyond the run's steps) is a mistake: refused
    naming the flag or key, by SimConfig, so on the command line, in a study config and in the API."""
    from pfjax.cli import main
    from pfjax.errors import InputError
    from pfjax.sim import SimConfig

    with pytest.raises(InputError, match=r"^control_every: .*\(200 steps\)"):
        SimConfig(horizon=1.0, control_every=201)
    assert SimConfig(horizon=1.0, control_every=200).control_every == 200
    assert main(["simulate", "--path", "line", "--controller", "pi", "--horizon", "1", "--control-every", "1000"]) == 2
    with pytest.raises(InputError, match=r"^sim\.control_every: .*\(1200 steps\)"):
        load_study(data=copy.deepcopy(DATA), overrides=["sim.control_every=1201", "sim.horizon=6", "success.from_s=1"])


def test_a_horizon_of_a_fraction_of_a_step_is_refused_everywhere(tmp_path, capsys):
    """``horizon / dt`` must be a whole number (to a relative 1e-9): never rounded to whole steps
    (0.015 s at 10 ms would run 2 steps, 0.02 s), refused naming the horizon in each front end."""
    from pfjax.errors import InputError
    from pfjax.sim import SimConfig

    with pytest.raises(InputError, match=r"^horizon: must be a whole number of steps dt = 0.01 s, got 0.015 s = 1.5 "):
        SimConfig(dt=0.01, horizon=0.015)
    with pytest.raises(InputError) as e:  # the value as given, never rounded to the horizon it suggests
        SimConfig(dt=0.005, horizon=20.0000001)
    assert "got 20.0000001 s = 4000.00002 steps (e.g. 20 or 20.005 s)" in str(e.value)
    assert SimConfig(dt=0.01, horizon=30.0).n_steps == 3000  # 30 / 0.01 = 2999.9999999999995
    assert SimConfig(dt=0.003, horizon=19.998).n_steps == 6666
    assert main(["simulate", "--path", "line", "--controller", "pi", "--horizon", "19", "--dt", "0.003", "--json"]) == 2
    err = capsys.readouterr().err
    assert (
        err.startswith("pfjax simulate: error: --horizon: must be a whole number of steps")
        and "18.999 or 19.002 s" in err
    )
    # the step alone changed (the horizon at its default): the step is named, with the steps that fit
    with pytest.raises(InputError, match=r"^dt: must divide horizon = 20 s into whole steps, got 0.003 s = 6666.66"):
        SimConfig(dt=0.003)
    assert main(["simulate", "--path", "line", "--controller", "pi", "--dt", "0.003", "--json"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("pfjax simulate: error: --dt: must divide --horizon = 20 s into whole steps")
    assert "(e.g. 0.00299985000749963 or 0.003000300030003 s)" in err  # 20 / 6667 and 20 / 6666, every digit
    for suggested in (0.00299985000749963, 0.003000300030003):  # each is accepted as written
        assert SimConfig(dt=suggested).n_steps in (6666, 6667)
    out = tmp_path / "never"
    code = main(["study", "--example", "default", "--set", "sim.horizon=20.001", "--out", str(out)])
    assert code == 2 and not out.exists()
    assert "sim.horizon: must be a whole number of steps" in capsys.readouterr().err


def test_a_success_window_past_the_horizon_is_refused():
    """``success_from`` beyond the run would leave the success window empty, and every run that did
    not fail would pass: refused, as a study refuses ``success.from_s`` past ``sim.horizon``."""
    import pfjax
    from pfjax.errors import InputError
    from pfjax.sim import SimConfig

    with pytest.raises(InputError, match=r"^success_from: must be <= horizon \(1 s\), got 100$"):
        SimConfig(horizon=1.0, dt=0.01, success_from=100.0)
    assert SimConfig(horizon=1.0, dt=0.01, success_from=1.0).success_start == 1.0
    sc = pfjax.scenarios("line", 2)
    with pytest.raises(InputError, match=r"^config.success_from: must be <= horizon"):
        pfjax.simulate(sc, "pi", config={"horizon": 1.0, "dt": 0.01, "success_from": 100.0})


@pytest.mark.parametrize("axes", ['["rear","rear"]', "[]"])
def test_margin_axes_must_be_distinct_and_present(axes):
    """A repeated axis would run and count its sweep twice; an empty list would run none."""
    with pytest.raises(ConfigError, match=r"^margin.axes: must be distinct axes of rear, front, joint"):
        load_study(data=copy.deepcopy(DATA), overrides=[f"margin.axes={axes}"])


def test_a_design_with_both_weights_zero_is_refused_at_load():
    """alpha = beta = 0 leaves the mixed objective empty: the synthesis's own check
    (pfjax.synthesis.lmi.check_weights) refuses it when the study is read, not in a traceback."""
    overrides = ['controllers[0].type="lmi"', "controllers[0].alpha=0", "controllers[0].beta=0"]
    with pytest.raises(ConfigError, match=r"^controllers\[0\].alpha: must not be 0 together with beta"):
        load_study(data=copy.deepcopy(DATA), overrides=overrides)
