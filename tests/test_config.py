"""pfjax.config: a schema of the family read from defaults <- TOML file <- presets <- --set overrides, one-line errors naming the key, hashing;
and the study script's handling of bad configuration (exit 2, one line, nothing written)."""

from __future__ import annotations

import copy
import hashlib
import json
import math
import tomllib
from pathlib import Path
from types import SimpleNamespace
from typing import Literal

import pytest
from pydantic import Field

from pfjax.config import ConfigError, ConfigModel, Real, load_model, parse_override
from pfjax.provenance import config_hash

ROOT = Path(__file__).resolve().parents[1]
STUDY = ROOT / "studies" / "paper_reproduction.py"


class Model(ConfigModel):
    v: Real = 1.0
    L: Real = Field(0.2, gt=0)
    convention: Literal["source", "lenain"] = "source"
    n: int = 3


class Source(ConfigModel):
    K: list[Real] = Field([-2.7381, -2.0772], min_length=2, max_length=2)
    flags: list[bool] = Field([True, False], min_length=2, max_length=2)


class Inner(ConfigModel):
    x: Real = 0.5
    label: str = "a"


class Deep(ConfigModel):
    inner: Inner = Inner()


class Demo(ConfigModel):
    """A small schema of the family: nested tables, lists of fixed length, literals, bounds."""

    name: str = "demo"
    seed: int = 0
    trackers: bool = True
    model: Model = Model()
    source: Source = Source()
    deep: Deep = Deep()


DEFAULTS = {
    "name": "demo",
    "seed": 0,
    "trackers": True,
    "model": {"v": 1.0, "L": 0.2, "convention": "source", "n": 3},
    "source": {"K": [-2.7381, -2.0772], "flags": [True, False]},
    "deep": {"inner": {"x": 0.5, "label": "a"}},
}


def load(path=None, overrides=(), **kw) -> dict:
    return load_model(Demo, path, overrides, **kw)[0].model_dump()


def write(tmp_path, text, name="cfg.toml"):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_defaults_and_no_aliasing_of_the_raw_data():
    assert load() == DEFAULTS
    data = copy.deepcopy(DEFAULTS)
    cfg, raw = load_model(Demo, data=data, overrides=["model.v=3"])
    assert cfg.model.v == 3.0 and data == DEFAULTS and raw is not data  # the caller's dict is untouched


def test_file_then_presets_then_overrides(tmp_path):
    p = write(tmp_path, 'name = "from-file"\n[model]\nv = 2\nn = 7\n[deep.inner]\nx = 1.5\n[source]\nK = [-1, -2.5]\n')
    cfg = load(
        p,
        [
            "model.v=3.5",
            "deep.inner.label=b",
            "source.flags=[false, true]",
            "trackers=false",
            "model.convention = lenain",
        ],
        presets=[{"model": {"L": 0.3, "v": 9.0}}],
    )
    assert cfg["name"] == "from-file"
    # the preset wins over the file, --set over the preset
    assert cfg["model"] == {"v": 3.5, "L": 0.3, "convention": "lenain", "n": 7}
    assert cfg["deep"]["inner"] == {"x": 1.5, "label": "b"}
    assert cfg["source"] == {"K": [-1.0, -2.5], "flags": [False, True]}
    assert cfg["trackers"] is False
    # ints accepted where floats are expected, and stored as floats
    assert type(cfg["source"]["K"][0]) is float
    assert type(load(None, ["model.v=2"])["model"]["v"]) is float
    assert type(cfg["model"]["n"]) is int


def test_override_values_are_toml():
    assert parse_override("a.b.c=3") == {"a": {"b": {"c": 3}}}
    assert parse_override("x=1e-3") == {"x": 0.001}
    assert parse_override("x=[1, 2.5]") == {"x": [1, 2.5]}
    assert parse_override("x=true") == {"x": True}
    assert parse_override('x="quoted"') == {"x": "quoted"}
    assert parse_override("x=bare word") == {"x": "bare word"}  # not TOML: taken as a string
    assert parse_override(" x = 2 ") == {"x": 2}


