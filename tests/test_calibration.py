"""pfjax.numerics.calibration and pfjax calibrate: CPU-dependent settings chosen by measurement."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from pfjax.bench import calibrate as C
from pfjax.numerics import calibration, compiler
from pfjax.sim import sharding


def _file(tmp_path, **over):
    data = dict(
        version=calibration.VERSION, cpu_key="x", vector_width=None, block_bytes={"float32": 2500, "float64": 10000}
    )
    data.update(over)
    p = tmp_path / "cal.json"
    p.write_text(json.dumps(data))
    return str(p)


def test_a_calibration_file_is_read_and_checked(tmp_path):
    calibration.load.cache_clear()
    cal = calibration.load(_file(tmp_path, vector_width=512))
    assert cal["vector_width"] == 512 and cal["block_bytes"]["float64"] == 10000
    calibration.load.cache_clear()
    cal = calibration.load(_file(tmp_path, sincos_sharing={"float32": "none", "float64": "real"}))
    assert cal["sincos_sharing"] == {"float32": "none", "float64": "real"}
    calibration.load.cache_clear()
    for bad in (
        dict(version=99),
        dict(vector_width=-1),
        dict(block_bytes={"float32": 8}),
        dict(block_bytes=3),
        dict(sincos_sharing={"float32": "fast", "float64": "real"}),
        dict(sincos_sharing={"float32": "real"}),
        dict(sincos_sharing="real"),
    ):
        calibration.load.cache_clear()
        with pytest.warns(UserWarning, match="calibration ignored"):
            assert calibration.load(_file(tmp_path, **bad)) is None
    calibration.load.cache_clear()
    (tmp_path / "cal.json").write_text("{not json")
    with pytest.warns(UserWarning, match="unreadable"):
        assert calibration.load(str(tmp_path / "cal.json")) is None
    calibration.load.cache_clear()


def test_the_settings_follow_the_calibration_and_the_environment_wins(tmp_path, monkeypatch):
    cal = json.loads(Path(_file(tmp_path, vector_width=256)).read_text())
    monkeypatch.setattr(calibration, "load", lambda path=None: cal)
    assert calibration.block_bytes(4) == 2500 and calibration.block_bytes(8) == 10000
    assert sharding.cpu_block_bytes(4) == 2500 and sharding.cpu_block_bytes(8) == 10000
    assert compiler.vector_width(environ={}) == 256
    assert compiler.vector_width(environ={"PFJAX_VECTOR_WIDTH": "0"}) is None  # the variable overrides
    monkeypatch.setattr(calibration, "load", lambda path=None: None)
    assert sharding.cpu_block_bytes(8) == sharding.block_bytes_rule()  # no calibration: the stated rule
    info = tmp_path / "cpuinfo"
    for vendor, want in (("GenuineIntel", 2500), ("AuthenticAMD", 5000), ("", 5000)):
        info.write_text(f"vendor_id\t: {vendor}\nflags\t: avx2\n\n")
        sharding.block_bytes_rule.cache_clear()  # read once per file
        assert sharding.block_bytes_rule(str(info)) == want
    sharding.block_bytes_rule.cache_clear()
    assert compiler.vector_width(environ={}) == (512 if compiler.has_avx512() else None)


def test_the_directory_and_the_cpu_key(tmp_path):
    assert calibration.directory({"PFJAX_CALIBRATION": "off"}) is None
    assert calibration.directory({"PFJAX_CALIBRATION_DIR": str(tmp_path)}) == tmp_path
    # one rule, whatever the compilation cache's PFJAX_CACHE_DIR says (never a sibling of that directory)
    assert calibration.directory({"PFJAX_CACHE_DIR": str(tmp_path / "xla")}) == (
        Path.home() / ".cache" / "pfjax" / "calibration"
    )
    assert calibration.directory({"XDG_CACHE_HOME": str(tmp_path), "PFJAX_CACHE_DIR": "/tmp/xla"}) == (
        tmp_path / "pfjax" / "calibration"
    )
    assert calibration.directory({"PFJAX_CALIBRATION_DIR": str(tmp_path / "c"), "XDG_CACHE_HOME": "/x"}) == (
        tmp_path / "c"
    )
    info = tmp_path / "cpuinfo"
    info.write_text(
        "vendor_id\t: GenuineIntel\ncpu family\t: 6\nmodel\t\t: 207\nmodel name\t: Xeon\nflags\t: avx2 avx512f\n\n"
    )
    key = calibration.cpu_key(str(info), jax_version="0.1")
    assert key.startswith("genuineintel-6-207-") and len(key.rsplit("-", 1)[1]) == 8
    assert calibration.cpu_key(str(info), jax_version="0.2") != key  # another JAX compiles other code


def test_the_choice_takes_each_precisions_best_block_at_the_best_width():
    rows = _candidates()  # every candidate agrees with the default settings
    got = C.choose(rows)  # 512: 200 * 45 = 9000 > default: 120 * 60 = 7200
    assert got == dict(
        vector_width=512,
        block_bytes={"float32": 2500, "float64": 5000},
        msteps_per_s={"float32": 200.0, "float64": 45.0},
    )
    rows[6]["msteps_per_s"] = rows[7]["msteps_per_s"] = 30.0  # now 200 * 30 = 6000 < 7200
    assert C.choose(rows)["vector_width"] is None


def test_a_small_calibration_measures_agrees_and_round_trips(tmp_path):
    result = C.calibrate(batch=100, horizon=0.05, rounds=1, blocks=(256, 2500), width_set=(None,))  # 100: padded blocks
    assert result["cpu_key"] == calibration.cpu_key() and result["vector_width"] is None
    assert len(result["config_sha256"]) == 64  # over what was measured
    assert {(r["dtype"], r["block_bytes"]) for r in result["rows"]} == {
        (d, b) for d in ("float32", "float64") for b in (256, 2500)
    }
    for r in result["rows"]:
        assert math.isfinite(r["msteps_per_s"]) and r["msteps_per_s"] > 0
        # blocks change the result only by rounding
        assert r["max_abs_iae_diff"] <= (1e-5 if r["dtype"] == "float32" else 1e-12) and r["agrees"] is True
    assert result["iae_tolerance"] == {"float32": 1e-4, "float64": 1e-10} and "failed" not in result
    # the second stage: every sharing of the sine-cosine pair at the chosen block, which changes no value
    assert sorted((r["dtype"], r["sincos_sharing"]) for r in result["sharing_rows"]) == sorted(
        (d, sh) for d in ("float32", "float64") for sh in C.SHARINGS
    )
    assert "none" not in C.SHARINGS  # it makes forward-mode gradients dearer
    for r in result["sharing_rows"]:
        assert r["block_bytes"] == result["block_bytes"][r["dtype"]] and r["agrees"] is True
        assert r["max_abs_iae_diff"] <= (1e-5 if r["dtype"] == "float32" else 1e-12)
    assert set(result["sincos_sharing"].values()) <= set(calibration.SHARINGS)
    assert result["sincos_sharing"] == C.choose_sharing(result["sharing_rows"])
    path = calibration.save(result, tmp_path / "c.json")
    calibration.load.cache_clear()
    try:
        assert calibration.load(str(path))["block_bytes"] == result["block_bytes"]
        assert calibration.load(str(path))["sincos_sharing"] == result["sincos_sharing"]
    finally:
        calibration.load.cache_clear()
    assert np.all([p.suffix == ".json" for p in tmp_path.iterdir()])  # written atomically, no temporary left


def test_pfjax_calibrate_refuses_where_it_could_keep_nothing_before_measuring(tmp_path, monkeypatch, capsys):
    """Calibrations off, or a calibration directory that is a file (or under one): exit 2 with one line
    naming the environment variable, before any measuring and with nothing created; --dry-run still runs."""
    from pfjax.cli import main
    from pfjax.errors import InputError

    afile = tmp_path / "afile"
    afile.write_text("the user's")
    for env, value, name in (
        ("PFJAX_CALIBRATION", "off", "PFJAX_CALIBRATION"),
        ("PFJAX_CALIBRATION_DIR", str(afile), "PFJAX_CALIBRATION_DIR"),
        ("PFJAX_CALIBRATION_DIR", str(afile / "sub"), "PFJAX_CALIBRATION_DIR"),
    ):
        environ = {env: value}
        with pytest.raises(InputError, match=f"^{name}: "):
            calibration.writable_directory(environ)
        monkeypatch.setenv(env, value)
        monkeypatch.setattr(C, "calibrate", lambda **kw: pytest.fail("measured before checking"))
        assert main(["calibrate", "--quick"]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith(f"pfjax calibrate: error: {name}: "), err
        monkeypatch.delenv(env)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["afile"] and afile.read_text() == "the user's"
    # a directory that is not there yet is made (pfjax's own), with nothing left in it
    new = tmp_path / "new" / "dir"
    assert calibration.writable_directory({"PFJAX_CALIBRATION_DIR": str(new)}) == new
    assert new.is_dir() and not any(new.iterdir())


def test_only_the_supported_vector_widths_are_read_and_a_bad_file_warns_in_one_line(tmp_path):
    """A width XLA cannot take (7), a boolean or a float is not a calibration; the warning is one line
    attributed to pfjax, not a line of pfjax's source."""
    import warnings

    for width in (None, *calibration.WIDTHS):
        calibration.load.cache_clear()
        assert calibration.load(_file(tmp_path, vector_width=width))["vector_width"] == width
    for bad in (dict(vector_width=7), dict(vector_width=True), dict(vector_width=512.0), dict(vector_width=0)):
        calibration.load.cache_clear()
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            assert calibration.load(_file(tmp_path, **bad)) is None, bad
        (w,) = caught
        text = warnings.formatwarning(w.message, w.category, w.filename, w.lineno, w.line)
        assert text.count("\n") == 1 and text.startswith("pfjax:0: UserWarning: "), text
        assert "calibration ignored" in text and "calibration.py" not in text
    calibration.load.cache_clear()
    assert not calibration._valid(dict(version=1, vector_width=None, block_bytes={"float32": True, "float64": 5000}))


