"""The command line's audit: exact flags only, errors that name the subcommand and the flag at
fault, defaults in every ``--help``, spelling hints for controllers, packaged examples that run
without the repository, warnings as one line, a readable null in plain text and the warnings of a
design that is not usable."""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import warnings
from pathlib import Path

import pytest

from pfjax.cli import SUBCOMMANDS, build_parser, main

_SCRIPT = Path(sys.executable).with_name("pfjax")
PFJAX = [str(_SCRIPT)] if _SCRIPT.exists() else [sys.executable, "-m", "pfjax.cli"]
SIM = ("simulate", "--path", "line", "--controller", "pi")


def refused(capsys, argv) -> str:
    """The one error line of a refused command (exit code 2, nothing on stdout)."""
    try:
        code = main(list(argv))
    except SystemExit as e:
        code = e.code
    out, err = capsys.readouterr()
    assert code == 2 and out == "", (argv, code, out, err)
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    return lines[0]


def subparsers() -> dict[str, argparse.ArgumentParser]:
    p = build_parser()
    action = next(a for a in p._actions if isinstance(a, argparse._SubParsersAction))
    return dict(action.choices)


# ------------------------------------------------------------------ 1, 2: exact flags, the subcommand named


@pytest.mark.parametrize(
    "argv, command, word",
    [
        ((*SIM, "--hor", "10"), "simulate", "--hor"),
        ((*SIM, "--jso"), "simulate", "--jso"),
        (("study", "--ex", "default"), "study", "--ex"),
        (("synth", "--meth", "h2"), "synth", "--meth"),
        (("tune", "--controller", "pi", "--meth", "ga"), "tune", "--meth"),
        (("rare-event", "--examp", "rare_events"), "rare-event", "--examp"),
    ],
)
def test_an_abbreviated_flag_is_refused(capsys, argv, command, word):
    line = refused(capsys, argv)
    assert line.startswith(f"pfjax {command}: error: unrecognized arguments: {word}"), line


def test_no_parser_reads_abbreviations():
    assert build_parser().allow_abbrev is False
    assert all(p.allow_abbrev is False for p in subparsers().values())
    from pfjax.cli.study import script_parser

    assert script_parser("Doc.", config=None, out_default="results/x", quick="q").allow_abbrev is False


@pytest.mark.parametrize("argv", [(*SIM, "--bogus"), ("synth", "extra"), ("examples", "--nope")])
def test_an_unknown_word_is_refused_by_its_subcommand(capsys, argv):
    line = refused(capsys, argv)
    assert line.startswith(f"pfjax {argv[0]}: error: unrecognized arguments: {argv[-1]}"), line


# ------------------------------------------------------------------ 3: defaults in --help


def _help(command: str, flag: str) -> str:
    action = subparsers()[command]._option_string_actions[flag]
    return " ".join((action.help or "").split())


@pytest.mark.parametrize(
    "command, flag, text",
    [
        ("tune", "--scenario", "default paper-line"),
        ("tune", "--cost", "default iae"),
        ("tune", "--aggregate", "default mean"),
        ("tune", "--effort", "default 0"),
        ("tune", "--level", "default 0.9"),
        ("tune", "--generations", "default 100"),
        ("track", "--leader", "default line"),
        ("track", "--mode", "default forward"),
        ("parking", "--direction", "default forward"),
        ("synth", "--method", "default mixed"),
        ("simulate", "--model", "default kinematic"),
        ("parking-search", "--method", "required"),
        ("rare-event", "--max-rollouts", "at least 100, at most 100000000"),
    ],
)
def test_help_states_the_default(command, flag, text):
    assert text in _help(command, flag)


@pytest.mark.parametrize("command", SUBCOMMANDS)
def test_every_flag_with_a_default_says_it_in_help(command):
    for action in subparsers()[command]._actions:
        d = action.default
        if d is None or d is False or d is argparse.SUPPRESS or d == []:
            continue
        assert action.help and "default" in action.help, (command, action.option_strings, d)


def test_simulate_controller_help_lists_the_designs_from_their_registry():
    from pfjax import controllers as C

    text = _help("simulate", "--controller")
    designs, _, registered = text.partition("or a registered controller")
    for d in C.DESIGNS.values():
        assert f"{d.cli_name}: {d.style['label']}" in designs, d.name
    for e in C.REGISTRY.values():
        assert e.cli_name in registered and not re.search(rf"(?<![\w-]){e.cli_name}:", designs), e.name


# ------------------------------------------------------------------ 4: the flag at fault, one wording


