"""Property-based fuzzing of every input edge (hypothesis): study configs generated from the
schema with one or more hostile values, ``--set`` overrides with malformed keys and values,
argument lists of the subcommands with out-of-range flags, and obstacle-map files.

Properties, for every generated input:

- the library raises nothing but its one-line :class:`~pfjax.errors.InputError` (no traceback
  from pydantic, NumPy or the TOML parser);
- what validation accepts satisfies the schema's invariants (every number finite and within
  1e12, seeds below 2**63, slip below 90 deg over the support);
- through the command line entry point, in-process: exit code 2, exactly one line on stderr
  starting ``pfjax <command>: error: <key or flag>:``, nothing on stdout, and the working
  directory byte-identical to before.

The default profile runs a few hundred examples (CI); ``PFJAX_FUZZ_EXAMPLES=5000`` runs more by hand:

    PFJAX_FUZZ_EXAMPLES=5000 .venv/bin/python -m pytest tests/test_fuzz.py -p no:cacheprovider
"""

import contextlib
import io
import json
import math
import os
import re
from pathlib import Path

import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from pfjax.cli import main
from pfjax.errors import MAX_MAGNITUDE, MAX_SEED, InputError
from pfjax.montecarlo.config import StudySpec, load_study
from pfjax.parking.maps import parse_map

EXAMPLES = int(os.environ.get("PFJAX_FUZZ_EXAMPLES", "0")) or None
FUZZ = settings(
    max_examples=EXAMPLES or 60,
    deadline=None,
    derandomize=EXAMPLES is None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)

BASE = {
    "name": "fz",
    "n_runs": 4,
    "seed": 1,
    "chunk_size": 4,
    "sim": {"horizon": 2.0, "steady_window": 1.0},
    "success": {"from_s": 1.0},
    "margin": {"enabled": False},
    "paths": [{"kind": "line"}],
    "controllers": [{"name": "st", "type": "stanley"}],
}

#: Values no numeric field should take, and some that only some fields reject.
HOSTILE = [
    math.nan,
    math.inf,
    -math.inf,
    1e308,
    -1e308,
    1e-300,
    -1e-300,
    2**63,
    -(2**63),
    10**400,
    -(10**400),
    True,
    False,
    "1",
    "",
    [],
    {},
    [1.0],
    {"dist": "uniform"},
    0,
    -1,
    0.0,
    1e13,
]
#: Dotted keys of the schema's scalar fields (and list items), with the sections they live in.
KEYS = [
    "name",
    "n_runs",
    "seed",
    "chunk_size",
    "dtype",
    "f64_check_runs",
    "sim.dt",
    "sim.horizon",
    "sim.control_every",
    "sim.d_fail",
    "sim.steady_window",
    "sim.settle_band",
    "success.band",
    "success.from_s",
    "vehicle.speed",
    "vehicle.L",
    "vehicle.delta_max_deg",
    "vehicle.delta_rate_max_deg",
    "vehicle.convention",
    "slip.kind",
    "slip.beta_r_deg",
    "slip.beta_f_deg",
    "slip.step_time_s",
    "slip.step_r_deg",
    "slip.amp_r_deg",
    "slip.freq_hz",
    "slip.ou_sigma_deg",
    "slip.ou_tau_s",
    "slip.seq_dt",
    "initial.start_along_m",
    "initial.lateral_offset",
    "initial.heading_error_deg",
    "noise.sigma_d",
    "noise.sigma_theta_e_deg",
    "margin.enabled",
    "margin.amplitudes_deg",
    "margin.n_per_amplitude",
    "margin.eps",
    "margin.axes",
    "falsifier.enabled",
    "falsifier.slip_bound_deg",
    "falsifier.f_max_hz",
    "falsifier.steps",
    "falsifier.n_restarts",
    "paths[0].kind",
    "paths[0].radius",
    "paths[0].length",
    "paths[0].n_waypoints",
    "paths[0].points",
    "controllers[0].name",
    "controllers[0].type",
    "controllers[0].K",
    "controllers[0].gains",
    "controllers[0].alpha",
]


