"""The ST model in studies, on the command line and in the Python API: ``[vehicle] model = "st"`` with
its parameter set and friction distribution; the kinematic-only and ST-only keys refused with the
other model, one line naming the key (the flag on the command line, exit 2; the argument in the API);
a small study's run table with the friction and the slip the runs produced."""

from __future__ import annotations

import contextlib
import inspect
import io
import json

import numpy as np
import pytest

import pfjax
from pfjax.cli import main
from pfjax.config import ConfigError
from pfjax.errors import InputError
from pfjax.montecarlo.config import MODEL_SETTINGS, VehicleSpec, load_study

BASE = {
    "name": "st",
    "n_runs": 8,
    "seed": 3,
    "paths": [{"kind": "sine"}],
    "controllers": [{"name": "stanley", "type": "stanley"}],
}


def _spec(vehicle: dict, **top):
    return load_study(data={**BASE, "vehicle": vehicle, **top})[0]


@pytest.mark.parametrize(
    "vehicle, top, message",
    [
        ({"model": "st"}, {}, "margin.enabled: the slip-margin sweep declares slip"),
        ({"model": "st", "L": 0.3}, {"margin": {"enabled": False}}, 'vehicle.L: not with model = "st"'),
        ({"model": "st", "convention": "lenain"}, {"margin": {"enabled": False}}, "vehicle.convention: not with"),
        ({"mu": 0.5}, {}, 'vehicle.mu: not with model = "kinematic"'),
        ({"params": "vehicle2"}, {}, 'vehicle.params: not with model = "kinematic"'),
        ({"model": "st", "mu": 0.0}, {"margin": {"enabled": False}}, "vehicle.mu: must lie in (0, 10]"),
        ({"model": "st"}, {"margin": {"enabled": False}, "slip": {"beta_r_deg": 2.0}}, "slip.beta_r_deg: not with"),
        ({"model": "st", "params": "truck"}, {"margin": {"enabled": False}}, "vehicle.params: Input should be"),
        ({"model": "st", "mu": 10.0}, {"margin": {"enabled": False}}, "sim.dt: the ST model at mu = 10 and speed 1"),
        (
            {"model": "st"},
            {"margin": {"enabled": False}, "falsifier": {"enabled": True}},
            "falsifier.enabled: the worst-case search",
        ),
    ],
)
def test_config_refuses_keys_of_the_other_model_naming_them(vehicle, top, message):
    with pytest.raises(ConfigError) as e:
        _spec(vehicle, **top)
    assert str(e.value).startswith(message) and "\n" not in str(e.value)


#: A valid value, other than the default, for every name in MODEL_SETTINGS.
SETTING_VALUES = {
    **dict.fromkeys(["beta_r_deg", "beta_f_deg", "--beta-r-deg", "--beta-f-deg"], "3"),
    **dict.fromkeys(["L", "--wheelbase"], "0.3"),
    **dict.fromkeys(["delta_max_deg", "--delta-max-deg"], "20"),
    "delta_rate_max_deg": "50",
    **dict.fromkeys(["convention", "--convention"], "lenain"),
    **dict.fromkeys(["params", "vehicle_params", "--vehicle"], "vehicle2"),
    **dict.fromkeys(["mu", "--mu"], "0.5"),
    **dict.fromkeys(["tau_delta_s", "--tau-delta"], "0.1"),
    **dict.fromkeys(["k_v", "--k-v"], "3"),
}


def _value(name: str):
    """The value as the config and the API take it: a number, or a name."""
    try:
        return float(SETTING_VALUES[name])
    except ValueError:
        return SETTING_VALUES[name]