def message(excinfo) -> str:
    msg = str(excinfo.value)
    assert "\n" not in msg and msg.strip() == msg and msg
    return msg


@pytest.mark.parametrize(
    "override, key, extra",
    [
        ("model.vv=1", "model.vv", "did you mean 'model.v'"),
        ("modle.v=1", "modle", "did you mean 'model'"),
        ("deep.inner.lable=x", "deep.inner.lable", "did you mean 'deep.inner.label'"),
        ("zzz=1", "zzz", "unknown key"),
        ("model.v=true", "model.v", "valid number"),  # a bool is not a number
        ("model.v=fast", "model.v", "valid number"),
        ("model.n=2.5", "model.n", "valid integer"),
        ("model.convention=3", "model.convention", "'source' or 'lenain'"),
        ("trackers=1", "trackers", "valid boolean"),
        ("source.K=[1.0]", "source.K", "at least 2 items"),
        ("source.K=[1.0, 2.0, 3.0]", "source.K", "at most 2 items"),
        ("source.K=3.0", "source.K", "valid list"),
        ('source.K=[1.0, "a"]', "source.K[1]", "valid number"),
        ("model.v=nan", "model.v", "finite"),
        ("model.L=-inf", "model.L", "must be > 0"),
        ("model=3", "model", "valid dictionary"),
        ("model.v.x=1", "model.v", "valid number"),
        ("novalue", "--set", "key=value"),
        ("=3", "--set", "empty key"),
    ],
)
def test_override_errors_name_the_key(override, key, extra):
    with pytest.raises(ConfigError) as e:
        load(None, [override])
    msg = message(e)
    assert msg.startswith(key + ":") or msg.startswith(key + " "), msg
    assert extra in msg, msg


@pytest.mark.parametrize(
    "text, key, extra",
    [
        ("[model]\nvv = 1.0\n", "model.vv", "did you mean 'model.v'"),
        ("[model]\nv = 'fast'\n", "model.v", "valid number"),
        ("[model]\nv = nan\n", "model.v", "finite"),
        ("[source]\nK = [1.0]\n", "source.K", "at least 2 items"),
        ("[deep]\ninner = 2\n", "deep.inner", "valid dictionary"),
        ("seed = 1.5\n", "seed", "valid integer"),
    ],
)
def test_file_errors_name_the_key(tmp_path, text, key, extra):
    with pytest.raises(ConfigError) as e:
        load(write(tmp_path, text))
    msg = message(e)
    assert msg.startswith(key + ":"), msg
    assert extra in msg, msg


def test_missing_file_and_invalid_toml(tmp_path):
    with pytest.raises(ConfigError) as e:
        load(tmp_path / "nope.toml")
    assert "not found" in message(e) and "nope.toml" in str(e.value)
    bad = write(tmp_path, "[model\nv = 1\n", "bad.toml")
    with pytest.raises(ConfigError) as e:
        load(bad)
    assert "invalid TOML" in message(e) and "bad.toml" in str(e.value)


def test_config_error_is_a_value_error():
    assert issubclass(ConfigError, ValueError)


def test_config_hash():
    cfg = load()
    h = config_hash(cfg)
    assert len(h) == 64 and int(h, 16) >= 0
    # the documented definition: SHA-256 of the canonical (sorted, compact) JSON
    assert h == hashlib.sha256(json.dumps(cfg, sort_keys=True, separators=(",", ":")).encode()).hexdigest()
    # stable under key order at every level
    rev = lambda d: {k: rev(v) for k, v in reversed(list(d.items()))} if isinstance(d, dict) else d
    assert list(rev(cfg)) != list(cfg) and config_hash(rev(cfg)) == h
    # stable under how a float was written (an int is stored as a float)
    assert config_hash(load(None, ["model.v=1"])) == h
    # changes when any value changes, however deep
    for o in ["model.v=1.0000001", "deep.inner.label=b", "source.K=[-2.7381, -2.0773]", "trackers=false", "seed=1"]:
        assert config_hash(load(None, [o])) != h, o