def _set(data: dict, key: str, value) -> None:
    node = data
    parts = key.split(".")
    for p in parts[:-1]:
        m = re.match(r"(\w+)\[(\d+)\]$", p)
        node = node[m.group(1)][int(m.group(2))] if m else node.setdefault(p, {})
    m = re.match(r"(\w+)\[(\d+)\]$", parts[-1])
    if m:
        node[m.group(1)][int(m.group(2))] = value
    else:
        node[parts[-1]] = value


def _numbers(obj):
    """Every number in a validated config dump."""
    if isinstance(obj, dict):
        for v in obj.values():
            yield from _numbers(v)
    elif isinstance(obj, list):
        for v in obj:
            yield from _numbers(v)
    elif isinstance(obj, (int, float)) and not isinstance(obj, bool):
        yield obj


def _check_invariants(spec: StudySpec) -> None:
    for x in _numbers(spec.model_dump(mode="json")):
        assert math.isfinite(x) and (abs(x) <= MAX_MAGNITUDE or (isinstance(x, int) and 0 <= x <= MAX_SEED)), x
    for axis in ("r", "f"):
        lo, hi = getattr(spec.slip, f"beta_{axis}_deg").bounds()
        assert max(abs(lo), abs(hi)) < 90


def _toml(value) -> str:
    """``value`` as the right-hand side of a TOML ``key = value`` (what --set parses)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return (
            "nan"
            if math.isnan(value)
            else ("inf" if value == math.inf else "-inf" if value == -math.inf else repr(value))
        )
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, list):
        return "[" + ", ".join(_toml(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{k} = {_toml(v)}" for k, v in value.items()) + "}"
    return str(value)


# ----------------------------------------------------------------------------- library level


@FUZZ
@given(st.lists(st.tuples(st.sampled_from(KEYS), st.sampled_from(HOSTILE)), min_size=1, max_size=3))
def test_schema_raises_only_input_errors_and_accepts_only_sane_configs(changes):
    data = json.loads(json.dumps(BASE))
    for key, value in changes:
        _set(data, key, value)
    try:
        spec, _ = load_study(data=data)
    except InputError as e:
        text = str(e)
        assert "\n" not in text and re.match(r"^[\w.\[\]-]+: ", text), text
        return
    _check_invariants(spec)


KEY_TEXT = st.one_of(
    st.sampled_from(KEYS),
    st.text(alphabet="abc_[]0.-= \t", min_size=0, max_size=12),
    st.sampled_from(
        [
            "controllers[abc].name",
            "controllers[].name",
            "paths[9].kind",
            ".",
            "a..b",
            "[0]",
            "controllers[0]]",
            "sim.",
            "n_runs[0]",
            "controllers[-99].name",
        ]
    ),
)
VALUE_TEXT = st.one_of(
    st.sampled_from([_toml(v) for v in HOSTILE if not (isinstance(v, int) and abs(v) > 2**64)]),
    st.text(max_size=12),
    st.sampled_from(["{", "[1,", "'", "1e999", "0x", "{dist='normal'}"]),
)


@FUZZ
@given(st.lists(st.tuples(KEY_TEXT, VALUE_TEXT), min_size=1, max_size=3))
def test_set_overrides_raise_only_input_errors(pairs):
    try:
        spec, _ = load_study(data=json.loads(json.dumps(BASE)), overrides=[f"{k}={v}" for k, v in pairs])
    except InputError as e:
        assert "\n" not in str(e), str(e)
        return
    _check_invariants(spec)


# ----------------------------------------------------------------------------- the command line


def _snapshot(root: Path) -> dict:
    return {str(p.relative_to(root)): (None if p.is_dir() else p.read_bytes()) for p in sorted(root.rglob("*"))}


@contextlib.contextmanager
def _workdir(path: Path):
    old = os.getcwd()
    os.chdir(path)
    try:
        yield
    finally:
        os.chdir(old)


def _refused(argv: list[str], root: Path, flags=None) -> None:
    """``pfjax <argv>`` in-process: exit 2, one line naming a key or flag, nothing written."""
    before = _snapshot(root)
    out, err = io.StringIO(), io.StringIO()
    with _workdir(root), contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main(argv)
        except SystemExit as e:  # argparse's own errors (a choice, a type)
            code = e.code
    lines = err.getvalue().strip().splitlines()
    assert code == 2, (argv, err.getvalue()[-2000:])
    assert out.getvalue() == "" and len(lines) == 1 and "Traceback" not in err.getvalue(), (argv, err.getvalue())
    m = re.match(rf"^pfjax {argv[0]}: error: (\S+?):? ", lines[0])
    assert m, lines[0]
    if flags is not None and not lines[0].startswith(f"pfjax {argv[0]}: error: argument"):
        named = m.group(1)
        assert any(named.startswith(f) for f in flags) or any(f in lines[0] for f in flags), (flags, lines[0])
    assert _snapshot(root) == before, argv


@pytest.fixture(scope="module")
def root(tmp_path_factory):
    r = tmp_path_factory.mktemp("fuzz")
    (r / "s.toml").write_text(
        "\n".join(f"{k} = {_toml(v)}" for k, v in BASE.items() if not isinstance(v, (dict, list)))
        + "\n[sim]\nhorizon = 2.0\nsteady_window = 1.0\n[success]\nfrom_s = 1.0\n[margin]\n"
        'enabled = false\n[[paths]]\nkind = "line"\n[[controllers]]\nname = "st"\n'
        'type = "stanley"\n'
    )
    (r / "keep").mkdir()
    (r / "keep" / "thesis.tex").write_text("data")
    (r / "a_file").write_text("x")
    return r


@FUZZ
@given(
    st.lists(st.tuples(st.sampled_from(KEYS), st.sampled_from(HOSTILE)), min_size=1, max_size=2),
    st.sampled_from([None, "keep", ".", "..", "a_file/sub", "new"]),
)
def test_cli_study_refuses_bad_configs_and_outputs(root, changes, out):
    data = json.loads(json.dumps(BASE))
    for key, value in changes:
        _set(data, key, value)
    sets = [f"{k}={_toml(v)}" for k, v in changes if not (isinstance(v, int) and abs(v) > 2**64)]
    try:
        load_study(root / "s.toml", sets)
        bad_config = False
    except InputError:
        bad_config = True
    assume(bad_config or out in ("keep", ".", "..", "a_file/sub"))
    argv = ["study", "s.toml", *[a for s in sets for a in ("--set", s)], "--no-report", "--quiet"]
    _refused(argv + ([] if out is None else ["--out", out]), root)


#: Per subcommand: the flags and values none of which may be accepted (each example uses one or
#: more of them, with otherwise valid arguments).
BAD_FLAGS = {
    "simulate": {
        "--speed": ["0", "-1", "nan", "inf", "1e308"],
        "--wheelbase": ["0", "-0.2", "nan"],
        "--beta-r-deg": ["90", "-95", "nan", "1e400"],
        "--beta-f-deg": ["91", "inf"],
        "--delta-max-deg": ["0", "90", "-5"],
        "--horizon": ["0", "-1", "inf", "1e308"],
        "--dt": ["0", "-0.1", "1e-300", "nan"],
        "--control-every": ["0", "-3"],
        "--gains": ["", ",", "1,2", "kp_d=1,kp_d=2", "nan,1,1,1,1", "x=1", "1,kp_d=2", "1e999,0,0,0,0"],
        "--x0": [["0", "nan", "0"], ["inf", "0", "0"], ["1e308", "0", "0"], ["0", "0", "1e13"]],
    },  # THETA in deg
    "synth": {
        "--speed": ["0", "nan"],
        "--wheelbase": ["-1", "inf"],
        "--alpha": ["-1", "nan"],
        "--beta": ["-2"],
        "--disk": [["0", "-1"], ["nan", "1"]],
        "--sector-deg": ["0", "95", "nan"],
        "--max-real": ["inf"],
    },
    "tune": {
        "--population": ["1", "0", "100000000"],
        "--generations": ["-1"],
        "--steps": ["0"],
        "--starts": ["0"],
        "--lr": ["0", "nan", "-1"],
        "--level": ["0", "1", "2"],
        "--effort": ["-1", "inf"],
        "--n-runs": ["0"],
        "--seed": ["-1", "9223372036854775808"],
        "--horizon": ["0", "inf"],
        "--dt": ["0", "1e-300"],
        "--cost": ["mse"],
        "--aggregate": ["max"],
    },
    "bench": {"--sizes": ["0", "-5", ",", "1e6", "100000000000"], "--seed": ["-1"]},
    "parking": {
        "--k1": ["0", "nan"],
        "--speed": ["-1", "inf"],
        "--scan-period": ["0", "100"],
        "--horizon": ["0"],
        "--front": ["0", "0.6", "nan"],
        "--x0": [["0", "0", "95"], ["0", "0", "nan"], ["1e308", "0", "0"]],
        "--alpha-schedule": ["", "a", "nan"],
    },
    "track": {
        "--p": ["0", "nan"],
        "--l": ["0"],
        "--gamma-max-deg": ["0", "90"],
        "--speed": ["0", "-1"],
        "--k": ["0"],
        "--dt": ["0", "inf"],
        "--horizon": ["-1"],
        "--stop-and-go": ["2", "-1"],
    },
}
REQUIRED = {
    "simulate": ["--path", "line", "--controller", "pi"],
    "synth": [],
    "tune": ["--method", "ga", "--controller", "pi"],
    "bench": ["--quick", "--out", "b"],
    "parking": [],
    "track": [],
}


@st.composite
def bad_argv(draw):
    command = draw(st.sampled_from(sorted(BAD_FLAGS)))
    table = BAD_FLAGS[command]
    flags = draw(st.lists(st.sampled_from(sorted(table)), min_size=1, max_size=2, unique=True))
    argv = [command, *REQUIRED[command]]
    for f in flags:
        value = draw(st.sampled_from(table[f]))
        argv += [f, *value] if isinstance(value, list) else [f"{f}={value}"]
    return argv, flags


@FUZZ
@given(bad_argv())
def test_cli_subcommands_refuse_out_of_range_flags(root, case):
    argv, flags = case
    _refused(argv, root, flags)


# ----------------------------------------------------------------------------- map files


POINT = st.one_of(st.floats(-3, 3, allow_nan=False), st.sampled_from([math.nan, math.inf, 1e308, 2**70]))
POLY = st.lists(st.lists(POINT, min_size=2, max_size=2), min_size=0, max_size=7)


@st.composite
def map_docs(draw):
    obstacles = []
    for i in range(draw(st.integers(0, 3))):
        verts = draw(POLY)
        if verts and draw(st.booleans()):
            verts = verts + [verts[0]]  # closed, as a valid map has it
        ob = {"vertices": verts}
        if draw(st.booleans()):
            ob["name"] = draw(st.sampled_from(["kerb", "kerb", "wall", "obstacle_0", "", 3]))
        if draw(st.integers(0, 9)) == 0:
            ob["colour"] = "red"
        obstacles.append(ob)
    return {"obstacles": obstacles} if draw(st.integers(0, 9)) else {"obstacles": obstacles, "extra": 1}


@FUZZ
@given(map_docs(), st.sampled_from(["json", "toml", "latin1"]))
def test_map_files_are_validated_or_refused_in_one_line(root, doc, fmt):
    def toml_doc(d):
        rows = []
        for o in d["obstacles"]:
            rows.append("[[obstacles]]")
            rows += [f"{k} = {_toml(v)}" for k, v in o.items()]
        return "\n".join([f"{k} = {_toml(v)}" for k, v in d.items() if k != "obstacles"] + rows) + "\n"

    if fmt == "json":
        data, name = json.dumps(doc).encode(), "m.json"
    elif fmt == "toml":
        data, name = toml_doc(doc).encode(), "m.toml"
    else:
        data, name = toml_doc(doc).encode() + b"# caf\xe9\n", "m.toml"
    try:
        parse_map(json.loads(json.dumps(doc)), "m")
        valid = fmt != "latin1"
    except InputError as e:
        assert "\n" not in str(e)
        valid = False
    except ValueError:  # NaN/inf are not JSON; the TOML writer above spells them
        valid = False
    assume(not valid)
    path = root / "maps" / name
    path.parent.mkdir(exist_ok=True)
    path.write_bytes(data)
    try:
        _refused(["parking", "--map", str(path), "--x0", "0", "2", "0"], root, ["--map", "--x0"])
    finally:
        path.unlink()