@pytest.mark.parametrize("setting", MODEL_SETTINGS, ids=lambda s: s.flag or s.key)
def test_the_study_config_the_api_and_the_cli_refuse_each_setting_of_the_other_model_alike(setting):
    """One table (MODEL_SETTINGS), three places that read it: each refuses the setting with the
    other kind of model under its own name, for the same reason."""
    model = "st" if setting.reader == "kinematic" else "kinematic"
    why = f"({setting.refusal(model)})"
    assert setting.key or setting.argument or setting.flag
    if setting.key is not None:
        assert setting.key in VehicleSpec.model_fields
        with pytest.raises(ConfigError) as e:
            _spec({"model": model, setting.key: _value(setting.key)}, margin={"enabled": False})
        assert str(e.value) == f'vehicle.{setting.key}: not with model = "{model}" {why}; remove it'
    if setting.argument is not None:
        assert setting.argument in inspect.signature(pfjax.scenarios).parameters
        with pytest.raises(InputError) as e:
            pfjax.scenarios("sine", n=2, model=model, **{setting.argument: _value(setting.argument)})
        assert str(e.value) == f'{setting.argument}: not with model = "{model}" {why}; remove it'
    if setting.flag is not None:
        value = [] if setting.flag == "--continuous" else [SETTING_VALUES[setting.flag]]
        code, _, err = _main(
            "simulate", "--model", model, "--path", "line", "--controller", "stanley", setting.flag, *value
        )
        assert code == 2
        assert err.strip().splitlines()[-1] == f"pfjax simulate: error: {setting.flag}: not with --model {model} {why}"


def test_config_st_reads_the_parameter_set_and_friction():
    spec = _spec(
        {"model": "st", "params": "vehicle2", "mu": {"dist": "uniform", "low": 0.3, "high": 1.0}, "speed": 10.0},
        margin={"enabled": False},
    )
    p = spec.vehicle.st_params()
    assert p.mu == pytest.approx(0.65) and p.l_f == 1.1561957064
    assert spec.vehicle.wheelbase_bounds() == (p.l_f + p.l_r,) * 2


def test_api_validates_as_the_config_naming_the_argument():
    for kw, message in [
        ({"model": "st", "beta_r_deg": 3.0}, 'beta_r_deg: not with model = "st"'),
        ({"model": "st", "L": 0.3}, 'L: not with model = "st"'),
        # at their defaults too, as pfjax simulate --model st refuses --wheelbase 0.2 and --convention source
        ({"model": "st", "L": 0.2}, 'L: not with model = "st"'),
        ({"model": "std", "convention": "source"}, 'convention: not with model = "std"'),
        ({"model": "st", "beta_f_deg": 0.0}, 'beta_f_deg: not with model = "st"'),
        ({"mu": 0.5}, 'mu: not with model = "kinematic"'),
        ({"model": "st", "mu": -1.0}, "mu: must lie in (0, 10]"),
        ({"model": "st", "vehicle_params": "truck"}, "vehicle_params: Input should be"),
    ]:
        with pytest.raises(InputError) as e:
            pfjax.scenarios("sine", n=2, **kw)
        assert str(e.value).startswith(message), (kw, str(e.value))


def test_api_and_study_simulate_the_st_model_with_its_slip():
    runs = pfjax.scenarios("sine", n=3, model="st", mu=[0.3, 0.6, 1.0], key=1)
    sim = pfjax.simulate(runs, "stanley", config={"horizon": 2.0})
    t = sim.table
    assert list(t["mu"]) == [0.3, 0.6, 1.0]
    slip = t["max_abs_beta_f_deg"].to_numpy()
    assert np.all(slip > 0) and slip[0] > slip[1] > slip[2]  # less friction, more slip
    assert (t["L"] == 0.2).all()  # the robot set's wheelbase