def test_too_many_steps_names_horizon_and_dt(capsys):
    line = refused(capsys, (*SIM, "--horizon", "1e7"))
    assert line.startswith("pfjax simulate: error: --horizon/--dt: --horizon / --dt"), line
    line = refused(capsys, ("track", "--horizon", "1e7"))
    assert line.startswith("pfjax track: error: --horizon/--dt: --horizon / --dt"), line
    line = refused(capsys, ("tune", "--method", "ga", "--controller", "pi", "--horizon", "1e7"))
    assert line.startswith("pfjax tune: error: --horizon/--dt: --horizon / --dt"), line


def test_a_horizon_of_partial_steps_is_told_alike_by_simulate_and_tune(capsys):
    sim = refused(capsys, (*SIM, "--horizon", "20.001"))
    tune = refused(capsys, ("tune", "--check", "10,0,2,0", "--controller", "pi", "--horizon", "20.001"))
    for line, command in ((sim, "simulate"), (tune, "tune")):
        assert line.startswith(f"pfjax {command}: error: --horizon: must be a whole number of steps --dt = 0.005 s")
    assert sim.split("error: ")[1] == tune.split("error: ")[1]


# ------------------------------------------------------------------ 5: --out /


def test_out_root_and_empty_are_told_as_what_they_are(capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    line = refused(capsys, ("study", "--example", "default", "--out", "/"))
    assert line == "pfjax study: error: --out: / is a filesystem root; pfjax writes only into a directory of its own"
    line = refused(capsys, ("study", "--example", "default", "--out", ""))
    assert line.startswith("pfjax study: error: --out: '' does not name a new directory (it is empty)"), line
    line = refused(capsys, ("study", "--example", "default", "--out", "a/.."))
    assert "(it ends in '..')" in line
    assert list(tmp_path.iterdir()) == []


# ------------------------------------------------------------------ 6: controller spellings


@pytest.mark.parametrize(
    "argv, hint",
    [
        ((*SIM[:-1], "pure_pursuit"), "pure-pursuit"),
        ((*SIM[:-1], "lmi"), "mixed"),
        ((*SIM[:-1], "integral_lmi"), "integral-mixed"),
        (("tune", "--method", "ga", "--controller", "pure_pursuit"), "pure-pursuit"),
        (("tune", "--method", "ga", "--controller", "state_feedback"), "state-feedback"),
        (("tune", "--method", "ga", "--controller", "lmi"), "state-feedback"),
        (("track", "--leader", "lane_change"), "lane-change"),
        (("rare_event",), "rare-event"),
    ],
)
def test_a_config_spelling_is_refused_with_the_command_line_name(capsys, argv, hint):
    line = refused(capsys, argv)
    assert f"(did you mean {hint}?" in line, line


def test_an_unknown_controller_gets_no_hint(capsys):
    assert "did you mean" not in refused(capsys, (*SIM[:-1], "nope"))


# ------------------------------------------------------------------ 7: examples without the repository


def test_example_descriptions_give_commands_of_the_installed_package():
    from pfjax import examples

    for name, text in examples.describe().items():
        assert "studies/" not in text and ".toml" not in text, (name, text)
        for example in re.findall(r"(?:--example|--scenario) (\w+)", text):
            assert example in examples.FILES, (name, text)


def test_rare_event_takes_an_example(capsys):
    # the example is read: --max-rollouts is checked against the study it loaded
    line = refused(capsys, ("rare-event", "--example", "rare_events", "--max-rollouts", "50"))
    assert line == "pfjax rare-event: error: --max-rollouts: must be >= 100, got 50"
    line = refused(capsys, ("rare-event", "--example", "rare_events", "--controller", "nope"))
    assert line.startswith("pfjax rare-event: error: --controller: 'nope' is not one of study 'rare_events'")
    assert refused(capsys, ("rare-event", "--example", "nope")).startswith(
        "pfjax rare-event: error: --example: unknown example 'nope'"
    )
    assert refused(capsys, ("rare-event",)).startswith("pfjax rare-event: error: config: expected a study TOML")
    assert "not both" in refused(capsys, ("rare-event", "x.toml", "--example", "rare_events"))


def test_tune_takes_an_example_as_its_scenario(capsys):
    # read as the packaged study (its success window is longer than 2 s), not refused as a name
    line = refused(
        capsys, ("tune", "--check", "10,0,2,0", "--controller", "pi", "--scenario", "heldout", "--horizon", "2")
    )
    assert line.startswith("pfjax tune: error: --horizon: 2 s is too short for the scenario set"), line


# ------------------------------------------------------------------ 8: warnings as one line


def _cli(*args):
    env = {k: v for k, v in os.environ.items() if k != "PYTHONWARNINGS"}
    return subprocess.run([*PFJAX, *args], capture_output=True, text=True, timeout=300, env=env)


def test_a_deprecated_spelling_warns_in_one_line(capsys):
    from pfjax import errors

    errors._DEPRECATIONS.clear()
    assert main(["synth", "--v", "1", "--json"]) == 0
    err = capsys.readouterr().err
    assert err.splitlines() == [
        "pfjax synth: warning: --v is deprecated: it is read as --speed, and will be refused in the next release"
    ]


def test_a_library_warning_is_one_line_naming_the_command():
    r = _cli("synth", "--speed", "1e-9", "--wheelbase", "1e6", "--json")
    assert r.returncode == 0, r.stderr
    lines = r.stderr.splitlines()
    assert lines and all(ln.startswith("pfjax synth: warning: ") for ln in lines), r.stderr
    assert "RuntimeWarning" not in r.stderr and "return _solve(" not in r.stderr


def test_the_cli_restores_warnings_and_importing_pfjax_changes_nothing(capsys):
    shown = warnings.showwarning
    main(["examples", "--json"])
    assert warnings.showwarning is shown
    code = "import warnings; s = warnings.showwarning; import pfjax, pfjax.cli; print(warnings.showwarning is s)"
    assert subprocess.run([sys.executable, "-c", code], capture_output=True, text=True).stdout.strip() == "True"


# ------------------------------------------------------------------ 9: a readable null


def test_plain_text_shows_a_missing_value_as_none(capsys):
    from pfjax.cli.common import NULL, print_human

    print_human({"fail_time": None, "ci": [None, 0.5], "sub": {"margin": None}, "rows": [{"a": None}]})
    text = capsys.readouterr().out
    assert "None" not in text and NULL == "none"
    assert re.search(r"^fail_time +none$", text, re.M) and "[none, 0.5]" in text and "a none" in text


def test_simulate_plain_text_has_no_python_none(capsys):
    assert main([*SIM, "--dt", "0.05", "--horizon", "2"]) == 0
    out = capsys.readouterr().out
    assert re.search(r"^fail_time +none$", out, re.M) and "None" not in out, out


# ------------------------------------------------------------------ 10: a design that is not usable


def _synth(capsys, *args):
    import json

    assert main(["synth", *args, "--json"]) == 0
    out, err = capsys.readouterr()
    return json.loads(out), err


def test_synth_hinf_warns_that_its_gain_is_not_usable(capsys):
    out, err = _synth(capsys, "--method", "hinf")
    usable = [w for w in out["warnings"] if w.startswith("K is not a usable design")]
    assert len(usable) == 1 and "beyond 100 v/L = 500 1/s" in usable[0], out["warnings"]
    assert f"pfjax synth: warning: {usable[0]}" in err.splitlines()


def test_synth_mixed_and_a_bounded_hinf_design_have_no_warning(capsys):
    out, err = _synth(capsys)
    assert out["warnings"] == [] and err == "" and out["solver_status"] == "optimal"
    out, err = _synth(capsys, "--method", "hinf", "--disk", "0", "100")
    assert out["warnings"] == [] and err == ""


def test_synth_an_inaccurate_status_is_a_warning(capsys):
    out, err = _synth(capsys, "--speed", "1e-6")
    if out["solver_status"] == "optimal":  # another solver version may finish accurately
        pytest.skip("the solver reached 'optimal' here")
    status = [w for w in out["warnings"] if "status 'optimal_inaccurate', not 'optimal'" in w]
    assert len(status) == 1 and f"pfjax synth: warning: {status[0]}" in err.splitlines()


def test_the_library_refuses_weights_the_design_does_not_read_and_warns_on_an_unusable_gain():
    """pfjax.synthesis.synthesize refuses alpha and beta with hinf and h2, as pfjax synth refuses
    --alpha and --beta; its hinf design without a pole region (a gain growing without bound) carries
    the warning pfjax synth prints, and the mixed design none."""
    import warnings

    from pfjax.errors import InputError
    from pfjax.synthesis import synthesize

    for method in ("hinf", "h2"):
        with pytest.raises(InputError, match=rf"^alpha: only the mixed design reads it, not method '{method}'"):
            synthesize(method, alpha=-5.0)
    with pytest.raises(InputError, match=r"^beta: only the mixed design reads it"):
        synthesize("h2", beta=float("nan"))
    with pytest.warns(RuntimeWarning, match="K is not a usable design"):
        d = synthesize("hinf")
    assert any(w.startswith("K is not a usable design") for w in d.warnings)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert synthesize("mixed").warnings == ()