# ------------------------------------------------------------------ the study script's CLI


def run_study(*args) -> SimpleNamespace:
    """The study script's ``main`` (its return value is the script's exit code) in this process, its
    stdout and stderr captured. The script as a process: tests/test_paper_config_audit.py."""
    import contextlib
    import importlib.util
    import io

    spec = importlib.util.spec_from_file_location("paper_reproduction_script", STUDY)
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = script.main(list(args))
        except SystemExit as e:  # argparse's own errors
            code = e.code
    return SimpleNamespace(returncode=code, stdout=out.getvalue(), stderr=err.getvalue())


STUDY_BAD = {  # --set override -> the key the message must name
    "model.v=-1": "model.v",
    "sim.dtt=0.1": "sim.dtt",
    "sim.horizon=nan": "sim.horizon",
    "sim.horizon=5": "sim.horizon",  # the sine-error analysis needs samples after t = 5 s
}


@pytest.fixture(scope="module")
def study_errors(tmp_path_factory):
    """Each bad invocation in its own empty parent directory."""
    jobs = {o: tmp_path_factory.mktemp("bad") for o in STUDY_BAD}
    missing = tmp_path_factory.mktemp("missing")
    jobs["<missing config>"] = missing
    argv = {o: ["--set", o, "--out", str(d / "out")] for o, d in jobs.items() if o in STUDY_BAD}
    argv["<missing config>"] = ["--config", str(missing / "missing.toml"), "--out", str(missing / "out")]
    res = {o: run_study(*a) for o, a in argv.items()}
    return {o: (res[o], jobs[o]) for o in jobs}


@pytest.mark.parametrize("override", list(STUDY_BAD))
def test_study_rejects_bad_config_and_writes_nothing(study_errors, override):
    r, parent = study_errors[override]
    assert r.returncode == 2, r.stderr
    lines = r.stderr.splitlines()
    assert len(lines) == 1, r.stderr
    assert STUDY_BAD[override] in lines[0] and "error" in lines[0]
    if override == "sim.dtt=0.1":
        assert "did you mean 'sim.dt'" in lines[0]
    assert r.stdout == ""
    assert list(parent.iterdir()) == []  # neither --out nor a temporary directory


def test_study_rejects_missing_config_file(study_errors):
    r, parent = study_errors["<missing config>"]
    assert r.returncode == 2 and len(r.stderr.splitlines()) == 1 and "missing.toml" in r.stderr
    assert r.stdout == "" and list(parent.iterdir()) == []


def test_study_toml_matches_schema_defaults():
    """studies/paper_reproduction.toml documents the schema's defaults: loading it changes nothing."""
    from pfjax.reproduce.paper_config import PaperStudy
    from pfjax.reproduce.paper_config import load as load_paper

    cfg = load_paper(ROOT / "studies" / "paper_reproduction.toml").model_dump(mode="json")
    assert config_hash(cfg) == config_hash(PaperStudy().model_dump(mode="json"))
    assert math.isclose(cfg["model"]["delta_max_deg"], 30.0)
    # and it lists every key ("these are the defaults")
    keys = lambda d, pre="": {
        k for n, v in d.items() for k in (keys(v, f"{pre}{n}.") if isinstance(v, dict) else [pre + n])
    }
    raw = tomllib.loads((ROOT / "studies" / "paper_reproduction.toml").read_text())
    assert keys(raw) == keys(PaperStudy().model_dump(mode="json"))


@pytest.mark.parametrize(
    "setting, key",
    [
        ("model.convention='other'", "model.convention"),
        ("model.beta_r_deg=90", "model.beta_r_deg"),
        ("stability.horizon=0.001", "stability.horizon"),  # below sim.dt (cross-field)
        ("sim.steady_window=30.0", "sim.steady_window"),  # longer than sim.horizon
        ("stability.n=1", "stability.n"),
        ("stability.n=100000", "stability.n"),  # the grid would not fit in memory
        ("ga.seeds=true", "ga.seeds"),  # strict: a boolean is not a count
    ],
)
def test_paper_config_errors_name_the_key(setting, key):
    from pfjax.reproduce.paper_config import load as load_paper

    with pytest.raises(ConfigError) as e:
        load_paper(None, [setting])
    msg = str(e.value)
    assert len(msg.splitlines()) == 1 and msg.startswith(key), msg