def test_small_st_study_writes_friction_and_slip_columns(tmp_path):
    res = pfjax.run_study(
        {
            **BASE,
            "vehicle": {"model": "st", "mu": {"dist": "uniform", "low": 0.3, "high": 1.0}},
            "margin": {"enabled": False},
            "sim": {"horizon": 2.0, "steady_window": 1.0},
            "success": {"from_s": 1.0},
            "f64_check_runs": 0,
        },
        tmp_path / "out",
        report=False,
    )
    runs = res.runs
    assert {"mu", "max_abs_beta_r_deg", "max_abs_beta_f_deg", "mean_abs_beta_deg"} <= set(runs.columns)
    assert runs["mu"].between(0.3, 1.0).all() and (runs["status"] == "ok").all()
    q = res.summary["controllers"]["stanley"]["quantiles"]
    assert q["max_abs_beta_f_deg"]["mean"] == pytest.approx(runs["max_abs_beta_f_deg"].mean())


def _main(*argv):
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main(list(argv))
        except SystemExit as e:
            code = e.code
    return code, out.getvalue(), err.getvalue()


def test_cli_simulate_model_st():
    code, out, _ = _main("simulate", "--model", "st", "--path", "line", "--controller", "stanley", "--horizon", "2")
    assert code in (0, None)
    code, out, _ = _main(
        "simulate",
        "--model",
        "st",
        "--mu",
        "0.4",
        "--path",
        "line",
        "--controller",
        "stanley",
        "--horizon",
        "2",
        "--json",
    )
    r = json.loads(out)
    assert r["model"] == "st" and r["mu"] == 0.4 and r["metrics"]["status"] == "ok"
    assert r["slip"]["max_abs_beta_f_deg"] > 0
    for argv, flag in [
        (["--model", "st", "--beta-r-deg", "3"], "--beta-r-deg"),
        (["--model", "st", "--wheelbase", "0.3"], "--wheelbase"),
        (["--mu", "0.5"], "--mu"),
        (["--mu", "0"], "--mu"),  # a given 0 is given (not taken for "not given")
        (["--k-v", "0"], "--k-v"),
        (["--model", "st", "--beta-r-deg", "0"], "--beta-r-deg"),
        (["--model", "st", "--wheelbase", "0"], "--wheelbase"),
        (["--model", "st", "--mu", "-1"], "--mu"),
        (["--model", "st", "--tau-delta", "0"], "--tau-delta"),
        (["--model", "st", "--mu", "10", "--dt", "0.005"], "--dt"),
    ]:
        code, _, err = _main("simulate", "--path", "line", "--controller", "stanley", *argv)
        assert code == 2 and err.strip().splitlines()[-1].startswith(f"pfjax simulate: error: {flag}: "), err


def test_cli_simulate_chooses_a_stable_step_and_records_arguments_that_run_again():
    """Without --dt the dynamic models take the largest stable step of the 1-2-5 series (STD at
    1 m/s: 0.0002 s, where 0.005 s would be refused); the recorded arguments, given back as flags,
    give the same run: no kinematic flag the dynamic models refuse, the chosen step filled in."""
    code, out, err = _main(
        "simulate", "--model", "std", "--path", "line", "--controller", "stanley", "--horizon", "0.5", "--json"
    )
    assert code in (0, None), err
    r = json.loads(out)
    assert r["dt"] == 0.0002 and r["metrics"]["status"] == "ok"
    given = r["arguments"]
    assert given["dt"] == 0.0002 and given["wheelbase"] is None and given["beta_r_deg"] is None
    assert given["x0"] == [r["x0"]["x"], r["x0"]["y"], r["x0"]["theta_deg"]] and given["gains"] == r["gains"]

    def flag(k, v):  # a recorded argument as the flag it came from (--gains as name=value pairs, --x0 its three)
        if isinstance(v, dict):
            v = ",".join(f"{n}={x!r}" for n, x in v.items())
        return [f"--{k.replace('_', '-')}", *map(str, v)] if isinstance(v, list) else [f"--{k.replace('_', '-')}={v}"]

    flags = [f for k, v in given.items() if v not in (None, False) and k != "continuous" for f in flag(k, v)]
    code, again, err = _main("simulate", *flags, "--json")
    assert code in (0, None), err
    assert json.loads(again)["metrics"] == r["metrics"]
    assert json.loads(again)["config_sha256"] == r["config_sha256"]