def test_a_calibration_file_that_is_a_directory_is_refused_before_measuring(tmp_path, monkeypatch, capsys):
    """``<dir>/<cpu key>.json`` a directory: one line naming PFJAX_CALIBRATION_DIR, exit 2, before any
    measuring, nothing created; and :func:`save` leaves no temporary file when its write fails."""
    from pfjax.cli import main
    from pfjax.errors import InputError

    key = calibration.cpu_key()
    (tmp_path / f"{key}.json").mkdir()
    with pytest.raises(InputError) as e:
        calibration.writable_directory({"PFJAX_CALIBRATION_DIR": str(tmp_path)})
    assert str(e.value).startswith("PFJAX_CALIBRATION_DIR: ") and f"{key}.json" in str(e.value)
    assert calibration.writable_directory({"PFJAX_CALIBRATION_DIR": str(tmp_path)}, key="other") == tmp_path
    monkeypatch.delenv("PFJAX_CALIBRATION", raising=False)  # the tests' "off" (conftest)
    monkeypatch.setenv("PFJAX_CALIBRATION_DIR", str(tmp_path))
    monkeypatch.setattr(C, "calibrate", lambda **kw: pytest.fail("measured before checking"))
    assert main(["calibrate", "--quick"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("pfjax calibrate: error: PFJAX_CALIBRATION_DIR: "), err
    result = dict(
        version=calibration.VERSION, cpu_key=key, vector_width=None, block_bytes={"float32": 2500, "float64": 5000}
    )
    with pytest.raises(InputError, match="^PFJAX_CALIBRATION_DIR: "):
        calibration.save(result, tmp_path / f"{key}.json")
    assert [p.name for p in tmp_path.iterdir()] == [f"{key}.json"]  # no temporary file left
    assert not any((tmp_path / f"{key}.json").iterdir())


def _result(key: str) -> dict:
    return dict(
        version=calibration.VERSION, cpu_key=key, vector_width=None, block_bytes={"float32": 2500, "float64": 5000}
    )


def test_a_directory_where_nothing_can_be_written_is_refused_before_measuring(tmp_path, monkeypatch, capsys):
    """The check writes: a directory that cannot be made (under /proc, where permission bits say
    yes to root) or one where no file can be created is one line naming PFJAX_CALIBRATION_DIR, exit 2,
    before any measuring; a write that fails in :func:`save` is the same line, with no file left."""
    from pfjax.cli import main
    from pfjax.errors import InputError

    monkeypatch.delenv("PFJAX_CALIBRATION", raising=False)  # the tests' "off" (conftest)
    monkeypatch.setattr(C, "calibrate", lambda **kw: pytest.fail("measured before checking"))
    if Path("/proc/self").is_dir():
        monkeypatch.setenv("PFJAX_CALIBRATION_DIR", "/proc/pfjax-calibration")
        assert main(["calibrate", "--quick"]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith("pfjax calibrate: error: PFJAX_CALIBRATION_DIR: "), err
        with pytest.raises(InputError, match="^PFJAX_CALIBRATION_DIR: "):
            calibration.save(_result("k"), Path("/proc/pfjax-calibration/k.json"))

    def read_only(*a, **kw):  # a directory of another owner, or a read-only file system
        raise PermissionError(13, "Permission denied")

    monkeypatch.setenv("PFJAX_CALIBRATION_DIR", str(tmp_path))
    with monkeypatch.context() as m:
        m.setattr(calibration.tempfile, "mkstemp", read_only)
        assert main(["calibrate", "--quick"]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert err == [f"pfjax calibrate: error: PFJAX_CALIBRATION_DIR: {tmp_path} cannot be made and written "
                       "(Permission denied); set PFJAX_CALIBRATION_DIR to a writable directory"]  # fmt: skip
    assert not any(tmp_path.iterdir())  # the probe is removed

    key = calibration.cpu_key()
    monkeypatch.setattr(C, "calibrate", lambda **kw: _result(key))
    with monkeypatch.context() as m:  # the directory checked, then the write refused
        m.setattr(calibration.os, "replace", read_only)
        assert main(["calibrate", "--quick"]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith(f"pfjax calibrate: error: PFJAX_CALIBRATION_DIR: {tmp_path}"), err
    assert not any(tmp_path.iterdir())  # no temporary file left
    assert main(["calibrate", "--quick", "--json"]) == 0
    capsys.readouterr()
    calibration.load.cache_clear()
    assert [p.name for p in tmp_path.iterdir()] == [f"{key}.json"]
    assert json.loads((tmp_path / f"{key}.json").read_text()) == _result(key)


def test_a_file_that_is_not_a_pfjax_calibration_is_never_replaced(tmp_path, monkeypatch, capsys):
    """The user's file at ``<dir>/<cpu key>.json``: one line naming PFJAX_CALIBRATION_DIR and the
    file, exit 2, before measuring, the file untouched; a pfjax calibration there is replaced."""
    from pfjax.cli import main
    from pfjax.errors import InputError

    key = calibration.cpu_key()
    mine = tmp_path / f"{key}.json"
    monkeypatch.delenv("PFJAX_CALIBRATION", raising=False)  # the tests' "off" (conftest)
    monkeypatch.setenv("PFJAX_CALIBRATION_DIR", str(tmp_path))
    monkeypatch.setattr(C, "calibrate", lambda **kw: pytest.fail("measured before checking"))
    for text in ("my notes\n", '{"notes": 1}', json.dumps(dict(_result(key), cpu_key="another"), indent=None)[:-1]):
        mine.write_text(text)
        assert main(["calibrate", "--quick"]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith(f"pfjax calibrate: error: PFJAX_CALIBRATION_DIR: {mine} "), err
        with pytest.raises(InputError, match="^PFJAX_CALIBRATION_DIR: .* not a pfjax calibration"):
            calibration.save(_result(key), mine)
        assert mine.read_text() == text and [p.name for p in tmp_path.iterdir()] == [mine.name]

    # a symbolic link, even to a pfjax calibration, is the user's: refused, the link and its file kept
    shared = tmp_path.parent / f"{tmp_path.name}-shared.json"
    shared.write_text(json.dumps(_result(key)))
    mine.unlink()
    mine.symlink_to(shared)
    assert main(["calibrate", "--quick"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "is a symbolic link, which pfjax does not replace" in err[0], err
    with pytest.raises(InputError, match="^PFJAX_CALIBRATION_DIR: .* is a symbolic link"):
        calibration.save(_result(key), mine)
    assert mine.is_symlink() and json.loads(shared.read_text()) == _result(key)
    mine.unlink()

    old = dict(_result(key), version=calibration.VERSION + 1)  # pfjax's, of another format
    for previous in (_result(key), old):
        mine.write_text(json.dumps(previous))
        new = dict(_result(key), vector_width=512)
        monkeypatch.setattr(C, "calibrate", lambda **kw: new)
        assert main(["calibrate", "--quick", "--json"]) == 0
        capsys.readouterr()
        calibration.load.cache_clear()
        assert json.loads(mine.read_text()) == new


def test_a_calibration_of_another_cpu_is_ignored_and_an_unknown_switch_warns(tmp_path, monkeypatch):
    """A file at this CPU's name whose key is another CPU's (a copied file) is ignored with one
    warning; a PFJAX_CALIBRATION value that is neither on nor off warns and leaves it on."""
    monkeypatch.setenv("PFJAX_CALIBRATION_DIR", str(tmp_path))
    monkeypatch.delenv("PFJAX_CALIBRATION", raising=False)
    data = json.loads(Path(_file(tmp_path, cpu_key="genuineintel-6-85-deadbeef", vector_width=256)).read_text())
    (tmp_path / f"{calibration.cpu_key()}.json").write_text(json.dumps(data))
    calibration.load.cache_clear()
    try:
        with pytest.warns(UserWarning, match="measured on another CPU"):
            assert calibration.load() is None
        data["cpu_key"] = calibration.cpu_key()
        (tmp_path / f"{calibration.cpu_key()}.json").write_text(json.dumps(data))
        calibration.load.cache_clear()
        assert calibration.load()["vector_width"] == 256
    finally:
        calibration.load.cache_clear()
    with pytest.warns(UserWarning, match="PFJAX_CALIBRATION='disabled' not understood"):
        assert calibration.directory({"PFJAX_CALIBRATION": "disabled", "PFJAX_CALIBRATION_DIR": str(tmp_path)})
    assert calibration.directory({"PFJAX_CALIBRATION": "on", "PFJAX_CALIBRATION_DIR": str(tmp_path)}) == tmp_path


def test_the_printed_calibration_gives_units_only_for_what_it_prints(monkeypatch, capsys):
    """pfjax calibrate --json leaves the machine record in the file, and its units with it: every
    unit the output names belongs to a number it prints."""
    from pfjax.cli import main

    fake = {
        "vector_width": 512,
        "block_bytes": {"float32": 5000, "float64": 5000},
        "machine": {"block_bytes": {"float32": 5000, "float64": 5000}},
        "units": {"block_bytes.*": {"float32": "B", "float64": "B"}, "machine.block_bytes.*": {"float32": "B"}},
    }
    monkeypatch.setattr(C, "calibrate", lambda **kw: fake)
    assert main(["calibrate", "--quick", "--dry-run", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert "machine" not in out and not any(k.startswith("machine.") for k in out["units"])
    assert out["units"]["block_bytes.*"] == {"float32": "B", "float64": "B"} and out["file"] is None


# --------------------------------------------------------------- a file that cannot be a calibration


def _warned_once(call) -> str:
    """The one warning line ``call()`` gives (as printed), asserting ``call()`` is None."""
    import warnings

    calibration.load.cache_clear()
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            assert call() is None
    finally:
        calibration.load.cache_clear()
    (w,) = caught
    text = warnings.formatwarning(w.message, w.category, w.filename, w.lineno, w.line)
    assert text.count("\n") == 1 and text.startswith("pfjax:0: UserWarning: "), text
    return text


def test_a_calibration_nested_too_deeply_to_parse_is_ignored_with_one_warning(tmp_path, monkeypatch, capsys):
    """JSON nested beyond Python's recursion limit: one warning line at import (every command still
    runs), and pfjax calibrate refuses it as the user's file (one line, exit 2), never a traceback."""
    import os
    import subprocess
    import sys

    from pfjax.cli import main

    key = calibration.cpu_key()
    deep = tmp_path / f"{key}.json"
    deep.write_text("[" * 100_000 + "]" * 100_000)
    text = _warned_once(lambda: calibration.load(str(deep)))
    assert f"{deep}: calibration ignored, unreadable (maximum recursion depth exceeded" in text
    env = {k: v for k, v in os.environ.items() if k != "PFJAX_CALIBRATION"}
    r = subprocess.run(
        [sys.executable, "-c", "import pfjax.numerics.compiler as c; print(c.OPTIONS is not None)"],
        env={**env, "PFJAX_CALIBRATION_DIR": str(tmp_path)},
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert r.returncode == 0 and r.stdout == "True\n", r.stderr[-2000:]
    assert r.stderr.count("calibration ignored, unreadable") == 1 and "Traceback" not in r.stderr
    monkeypatch.delenv("PFJAX_CALIBRATION", raising=False)  # the tests' "off" (conftest)
    monkeypatch.setenv("PFJAX_CALIBRATION_DIR", str(tmp_path))
    monkeypatch.setattr(C, "calibrate", lambda **kw: pytest.fail("measured before checking"))
    assert main(["calibrate", "--quick"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"pfjax calibrate: error: PFJAX_CALIBRATION_DIR: {deep} is not a pfjax")
    assert deep.read_text().startswith("[[[")  # the user's file, untouched


def test_a_directory_at_the_calibration_files_path_is_ignored_with_one_warning(tmp_path, monkeypatch):
    (tmp_path / f"{calibration.cpu_key()}.json").mkdir()
    monkeypatch.delenv("PFJAX_CALIBRATION", raising=False)
    monkeypatch.setenv("PFJAX_CALIBRATION_DIR", str(tmp_path))
    text = _warned_once(calibration.load)
    assert f"{tmp_path / calibration.cpu_key()}.json: calibration ignored, not a file" in text
    assert "not a file" in _warned_once(lambda: calibration.load(str(tmp_path)))
    calibration.load.cache_clear()
    assert calibration.load(str(tmp_path / "absent.json")) is None  # none written: no warning
    calibration.load.cache_clear()


# ------------------------------------------------------ a candidate that disagrees is never chosen


def _candidates(**diff) -> list[dict]:
    """Measured rows of two widths and two blocks; ``diff``: the max |IAE difference| (m s) of a
    row by ``<dtype>_<width>_<block>`` (0 otherwise). The fastest: float32 512-bit 2,500 bytes."""
    return [
        dict(dtype=d, vector_width=w, block_bytes=b, msteps_per_s=r, max_abs_iae_diff=diff.get(f"{d}_{w}_{b}", 0.0))
        for d, w, b, r in [
            ("float32", None, 2500, 100.0),
            ("float32", None, 5000, 120.0),
            ("float32", 512, 2500, 200.0),
            ("float32", 512, 5000, 150.0),
            ("float64", None, 2500, 60.0),
            ("float64", None, 5000, 50.0),
            ("float64", 512, 2500, 40.0),
            ("float64", 512, 5000, 45.0),
        ]
    ]


def test_a_candidate_whose_results_disagree_is_never_chosen():
    """Beyond the benchmark's tolerance (float32 1e-4, float64 1e-10 m s), or not finite: not chosen,
    however fast; a width with no agreeing candidate in a precision is not chosen; none at all:
    ``failed``, nothing to keep."""
    from pfjax.bench.run import TOLERANCE

    assert C.choose(_candidates())["block_bytes"] == {"float32": 2500, "float64": 5000}  # 512: 200 * 45
    assert C.choose(_candidates(float32_512_2500=TOLERANCE["float32"]))["block_bytes"]["float32"] == 2500  # at it
    for bad in (2 * TOLERANCE["float32"], math.nan):
        got = C.choose(_candidates(float32_512_2500=bad))  # 512: 150 * 45 = 6750 < default 120 * 60
        assert got["vector_width"] is None and got["block_bytes"] == {"float32": 5000, "float64": 2500}
    both = C.choose(_candidates(float64_512_2500=1e-9, float64_512_5000=1e-9))  # no 512-bit float64 agrees
    assert both["vector_width"] is None and "failed" not in both
    every = {f"{d}_{w}_{b}": math.nan for d in ("float32", "float64") for w in (None, 512) for b in (2500, 5000)}
    got = C.choose(_candidates(**every))
    assert (
        got["vector_width"] is None and got["block_bytes"] is None and got["failed"].startswith("no candidate agrees")
    )
    assert C.agrees(_candidates()[0]) and not C.agrees(_candidates(float32_None_2500=math.nan)[0])


def test_pfjax_calibrate_keeps_nothing_when_no_candidate_agrees(tmp_path, monkeypatch, capsys):
    from pfjax.cli import main

    key = calibration.cpu_key()
    every = {f"{d}_{w}_{b}": math.nan for d in ("float32", "float64") for w in (None, 512) for b in (2500, 5000)}
    rows = _candidates(**every)
    result = dict(_result(key), **C.choose(rows), rows=[dict(r, agrees=C.agrees(r)) for r in rows])
    monkeypatch.delenv("PFJAX_CALIBRATION", raising=False)  # the tests' "off" (conftest)
    monkeypatch.setenv("PFJAX_CALIBRATION_DIR", str(tmp_path))
    monkeypatch.setattr(C, "calibrate", lambda **kw: result)
    assert main(["calibrate", "--quick", "--json"]) == 1  # returned, not raised
    got = capsys.readouterr()
    assert got.err.splitlines() == [f"pfjax calibrate: error: {result['failed']}; nothing was kept"]
    printed = json.loads(got.out)  # the measurement, printed
    assert printed["file"] is None and printed["block_bytes"] is None and len(printed["rows"]) == 8
    assert not any(tmp_path.iterdir())


def test_the_calibrate_help_states_what_it_runs_not_how_long(capsys):
    from pfjax.cli import main

    with pytest.raises(SystemExit):
        main(["calibrate", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "20,000 runs of 5 s (1,000 steps), best of 3 rounds" in text and "1,024 runs of 0.5 s" in text
    assert "minute" not in text and "float32 1e-4 m s, float64 1e-10 m s" in text


def test_the_sharing_chosen_is_each_precisions_fastest_that_agrees():
    """choose_sharing: per precision the fastest sharing of the sine-cosine pair among those whose
    per-run IAE agrees; a precision where none agrees is left to the rule."""
    rows = [
        dict(dtype=d, sincos_sharing=sh, msteps_per_s=r, max_abs_iae_diff=e)
        for d, sh, r, e in [
            ("float32", "complex", 100.0, 0.0),
            ("float32", "real", 110.0, 0.0),
            ("float32", "none", 120.0, 1.0),  # fastest, but disagrees
            ("float64", "complex", 40.0, math.nan),
            ("float64", "real", 45.0, math.inf),
        ]
    ]
    assert C.choose_sharing(rows) == {"float32": "real"}


def test_each_candidate_program_is_traced_under_its_own_sharing():
    """Every call of _program is a new function, so the sharing in force when it is first traced
    decides its program, whatever was traced before (JAX keeps one trace per function)."""
    from pfjax.bench import problem as P
    from pfjax.controllers import state_feedback
    from pfjax.numerics import elementary as E
    from pfjax.sim import SimConfig

    placed, _, layout = sharding.plan_batch(P.scenarios(P.random_batch(8), np.float32), None, None)
    sim = SimConfig(dt=P.DT, horizon=0.02, newton_iters=P.NEWTON_ITERS, record=False)
    texts = {}
    for sharing in ("complex", "none", "complex"):
        with E.sharing_mode(sharing):
            program = C._program(None)
            texts[sharing] = (
                program.trace(placed, controller=state_feedback, config=sim, layout=layout).lower().as_text()
            )
    assert "complex" in texts["complex"] and "complex" not in texts["none"]