def test_paper_quick_preset_then_set():
    from pfjax.reproduce.paper_config import QUICK
    from pfjax.reproduce.paper_config import load as load_paper

    c = load_paper(None, ["stability.n=4"], quick=True)
    assert c.stability.n == 4 and c.sim.horizon == QUICK["sim"]["horizon"] and c.trackers is False


def test_a_study_file_with_a_byte_order_mark_loads(tmp_path):
    """Some editors start a UTF-8 file with a byte-order mark, which TOML parsers refuse
    ("Invalid statement" at line 1): it is dropped, and the file is read as without it."""
    from pfjax.montecarlo.config import load_study

    src = (Path(__file__).resolve().parents[1] / "studies" / "robustness_default.toml").read_bytes()
    bom = tmp_path / "bom.toml"
    bom.write_bytes(b"\xef\xbb\xbf" + src)
    assert (
        load_study(bom)[0] == load_study(Path(__file__).resolve().parents[1] / "studies" / "robustness_default.toml")[0]
    )


def test_the_nominal_value_of_every_distribution_kind():
    """A design controller is made at the nominal speed and wheelbase: a choice's is the mean of
    its values (it had none, and a study with an LMI controller and a choice of speeds crashed)."""
    from pfjax.montecarlo.dists import Dist, nominal

    cases = [
        ({"dist": "constant", "value": 1.5}, 1.5),
        ({"dist": "uniform", "low": 0.8, "high": 1.4}, 1.1),
        ({"dist": "normal", "mean": 0.3, "std": 0.1}, 0.3),
        ({"dist": "truncnormal", "mean": 1.0, "std": 0.2, "low": 0.7, "high": 1.4}, 1.0),
        ({"dist": "choice", "values": [0.8, 1.2, 1.6]}, 1.2),
    ]
    for table, want in cases:
        assert nominal(Dist.model_validate(table)) == pytest.approx(want), table


def test_an_unknown_gain_of_a_design_names_the_type_given():
    """A design (type lmi) is a state_feedback controller: its unknown gain names the type the
    config gave, then what it designs, not only the registry's name."""
    from pfjax.config import ConfigError
    from pfjax.montecarlo.config import load_study

    data = {
        "name": "g",
        "seed": 1,
        "n_runs": 10,
        "paths": [{"kind": "line"}],
        "controllers": [{"name": "m", "type": "lmi"}],
    }
    with pytest.raises(ConfigError, match=r"^controllers\[0\]\.gains\.k: unknown gain for controller 'lmi' \(a "):
        load_study(data=data, values={"controllers[0].gains.k": 3.0})


@pytest.mark.parametrize(
    ("value", "said"),
    [(-1.0, "must be > 0 (got -1.0)"), (0.0, "must be > 0 (got 0.0)"), (1e-300, "must be >= 1e-12 (got 1e-300)")],
)
def test_a_positive_setting_is_told_as_errors_number_tells_it(value, said):
    """A positive setting (``ge = MIN_POSITIVE``) given 0 or less is told "must be > 0", as
    :func:`pfjax.errors.number` tells it; a positive value below the smallest is told that bound."""
    from pfjax.config import ConfigError
    from pfjax.montecarlo.config import load_study

    data = {
        "name": "g",
        "seed": 1,
        "n_runs": 10,
        "paths": [{"kind": "line"}],
        "controllers": [{"name": "m", "type": "pi"}],
    }
    with pytest.raises(ConfigError, match=r"^sim\.dt: ") as e:
        load_study(data=data, values={"sim.dt": value})
    assert str(e.value) == f"sim.dt: {said}"