@pytest.mark.parametrize("model", ["st", "std"])
def test_stable_step_is_the_largest_of_the_series_within_the_bound(model):
    from pfjax.models import single_track as st

    names = st.PARAMETER_SETS if model == "st" else st.COMMONROAD_DRIFT_VEHICLES
    series = [m * 10.0**-k for k in range(3, 8) for m in (5, 2, 1)]
    for name in names:
        p = st.model_parameter_set(model, name)
        for v in (0.5, 1.0, 10.0, 20.0):
            bound = st.max_stable_step(p, v, 0.05, 5.0)
            step = st.stable_step(p, v, 0.05, 5.0)
            assert step == pytest.approx(max(s for s in series if s <= bound), rel=1e-12)
            st.check_step("dt", step, p, v, 0.05, 5.0)


def test_api_checks_the_simulation_step_against_the_tyre_modes():
    """A step given is checked; none given, the largest stable one of the series is taken for the
    runs' worst case, as pfjax simulate --model st takes it without --dt."""
    runs = pfjax.scenarios("line", n=2, model="st", mu=10.0)  # the step is simulate's
    with pytest.raises(InputError, match=r"^config\.dt: the ST model at mu = 10 "):
        pfjax.simulate(runs, "stanley", config={"horizon": 1.0, "dt": 0.005})
    r = pfjax.simulate(runs, "stanley", config={"horizon": 1.0})
    assert (r.table["status"] == "ok").all()
    # the step taken is the config's from then on: a horizon of no whole number of it is named so
    with pytest.raises(InputError, match=r"^config\.horizon: "):
        pfjax.simulate(runs, "stanley", config={"horizon": 1.005})
    code, out, _ = _main(
        "simulate",
        "--model",
        "st",
        "--mu",
        "10",
        "--path",
        "line",
        "--controller",
        "stanley",
        "--horizon",
        "1",
        "--json",
    )
    assert code in (0, None) and json.loads(out)["arguments"]["dt"] == 0.002


def test_a_dumped_config_loads_again_under_either_model():
    """A study's summary holds its whole config, every key at its value or default: it loads again."""
    for vehicle, top in (({}, {}), ({"model": "st", "mu": 0.5}, {"margin": {"enabled": False}})):
        spec = _spec(vehicle, **top)
        assert load_study(data=spec.model_dump(mode="json"))[0] == spec


def test_kinematic_vs_dynamic_toml_documents_the_schema_defaults():
    """studies/kinematic_vs_dynamic.toml lists the schema's defaults: loading it changes nothing."""
    from pathlib import Path

    from pfjax.dynamic_study.config import load

    toml = Path(__file__).resolve().parents[1] / "studies" / "kinematic_vs_dynamic.toml"
    assert load(toml) == load()
    assert load(toml).model_dump() == load().model_dump()


def test_a_speed_above_the_parameter_sets_top_speed_is_refused_everywhere():
    """CommonRoad's acceleration constraint only stops speeding up past v_max: a run started above it
    stays there. Refused by the study config, pfjax.scenarios and pfjax simulate alike."""
    with pytest.raises(ConfigError, match=r"^vehicle\.speed: must be at most the parameter set's top speed, 15\.57"):
        _spec({"model": "st", "speed": {"dist": "uniform", "low": 1.0, "high": 20.0}}, margin={"enabled": False})
    with pytest.raises(InputError, match=r"^speed: must be at most the parameter set's top speed"):
        pfjax.scenarios("sine", n=2, model="st", speed=20.0)
    code, _, err = _main("simulate", "--model", "st", "--path", "sine", "--controller", "stanley", "--speed", "20")
    assert code == 2 and err.strip().splitlines()[-1].startswith("pfjax simulate: error: --speed: must be at most")
    assert pfjax.scenarios("sine", n=2, model="std", speed=20.0).table["speed"].tolist() == [20.0, 20.0]  # vehicle2
