"""Output directories (pfjax.outputs): pfjax never deletes or overwrites what it did not write,
replaces its own outputs whole, holds one writer per output, and leaves nothing behind that a
later run does not clean up. With real processes for the lock, Ctrl-C and kills."""

import io
import json
import os
import shutil
import signal
import stat
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest

from pfjax import cli
from pfjax.errors import EXIT_INTERRUPTED, EXIT_TERMINATED, EXIT_USAGE, InputError
from pfjax.montecarlo.chunks import partial_dir
from pfjax.montecarlo.config import load_study
from pfjax.montecarlo.study import run
from pfjax.montecarlo.summary import missing_key
from pfjax.outputs import (
    MARKER,
    TEMP_MARK,
    OutputBusy,
    OutputDir,
    as_written,
    check_name,
    check_target,
    mark_temporary,
    read_marker,
    sibling,
    temporary_dir,
)

STUDY = """name = "outputs"
n_runs = 24
seed = 7
chunk_size = 8
f64_check_runs = 0
[sim]
horizon = 2.0
steady_window = 1.0
[success]
from_s = 1.0
band = 0.2
[slip]
beta_r_deg = { dist = "uniform", low = -5, high = 5 }
[initial]
lateral_offset = { dist = "uniform", low = -0.3, high = 0.3 }
[margin]
enabled = false
[[paths]]
kind = "line"
[[controllers]]
name = "st"
type = "stanley"
"""


def _write(out: Path, files: dict, *, command="study", sha="a" * 64) -> None:
    with OutputDir(out, command=command, config_sha256=sha, overwrite=True) as o:
        for name, text in files.items():
            (o.staging / name).parent.mkdir(parents=True, exist_ok=True)
            (o.staging / name).write_text(text)
        o.commit()


def _tree(root: Path) -> dict:
    """Every entry under ``root`` with its bytes (directories as None): "byte-identical" checks."""
    return {str(p.relative_to(root)): (None if p.is_dir() else p.read_bytes()) for p in sorted(root.rglob("*"))}


# ------------------------------------------------------------------------------ check_target


def test_new_and_empty_targets_are_accepted(tmp_path):
    assert check_target(tmp_path / "new", command="study", config_sha256="x") == tmp_path / "new"
    (tmp_path / "empty").mkdir()
    assert check_target(tmp_path / "empty", command="study", config_sha256="x") == tmp_path / "empty"


def test_a_directory_pfjax_did_not_write_is_refused_even_with_overwrite(tmp_path):
    keep = tmp_path / "keep"
    keep.mkdir()
    (keep / "thesis.tex").write_text("data")
    for overwrite in (False, True):
        with pytest.raises(InputError, match=r"^--out: .*keep is not empty and was not written by pfjax") as e:
            check_target(keep, command="study", config_sha256="x", overwrite=overwrite)
        assert e.value.key == "--out"
    (tmp_path / "file").write_text("x")
    with pytest.raises(InputError, match="exists and is not a directory"):
        check_target(tmp_path / "file", command="study", config_sha256="x", overwrite=True)
    (tmp_path / "link").symlink_to(keep)
    with pytest.raises(InputError, match="symbolic link"):
        check_target(tmp_path / "link", command="study", config_sha256="x", overwrite=True)


@pytest.mark.parametrize("target", [".", "..", "", "results/..", "a/."])
def test_dot_targets_are_refused(target, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(InputError, match=r"^--out: .*does not name a new directory"):
        check_target(target, command="study", config_sha256="x", overwrite=True)


def test_root_home_and_directories_containing_the_working_directory_are_refused(tmp_path, monkeypatch):
    work = tmp_path / "a" / "b"
    work.mkdir(parents=True)
    monkeypatch.chdir(work)
    _write(tmp_path / "a" / "b" / "out", {"x.txt": "1"})  # even a directory holding pfjax outputs
    for target, what in (
        (tmp_path / "a", "contains it"),
        (work, "current directory"),
        (Path("/"), "does not name a new directory|filesystem root"),
    ):
        with pytest.raises(InputError, match=what):
            check_target(target, command="study", config_sha256="x", overwrite=True)
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    (tmp_path / "home").mkdir()
    with pytest.raises(InputError, match="home directory"):
        check_target(tmp_path / "home", command="study", config_sha256="x", overwrite=True)


def test_own_outputs_are_replaced_by_a_rerun_and_others_only_with_overwrite(tmp_path):
    out = tmp_path / "out"
    _write(out, {"summary.json": "{}", "figures/a.png": "png"}, sha="a" * 64)
    assert read_marker(out)["files"].keys() == {"summary.json", "figures/a.png"}
    check_target(out, command="study", config_sha256="a" * 64)  # a re-run of the same config
    for command, sha in (("study", "b" * 64), ("bench", "a" * 64)):
        with pytest.raises(
            InputError,
            match=r"^--out: .* holds the output of `pfjax study` \(config aaaaaaaaaaaa\); "
            r"add --overwrite",
        ):
            check_target(out, command=command, config_sha256=sha)
        check_target(out, command=command, config_sha256=sha, overwrite=True)


def test_foreign_and_changed_files_in_an_output(tmp_path):
    out = tmp_path / "out"
    _write(out, {"summary.json": "{}", "figures/a.png": "png"})
    (out / "figures" / "notes.txt").write_text("mine")
    with pytest.raises(InputError, match=r"holds 'figures/notes.txt', which pfjax did not write"):
        check_target(out, command="study", config_sha256="a" * 64, overwrite=True)
    (out / "figures" / "notes.txt").unlink()
    (out / "mine").mkdir()
    with pytest.raises(InputError, match=r"holds 'mine'"):
        check_target(out, command="study", config_sha256="a" * 64, overwrite=True)
    (out / "mine").rmdir()
    (out / "summary.json").write_text('{"edited": 1}')
    with pytest.raises(InputError, match=r"summary.json changed after pfjax wrote it; add --overwrite"):
        check_target(out, command="study", config_sha256="a" * 64)
    check_target(out, command="study", config_sha256="a" * 64, overwrite=True)


def test_a_link_where_pfjax_wrote_a_file_is_the_users_even_with_overwrite(tmp_path):
    """pfjax writes no links: one in place of a file it listed was put there by the user, and
    --overwrite, which may replace pfjax's own changed files, does not remove it."""
    out = tmp_path / "out"
    _write(out, {"summary.json": "{}", "figures/a.png": "png"})
    mine = tmp_path / "mine.json"
    mine.write_text("precious")
    (out / "summary.json").unlink()
    (out / "summary.json").symlink_to(mine)
    with pytest.raises(InputError, match=r"holds 'summary.json', which pfjax did not write"):
        check_target(out, command="study", config_sha256="a" * 64, overwrite=True)
    with (
        pytest.raises(InputError, match=r"holds 'summary.json'"),
        OutputDir(out, command="study", config_sha256="b" * 64, overwrite=True),
    ):
        pass
    assert (out / "summary.json").is_symlink() and mine.read_text() == "precious"


def test_a_changed_file_kept_by_a_rewrite_stays_the_users(tmp_path):
    """``pfjax report --overwrite`` keeps the files it does not redraw (start_from_existing), an edited
    one too; that one is then the user's, left out of the new marker, so that a later run refuses
    to replace it instead of deleting the edit."""
    out = tmp_path / "out"
    _write(out, {"summary.json": "{}", "figures/worst.svg": "<svg/>", "figures/a.png": "png"})
    (out / "figures" / "worst.svg").write_text("<svg/><!-- my edit -->")
    with OutputDir(out, command="study", config_sha256="a" * 64, overwrite=True) as o:
        o.start_from_existing(lambda rel: rel.startswith("figures/"))
        (o.staging / "summary.json").write_text("{}")
        o.commit()
    assert (out / "figures" / "worst.svg").read_text() == "<svg/><!-- my edit -->"
    assert sorted(read_marker(out)["files"]) == ["figures/a.png", "summary.json"]
    with pytest.raises(InputError, match=r"holds 'figures/worst.svg', which pfjax did not write"):
        check_target(out, command="study", config_sha256="a" * 64, overwrite=True)


@pytest.mark.parametrize("name", ["", ".", "..", "a/b", "../x", ".hidden", "a b", "x" * 101, 3, None])
def test_bad_names(name):
    with pytest.raises(InputError, match=r"^name: expected a name"):
        check_name("name", name)


# ------------------------------------------------------------------------------ OutputDir


def test_a_failed_write_leaves_the_previous_output_and_no_staging(tmp_path):
    out = tmp_path / "out"
    _write(out, {"summary.json": "old"})
    before = _tree(out)
    with pytest.raises(RuntimeError), OutputDir(out, command="study", config_sha256="a" * 64) as o:
        (o.staging / "summary.json").write_text("new")
        raise RuntimeError("boom")
    assert _tree(out) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]  # no staging, no lock file


def test_stale_staging_of_a_killed_run_is_removed_by_the_next_writer(tmp_path):
    out = tmp_path / "out"
    stale = [temporary_dir(out, "pfjax-staging"), temporary_dir(out, "pfjax-old")]
    for s in stale:
        (s / "x").write_text("left by a kill")
    other = temporary_dir(tmp_path / "outer", "pfjax-staging")  # another target's: not this writer's business
    _write(out, {"a": "1"})
    assert not any(s.exists() for s in stale) and other.exists()


def test_a_previous_output_stranded_by_a_kill_between_the_final_renames_is_put_back(tmp_path):
    """A kill after the previous output was moved aside and before the new one was moved in leaves
    nothing at the target: the next writer puts the previous output back before it checks the
    target (so a refusal leaves it in place too)."""
    out = tmp_path / "out"
    _write(out, {"summary.json": "old"})
    before = _tree(out)
    old = temporary_dir(out, "pfjax-old")
    os.replace(out, old / "output")  # the state the kill leaves
    with pytest.raises(InputError, match="holds the output of `pfjax study`"):
        OutputDir(out, command="study", config_sha256="b" * 64).open()  # another config: refused ...
    assert _tree(out) == before and not old.exists()  # ... with the previous output back in place


def test_the_final_renames_are_not_split_by_ctrl_c(tmp_path, monkeypatch):
    """SIGINT during the two final renames is held and acted on once both are done."""
    import signal

    out = tmp_path / "out"
    _write(out, {"summary.json": "old"})
    real, calls = os.replace, []

    def replace(a, b):
        calls.append(1)
        if len(calls) == 1:
            signal.raise_signal(signal.SIGINT)  # between the two renames
        real(a, b)

    monkeypatch.setattr(os, "replace", replace)
    with pytest.raises(KeyboardInterrupt), OutputDir(out, command="study", config_sha256="a" * 64) as o:
        (o.staging / "summary.json").write_text("new")
        o.commit()
    assert (out / "summary.json").read_text() == "new" and len(calls) == 2


@pytest.mark.parametrize("mode", [0o700, 0o2750])
def test_a_users_empty_directory_keeps_its_mode_when_replaced(tmp_path, mode):
    """An empty --out the user made is replaced by the output directory: with its mode (who may
    read it, a setgid bit) and group, not pfjax's."""
    out = tmp_path / "out"
    out.mkdir()
    out.chmod(mode)
    _write(out, {"a": "1"})
    assert stat.S_IMODE(out.stat().st_mode) == mode
    new = tmp_path / "new"
    old_mask = os.umask(0o077)
    try:
        _write(new, {"a": "1"})
    finally:
        os.umask(old_mask)
    assert stat.S_IMODE(new.stat().st_mode) == 0o700  # a new one: 0o777 less the umask, as mkdir


def test_a_mount_point_is_refused_before_any_work_empty_or_not(tmp_path, monkeypatch):
    """An output is moved into place whole at the end, which a mount point cannot be: refused up
    front, whether empty or holding a previous pfjax output (which would fail only after the run)."""
    out = tmp_path / "mnt"
    out.mkdir()
    monkeypatch.setattr(os.path, "ismount", lambda p: str(p) == str(out))
    with pytest.raises(InputError, match=r"^--out: .* is a mount point"):
        check_target(out, command="study", config_sha256="a" * 64)
    monkeypatch.undo()
    _write(out, {"summary.json": "{}"})
    monkeypatch.setattr(os.path, "ismount", lambda p: str(p) == str(out))
    with pytest.raises(InputError, match=r"^--out: .* is a mount point"):
        check_target(out, command="study", config_sha256="a" * 64)


def test_a_writer_leaves_the_temporary_directories_of_a_target_named_like_its_own(tmp_path):
    """Target ``exp`` and a study running into ``exp.partial-v2``: the other's live staging
    ``.exp.partial-v2.pfjax-staging-*`` (marked, its lock held elsewhere) matches a glob of
    ``.exp.partial-*`` but is not ``exp``'s: it survives ``exp``'s clean-up; ``exp``'s own stale
    directories do not."""
    out = tmp_path / "exp"
    live = [temporary_dir(tmp_path / "exp.partial-v2", kind) for kind in ("pfjax-staging", "partial")]
    live.append(temporary_dir(tmp_path / "exp.pfjax-old-x", "pfjax-staging"))
    for d in live:
        (d / "summary.json").write_text("{}")
    stale = [temporary_dir(out, kind) for kind in ("pfjax-staging", "pfjax-old", "partial")]
    _write(out, {"a": "1"})
    assert all((d / "summary.json").is_file() for d in live) and not any(d.exists() for d in stale)


def test_entries_beside_the_target_that_pfjax_did_not_make_are_left_as_they_are(tmp_path):
    """Directories named like pfjax's temporary ones but without its mark (a user's, or a link to
    one) survive a writer's clean-up, byte for byte; so does the file a link points to."""
    out = tmp_path / "out"
    mine = [sibling(out, "pfjax-staging-mine"), sibling(out, "pfjax-old-mine"), sibling(out, "partial-mine")]
    for d in mine:
        d.mkdir()
        (d / "precious.txt").write_text("the user's")
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    (elsewhere / TEMP_MARK).write_text("")  # marked, but reached only through a link
    sibling(out, "partial-link").symlink_to(elsewhere, target_is_directory=True)
    before = _tree(tmp_path)
    _write(out, {"a": "1"})
    after = _tree(tmp_path)
    assert {k: v for k, v in after.items() if not k.startswith("out")} == before


@pytest.mark.parametrize("kind", ["file", "empty", "json with a pid", "symlink", "directory"])
def test_a_lock_name_taken_by_something_pfjax_did_not_write_is_refused_and_kept(tmp_path, kind):
    """Only a whole lock record (pid, host, command, started) is pfjax's: a user's file at the lock's
    name, empty or JSON with a ``pid`` of its own, is refused and kept, never taken over or removed
    (pfjax's lock file appears at its name with its record in it, so it is never empty)."""
    out, precious = tmp_path / "out", tmp_path / "precious.txt"
    precious.write_text("the user's")
    lock = sibling(out, "lock")
    if kind == "file":
        lock.write_text("the user's notes")
    elif kind == "empty":
        lock.write_text("")
    elif kind == "json with a pid":
        lock.write_text('{"pid": 1, "note": "mine"}')
    elif kind == "symlink":
        lock.symlink_to(precious)
    else:
        lock.mkdir()
        (lock / "x").write_text("the user's")
    before = _tree(tmp_path)
    with pytest.raises(InputError, match="--out: .*lock file .*pfjax did not write"):
        _write(out, {"a": "1"})
    assert _tree(tmp_path) == before and lock.is_symlink() == (kind == "symlink")


def test_a_lock_file_left_by_a_killed_writer_is_taken_over(tmp_path):
    out = tmp_path / "out"
    record = {"pid": 1, "host": "h", "command": "study", "started": "2026-01-01T00:00:00+00:00"}
    sibling(out, "lock").write_text(json.dumps(record) + "\n")
    _write(out, {"a": "1"})
    assert (out / "a").read_text() == "1" and not sibling(out, "lock").exists()


def test_a_held_lock_file_holds_its_whole_record_and_nothing_is_left_beside_it(tmp_path):
    out = tmp_path / "out"
    with OutputDir(out, command="study", config_sha256="x") as o:
        record = json.loads(sibling(out, "lock").read_text())
        assert set(record) == {"pid", "host", "command", "started"} and record["pid"] == os.getpid()
        assert sorted(p.name for p in tmp_path.iterdir() if p.name.startswith(".out.lock")) == [".out.lock"]
        (o.staging / "a").write_text("1")
        o.commit()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


def test_the_lock_refuses_a_second_writer_in_another_process(tmp_path):
    out = tmp_path / "out"
    holder = subprocess.Popen(
        [
            sys.executable,
            "-c",
            "import sys; from pfjax.outputs import OutputDir; "
            f"o = OutputDir({str(out)!r}, command='study', config_sha256='x').open(); print('held', flush=True); "
            "sys.stdin.readline(); o.close()",
        ],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert holder.stdout.readline().strip() == "held"
        with pytest.raises(OutputBusy, match=rf"^--out: a pfjax study is running into .*out \(pid {holder.pid} on "):
            OutputDir(out, command="study", config_sha256="x").open()
    finally:
        holder.communicate("\n", timeout=30)
    assert holder.returncode == 0
    OutputDir(out, command="study", config_sha256="x").open().close()  # released: free again
    assert not sibling(out, "lock").exists()


def test_a_killed_holder_releases_the_lock(tmp_path):
    out = tmp_path / "out"
    holder = subprocess.Popen(
        [
            sys.executable,
            "-c",
            "import time; from pfjax.outputs import OutputDir; "
            f"o = OutputDir({str(out)!r}, command='study', config_sha256='x').open(); print('held', flush=True); "
            "time.sleep(600)",
        ],
        stdout=subprocess.PIPE,
        text=True,
    )
    assert holder.stdout.readline().strip() == "held"
    holder.kill()
    holder.wait()
    assert sibling(out, "lock").exists()  # the file stays; the lock went with the process
    with OutputDir(out, command="study", config_sha256="x") as o:
        (o.staging / "a").write_text("1")
        o.commit()
    assert not sibling(out, "lock").exists()


# ------------------------------------------------------------------------------ commands


@pytest.fixture
def study_toml(tmp_path):
    p = tmp_path / "s.toml"
    p.write_text(STUDY)
    return p


def _cli(argv, capsys):
    code = cli.main(argv)
    err = capsys.readouterr().err.strip().splitlines()
    return code, err


@pytest.mark.parametrize(
    "command",
    [
        ["study", "{toml}", "--no-report"],
        ["report", "{toml}"],
        ["bench", "--quick"],
    ],
)
def test_commands_refuse_a_user_directory_and_touch_nothing(command, study_toml, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    keep = tmp_path / "keep"
    keep.mkdir()
    (keep / "thesis.tex").write_text("data")
    before = _tree(tmp_path)
    code, err = _cli([a.format(toml=study_toml) for a in command] + ["--out", "keep"], capsys)
    assert code == EXIT_USAGE and len(err) == 1 and err[0].startswith(f"pfjax {command[0]}: error: --out: "), err
    assert _tree(tmp_path) == before


@pytest.mark.parametrize("out", [".", ".."])
def test_study_refuses_dot_outputs(out, study_toml, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(study_toml.parent)
    before = _tree(tmp_path)
    code, err = _cli(["study", str(study_toml), "--out", out, "--no-report"], capsys)
    assert code == EXIT_USAGE and len(err) == 1 and "--out: " in err[0]
    assert _tree(tmp_path) == before


@pytest.mark.parametrize("name", ['".."', '"."', '"a/b"', '""'])
def test_study_names_that_are_not_directory_names_are_refused(name, study_toml, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    before = _tree(tmp_path)
    code, err = _cli(["study", str(study_toml), "--set", f"name={name}"], capsys)
    assert code == EXIT_USAGE and len(err) == 1 and err[0].startswith("pfjax study: error: name: "), err
    assert _tree(tmp_path) == before


def test_report_of_a_missing_or_corrupt_study_is_one_line(study_toml, tmp_path, capsys):
    out = tmp_path / "out"
    spec = load_study(study_toml)[0]
    run(spec, out, progress=False, report=False)
    code, err = _cli(["report", str(study_toml), "--out", str(out)], capsys)
    assert code == 0 and (out / "report.html").is_file()
    assert read_marker(out)["files"].keys() >= {"report.html", "runs.parquet", "summary.json"}
    summary = json.loads((out / "summary.json").read_text())
    assert missing_key(summary) is None  # what the study writes has every key a report reads
    name = next(iter(summary["controllers"]))
    del summary["controllers"][name]["success_rate"]
    edited = [json.dumps(summary).encode(), b'{"controllers": {}}', b"[]"]
    for name, text in (
        ("runs.parquet", b"not parquet"),
        ("summary.json", b"{"),
        *(("summary.json", t) for t in edited),
    ):
        saved, st = (out / name).read_bytes(), (out / name).stat()
        (out / name).write_bytes(text)
        before = _tree(out)
        code, err = _cli(["report", str(study_toml), "--out", str(out), "--overwrite"], capsys)
        assert (
            code == EXIT_USAGE
            and len(err) == 1
            and err[0].startswith("pfjax report: error: --out: ")
            and name in err[0]
        ), err
        assert _tree(out) == before
        # the file as the study wrote it (its time too), so that the study's own files are checked next
        (out / name).write_bytes(saved)
        os.utime(out / name, ns=(st.st_atime_ns, st.st_mtime_ns))
        # edited but readable (the same table or summary written anew, other bytes): never built
        # from, nor recorded as pfjax's by --overwrite
        if name == "summary.json":
            (out / name).write_text(json.dumps(json.loads(saved), indent=2))
        else:
            pd.read_parquet(io.BytesIO(saved)).to_parquet(out / name, compression="gzip")
        code, err = _cli(["report", str(study_toml), "--out", str(out), "--overwrite"], capsys)
        assert code == EXIT_USAGE and f"{name} changed after the study wrote it" in err[0], err
        # the same bytes with a new time (a copy): the study's own file
        (out / name).write_bytes(saved)
        assert as_written(read_marker(out)["files"], name, (out / name).stat(), out / name)
        os.utime(out / name, ns=(st.st_atime_ns, st.st_mtime_ns))
    (out / "runs.parquet").unlink()
    code, err = _cli(["report", str(study_toml), "--out", str(out), "--overwrite"], capsys)
    assert code == EXIT_USAGE and "runs.parquet is missing" in err[0]
    code, err = _cli(["report", str(study_toml), "--set", "seed=5", "--out", str(tmp_path / "nothing")], capsys)
    assert code == EXIT_USAGE and "no finished study" in err[0]
    assert f"; run `pfjax study {study_toml} --set seed=5 --out {tmp_path / 'nothing'}` first" in err[0]


def test_a_previous_output_that_cannot_be_removed_stays_marked_and_is_retried(tmp_path, monkeypatch):
    """A file of the previous output that the filesystem keeps (an immutable file, a file a
    non-root user may not delete) is left with a warning, in a directory still marked as pfjax's,
    so that the next run into the output removes it once it can, and never leaves it unmarked."""
    import pfjax.outputs as outputs

    out = tmp_path / "out"
    _write(out, {"summary.json": "{}", "runs.parquet": "old"})
    real_unlink = Path.unlink

    def stuck(self, *a, **k):
        if self.name == "runs.parquet" and ".pfjax-old-" in str(self):
            raise PermissionError(1, "Operation not permitted")
        return real_unlink(self, *a, **k)

    monkeypatch.setattr(outputs.shutil, "rmtree", lambda p, ignore_errors=False: _rmtree_with(p, stuck))
    monkeypatch.setattr(Path, "unlink", stuck)
    with pytest.warns(
        RuntimeWarning, match=r"could not remove .*pfjax-old-\w+/output; the next run into its output tries again"
    ):
        _write(out, {"summary.json": "{}", "runs.parquet": "new"})
    assert (out / "runs.parquet").read_text() == "new"
    (left,) = [p for p in tmp_path.iterdir() if ".pfjax-old-" in p.name]
    assert (left / TEMP_MARK).is_file() and (left / "output" / "runs.parquet").read_text() == "old"
    monkeypatch.undo()
    # the user removes the output meanwhile: the leftover is not "restored" as the output
    shutil.rmtree(out)
    _write(out, {"summary.json": "{}", "runs.parquet": "newer"})  # the next run removes it
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"] and (out / "runs.parquet").read_text() == "newer"


def _rmtree_with(path, unlink):
    """``shutil.rmtree(path, ignore_errors=True)`` whose file removals go through ``unlink``."""
    for root, dirs, files in os.walk(path, topdown=False):
        for f in files:
            try:
                unlink(Path(root) / f)
            except OSError:
                pass
        for d in dirs:
            try:
                os.rmdir(Path(root) / d)
            except OSError:
                pass
    try:
        os.rmdir(path)
    except OSError:
        pass


def test_a_report_refuses_a_study_whose_margin_table_was_deleted(tmp_path):
    """Every file a report is built from that the study wrote must still be there: a deleted
    margin.parquet is refused, not dropped from the new output while the report still shows the
    margins of summary.json."""
    from pfjax.montecarlo.study import _unchanged_inputs

    out = tmp_path / "out"
    _write(out, {"summary.json": "{}", "runs.parquet": "r", "margin.parquet": "m"})
    _unchanged_inputs(out)
    (out / "margin.parquet").unlink()
    with pytest.raises(InputError, match=r"^--out: .*margin\.parquet is missing \(the study wrote it\)"):
        _unchanged_inputs(out)


def test_a_bad_config_leaves_no_partial_directory_behind(study_toml, tmp_path, capsys):
    out = tmp_path / "out"
    code, err = _cli(["study", str(study_toml), "--out", str(out), "--set", "sim.dt=-1"], capsys)
    assert code == EXIT_USAGE and err[0].startswith("pfjax study: error: sim.dt")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.toml"]


def test_chunks_of_another_config_are_never_reused(study_toml, tmp_path):
    """A partial directory whose manifest matches but whose chunk files were computed with another
    seed (what a second process's --fresh could leave): every such chunk is recomputed, and the
    result equals a clean run's."""
    spec = load_study(study_toml)[0]
    other = spec.model_copy(update={"seed": 99})
    ref = tmp_path / "ref"
    run(spec, ref, progress=False, report=False)

    class Stop(BaseException):
        pass

    out = tmp_path / "out"
    from pfjax.montecarlo import chunk_runs as runner  # the chunk loop reads these names from its home

    real = runner.simulate_chunk
    calls = []

    def dies_after_2(*a, **k):
        if len(calls) == 2:
            raise Stop
        calls.append(1)
        return real(*a, **k)

    runner.simulate_chunk = dies_after_2
    try:
        with pytest.raises(Stop):
            run(other, out, progress=False, report=False)  # 2 chunks of seed 99
    finally:
        runner.simulate_chunk = real
    manifest = partial_dir(out) / "manifest.json"
    m = json.loads(manifest.read_text())
    m.update(config_sha256=json.loads((ref / "summary.json").read_text())["config_sha256"], seed=7)
    manifest.write_text(json.dumps(m))  # the directory now claims to be the seed-7 study's
    summary = run(spec, out, progress=False, report=False)
    assert summary["chunks"] == {"simulated": 3, "resumed": 0}
    pd.testing.assert_frame_equal(pd.read_parquet(out / "runs.parquet"), pd.read_parquet(ref / "runs.parquet"))


@pytest.mark.parametrize(
    "files",
    [
        {"manifest.json": '{"mine": 1}', "a.parquet": None},  # a user's manifest, a user's table
        {"manifest.json": None},  # pfjax's manifest keys, a user's table below
        {"notes.txt": "x"},  # no manifest at all
        {"mine.parquet": None},  # a table of a user's, no manifest
        {},  # empty: no manifest, so not pfjax's
    ],
    ids=["user-manifest", "user-parquet", "no-manifest", "parquet-only", "empty"],
)
@pytest.mark.parametrize("fresh", [["--fresh"], []], ids=["fresh", "resume"])
def test_a_user_directory_named_like_the_partial_one_is_never_removed(study_toml, tmp_path, capsys, files, fresh):
    """``.<out>.partial`` that pfjax did not write (its manifest not pfjax's, a Parquet file without a
    study's identity, or no manifest) is refused with one line naming --out and left as it was,
    with --fresh and without (never "an interrupted study" to resume or discard)."""
    out = tmp_path / "out"
    user = partial_dir(out)
    user.mkdir()
    for name, text in files.items():
        if name.endswith(".parquet"):
            pd.DataFrame({"x": [1.0]}).to_parquet(user / name)
        elif text is None:  # the manifest pfjax writes, with a user's table beside it
            (user / name).write_text(json.dumps({"study": "s", "config_sha256": "0", "seed": 0, "pfjax_version": "0"}))
            pd.DataFrame({"x": [1.0]}).to_parquet(user / "t.parquet")
        else:
            (user / name).write_text(text)
    before = sorted((p.name, p.stat().st_size, p.stat().st_mtime_ns) for p in user.iterdir())
    code, err = _cli(["study", str(study_toml), "--out", str(out), *fresh], capsys)
    assert code == EXIT_USAGE and len(err) == 1 and err[0].startswith(f"pfjax study: error: --out: {user} "), err
    assert "pfjax did not" in err[0] and err[0].endswith("move it away"), err
    assert sorted((p.name, p.stat().st_size, p.stat().st_mtime_ns) for p in user.iterdir()) == before
    assert not out.exists()


# ------------------------------------------------------------------------------ real processes


def _env(tmp_path):
    return {
        **os.environ,
        "PFJAX_FIGURE_WORKER": "0",
        "JAX_COMPILATION_CACHE_DIR": str(tmp_path / "jax_cache"),
        "JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS": "0",
        "JAX_PERSISTENT_CACHE_MIN_ENTRY_SIZE_BYTES": "0",
    }


@pytest.mark.slow
def test_two_concurrent_studies_on_one_out_never_mix(study_toml, tmp_path):
    """Two real ``pfjax study`` processes started together on one --out, with different seeds (the
    second with --fresh --overwrite): whichever runs, the result is wholly one configuration's, and
    a refused process says a study is running."""
    out = tmp_path / "out"
    base = [
        sys.executable,
        "-m",
        "pfjax.cli",
        "study",
        str(study_toml),
        "--out",
        str(out),
        "--no-report",
        "--quiet",
        "--json",
        "--set",
        "n_runs=400",
        "--set",
        "chunk_size=40",
    ]
    env = _env(tmp_path)
    a = subprocess.Popen(base, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    while not sibling(out, "lock").exists() and a.poll() is None:
        time.sleep(0.01)
    b = subprocess.Popen(
        base + ["--set", "seed=99", "--fresh", "--overwrite"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )
    results = [p.communicate(timeout=600) + (p.returncode,) for p in (a, b)]
    assert any(rc == 0 for *_, rc in results)
    for _, err, rc in results:
        assert rc in (0, EXIT_USAGE), err[-2000:]
        if rc == EXIT_USAGE:
            line = err.strip().splitlines()
            assert len(line) == 1 and "a pfjax study is running into" in line[0], err
    summary = json.loads((out / "summary.json").read_text())
    spec = load_study(study_toml, ["n_runs=400", "chunk_size=40", f"seed={summary['seed']}"])[0]
    ref = tmp_path / "ref"
    run(spec, ref, progress=False, report=False)
    pd.testing.assert_frame_equal(pd.read_parquet(out / "runs.parquet"), pd.read_parquet(ref / "runs.parquet"))


@pytest.mark.slow
@pytest.mark.parametrize(
    ("sig", "code", "word"),
    [(signal.SIGINT, EXIT_INTERRUPTED, "interrupted"), (signal.SIGTERM, EXIT_TERMINATED, "terminated")],
    ids=["ctrl-c", "sigterm"],
)
def test_ctrl_c_and_sigterm_are_one_line_and_resumable(study_toml, tmp_path, sig, code, word):
    """Ctrl-C (exit 130) and SIGTERM (a batch system's time limit; exit 143) stop a study alike:
    one line, no traceback, the finished chunks kept, no staging and no lock left, and the same
    command resumes."""
    out = tmp_path / "out"
    cmd = [
        sys.executable,
        "-m",
        "pfjax.cli",
        "study",
        str(study_toml),
        "--out",
        str(out),
        "--no-report",
        "--quiet",
        "--json",
        "--set",
        "n_runs=4000",
        "--set",
        "chunk_size=40",
    ]
    env = _env(tmp_path)
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    t0 = time.time()
    while time.time() - t0 < 300 and proc.poll() is None and len(list(partial_dir(out).glob("*.parquet"))) < 2:
        time.sleep(0.02)
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == code, err[-2000:]
    assert err.strip().splitlines()[-1] == f"pfjax study: {word}; re-run the same command to resume", err
    assert "Traceback" not in err
    done = len(list(partial_dir(out).glob("*.parquet")))
    assert done >= 2 and not out.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == [".out.partial", "jax_cache", "s.toml"]  # no staging, no lock
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=600, env=env)
    assert r.returncode == 0, r.stderr[-2000:]
    assert json.loads(r.stdout)["chunks"]["resumed"] == done
    assert sorted(p.name for p in tmp_path.iterdir()) == ["jax_cache", "out", "s.toml"]
    assert MARKER in os.listdir(out)


def test_figure_worker_directories_of_killed_studies_are_removed(tmp_path, monkeypatch):
    import tempfile

    from pfjax.report import figure_worker

    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    stale, live, other, users = (
        tmp_path / f"pfjax-figures-{dead.pid}-x1",
        tmp_path / f"pfjax-figures-{os.getppid()}-x2",
        tmp_path / "pfjax-figures-notapid",
        tmp_path / f"pfjax-figures-{dead.pid}-mine",  # a dead pid's name, but not made by pfjax
    )
    for d in (stale, live, other, users):
        d.mkdir()
        if d is not users:
            mark_temporary(d)
    figure_worker.remove_stale_dirs()
    assert not stale.exists() and live.exists() and other.exists() and users.exists()


def test_a_half_created_partial_directory_is_removed_by_the_next_writer(tmp_path):
    out = tmp_path / "out"
    half = temporary_dir(out, "partial")  # ChunkStore's temporary directory before its atomic rename
    (half / "manifest.json").write_text("{}")
    _write(out, {"a": "1"})
    assert not half.exists()


def test_ctrl_c_whose_exception_python_drops_still_interrupts_the_command(monkeypatch, capsys):
    """Python prints and drops a ``KeyboardInterrupt`` raised in a garbage-collector callback (JAX
    registers one) or a weakref callback: the command takes it from the unraisable hook, prints
    nothing for it and sends SIGINT again 50 ms later (not if the command has ended by then), and
    remembers it for the check before each of a study's chunks (the backstop, tested without the
    second signal)."""
    import gc
    import threading
    import weakref

    from pfjax import errors, interrupts

    class NoTimer:
        def __init__(self, *a, **k):
            pass

        start = cancel = join = lambda self: None
        is_alive = lambda self: False

    def interrupt_in(where: str):
        """SIGINT handled inside a gc callback or a weakref callback (only under the command's handler)."""
        send = lambda *_: (
            signal.getsignal(signal.SIGINT) is interrupts._on_sigint and signal.raise_signal(signal.SIGINT)
        )
        if where == "weakref":
            obj = type("Obj", (), {})()
            ref = weakref.ref(obj, send)  # noqa: F841
            del obj  # the callback runs here
            return
        fired = []

        def in_gc(phase, info):
            if phase == "start" and not fired:
                fired.append(send())

        gc.callbacks.append(in_gc)
        try:
            gc.collect()
        finally:
            gc.callbacks.remove(in_gc)

    def body(mode: str):
        if mode == "backstop":
            monkeypatch.setattr(threading, "Timer", NoTimer)
        interrupt_in("weakref" if mode == "weakref" else "gc")
        if mode == "ended":
            return 0
        t0 = time.time()
        while mode != "backstop" and time.time() - t0 < 5:
            time.sleep(0.01)  # the second signal interrupts here
        waited.append(mode)  # reached only without the second signal
        interrupts.stop_if_interrupted()
        return 0

    dropped, waited, late = [], [], []
    monkeypatch.setattr(sys, "unraisablehook", dropped.append)
    real = signal.signal(signal.SIGINT, signal.default_int_handler)  # as in a fresh process
    try:
        for mode, code in (("gc", 130), ("weakref", 130), ("ended", 0), ("backstop", 130)):
            assert errors.command_main("pfjax study", lambda m=mode: body(m), interrupted="resume") == code, mode
            err = capsys.readouterr().err
            assert "Traceback" not in err and "Exception ignored" not in err, err
            if code:
                assert err.strip().splitlines()[-1] == "pfjax study: interrupted; resume", err
            else:  # the command ended within 50 ms: no second signal to whatever runs next
                signal.signal(signal.SIGINT, lambda *a: late.append(a))
                time.sleep(0.2)
                signal.signal(signal.SIGINT, signal.default_int_handler)
    finally:
        signal.signal(signal.SIGINT, real)
    assert waited == ["backstop"] and dropped == [] and late == []  # no exception reached the hook, no late signal
    assert sys.unraisablehook == dropped.append and interrupts._running is None  # restored, forgotten
    interrupts.stop_if_interrupted()  # outside a command: nothing to stop


@pytest.mark.parametrize("tty", [False, True])
def test_ctrl_c_prints_one_line_and_a_blank_line_only_below_a_terminals_progress_bar(monkeypatch, capsys, tty):
    """Ctrl-C: ``<prog>: interrupted; ...`` on stderr; a newline first only on a terminal (where a
    progress bar may have left a partial line), never blank lines into a log or a pipe."""
    from pfjax import errors

    monkeypatch.setattr(sys.stderr, "isatty", lambda: tty)

    def body():
        raise KeyboardInterrupt

    assert errors.command_main("prog", body) == EXIT_INTERRUPTED
    out, err = capsys.readouterr()
    assert out == "" and err == ("\n" if tty else "") + "prog: interrupted; nothing was written\n"


def test_a_ctrl_c_after_the_command_ended_changes_nothing():
    """``pfjax.interrupts.finished`` (the console script's and the study scripts' last step): a
    SIGINT after it neither interrupts the exit handlers nor changes the exit code (SIGTERM keeps
    its action: it still ends a process waiting in its exit handlers)."""
    code = (
        "import atexit, os, signal, sys, time\n"
        "from pfjax.interrupts import finished\n"
        "atexit.register(lambda: (os.kill(os.getpid(), signal.SIGINT), time.sleep(0.1), print('exit handler ran')))\n"
        "sys.exit(finished(3))\n"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert r.returncode == 3 and r.stdout == "exit handler ran\n" and r.stderr == "", r


def test_a_file_of_the_same_size_and_other_bytes_is_changed_whatever_its_time(tmp_path):
    """Only the contents decide where the time differs: a same-size edit is changed; a marker of
    format 1 (no hash) takes any new time for a change."""
    f = tmp_path / "summary.json"
    f.write_text('{"a": 1}')
    st = f.stat()
    listed = {"summary.json": [st.st_size, st.st_mtime_ns, __import__("hashlib").sha256(f.read_bytes()).hexdigest()]}
    assert as_written(listed, "summary.json", f.stat(), f)
    f.write_text('{"a": 2}')  # the same size, other bytes, a new time
    assert f.stat().st_size == st.st_size and not as_written(listed, "summary.json", f.stat(), f)
    f.write_text('{"a": 1}')  # the bytes pfjax wrote, a new time: as written
    os.utime(f, ns=(st.st_atime_ns, st.st_mtime_ns + 10**9))
    assert as_written(listed, "summary.json", f.stat(), f)
    assert not as_written({"summary.json": listed["summary.json"][:2]}, "summary.json", f.stat(), f)


@pytest.mark.parametrize("refused", ["setting the previous output aside", "moving the new one in", "a new output"])
def test_a_final_rename_the_system_refuses_is_one_line_and_changes_nothing(tmp_path, monkeypatch, refused):
    """A rename the operating system refuses at the end (an immutable target, another user's output
    in a sticky directory): one line naming --out, the previous output as it was, nothing left
    beside it (the set-aside directory removed, the previous output moved back)."""
    import pfjax.outputs as outputs

    out = tmp_path / "out"
    if refused != "a new output":
        _write(out, {"a": "previous"})
    before = _tree(tmp_path)
    real, calls = os.replace, []

    def replace(src, dst):
        calls.append((src, dst))
        first = refused == "setting the previous output aside"
        if len(calls) == (1 if first or refused == "a new output" else 2):
            raise PermissionError(1, "Operation not permitted")
        return real(src, dst)

    monkeypatch.setattr(outputs.os, "replace", replace)
    with pytest.raises(InputError, match=r"^--out: cannot move the new output into .*out: Operation not permitted; "):
        _write(out, {"a": "new"})
    monkeypatch.undo()
    assert _tree(tmp_path) == before


def test_without_hard_links_a_lock_file_being_created_is_told_busy_not_foreign(tmp_path, monkeypatch):
    """On a file system without hard links the lock file is created empty and locked an instant
    later: a second writer that opens it in between waits for the record (EMPTY_WAITS) and is told
    the output is busy, not that a file pfjax did not write is in the way."""
    import fcntl
    import threading

    import pfjax.output_lock as lock_module
    from pfjax.output_lock import OutputLock

    def no_link(*a, **k):
        raise PermissionError(1, "Operation not permitted")

    monkeypatch.setattr(lock_module.os, "link", no_link)
    real_flock, created, calls = fcntl.flock, threading.Event(), []

    def slow_flock(fd, op):  # the first writer's lock of the file at the lock's name comes 50 ms late
        if threading.current_thread().name == "first":
            calls.append(op)
            if len(calls) == 2:  # after its temporary file's: the file at the name exists, empty
                created.set()
                time.sleep(0.05)
        return real_flock(fd, op)

    monkeypatch.setattr(fcntl, "flock", slow_flock)
    out, results = tmp_path / "out", {}

    def first():
        a = OutputLock(out, command="study")
        a.acquire()
        results["first"] = a

    t = threading.Thread(target=first, name="first")
    t.start()
    assert created.wait(5)
    with pytest.raises(OutputBusy, match=r"^--out: a pfjax study is running into "):
        OutputLock(out, command="study").acquire()
    t.join(5)
    results["first"].release()
    assert sorted(p.name for p in tmp_path.iterdir()) == []


def test_deferred_puts_every_handler_back_even_when_a_signal_interrupts_it(monkeypatch):
    """A Ctrl-C that arrives while deferred() puts the first handler back raises there: the other
    handlers are put back all the same, so none stays held for good."""
    from pfjax import interrupts

    real, seen = signal.signal, []

    def signal_(sig, handler):
        out = real(sig, handler)
        seen.append(sig)
        if len(seen) == 3:  # the first handler put back (after the two held ones were installed)
            raise KeyboardInterrupt
        return out

    user_term = lambda s, f: None
    before = real(signal.SIGTERM, user_term)
    try:
        monkeypatch.setattr(interrupts.signal, "signal", signal_)
        with pytest.raises(KeyboardInterrupt), interrupts.deferred():
            pass
        monkeypatch.undo()
        assert signal.getsignal(signal.SIGTERM) is user_term and signal.getsignal(signal.SIGINT) is not None
        assert len(seen) == 4
    finally:
        real(signal.SIGTERM, before)


def test_a_signal_held_over_the_final_renames_says_the_output_was_written(tmp_path, monkeypatch, capsys):
    """SIGTERM between the two final renames is acted on after them: the command says its output
    was written (exit 143), and the previous output set aside is removed before."""
    from pfjax import errors
    from pfjax import outputs as outputs_module

    out = tmp_path / "out"
    _write(out, {"a": "v1"})
    real, calls = os.replace, []

    def replace(src, dst):
        calls.append(src)
        if len(calls) == 1:
            os.kill(os.getpid(), signal.SIGTERM)  # arrives between the two renames
        return real(src, dst)

    def body():
        with OutputDir(out, command="study", config_sha256="a" * 64, overwrite=True) as o:
            (o.staging / "a").write_text("v2")
            monkeypatch.setattr(outputs_module.os, "replace", replace)
            o.commit()
        return 0

    before = signal.signal(signal.SIGTERM, signal.SIG_DFL)  # as in a fresh process (a test runner may set its own)
    try:
        assert errors.command_main("pfjax study", body) == EXIT_TERMINATED
    finally:
        signal.signal(signal.SIGTERM, before)
    assert capsys.readouterr().err == f"pfjax study: terminated after writing {out}; its output is complete\n"
    assert (out / "a").read_text() == "v2" and sorted(p.name for p in tmp_path.iterdir()) == ["out"]


def test_a_commands_written_output_is_its_own(tmp_path, monkeypatch, capsys):
    """What a command wrote belongs to that command: an interrupt of a later command, or of an outer
    command after an inner one wrote, says nothing was written; and a Ctrl-C while the guard puts
    its handlers back leaves no state behind (a later command is guarded again)."""
    from pfjax import errors, interrupts

    def commit(name):
        with OutputDir(tmp_path / name, command="study", config_sha256="a" * 64) as o:
            (o.staging / "a").write_text("1")
            o.commit()

    assert errors.command_main("first", lambda: (commit("out1"), 0)[1]) == 0

    def interrupted():
        raise KeyboardInterrupt

    assert errors.command_main("second", interrupted) == EXIT_INTERRUPTED
    assert capsys.readouterr().err == "second: interrupted; nothing was written\n"

    def outer():
        assert errors.command_main("inner", lambda: (commit("inner"), 0)[1]) == 0
        raise KeyboardInterrupt

    assert errors.command_main("outer", outer) == EXIT_INTERRUPTED
    assert capsys.readouterr().err == "outer: interrupted; nothing was written\n"

    real, calls = signal.signal, []

    def signal_(sig, handler):  # a Ctrl-C arrives as the guard puts SIGINT's handler back
        out = real(sig, handler)
        calls.append(sig)
        if sig == signal.SIGINT and handler is signal.default_int_handler:
            raise KeyboardInterrupt
        return out

    monkeypatch.setattr(interrupts.signal, "signal", signal_)
    with pytest.raises(KeyboardInterrupt), interrupts.guard():
        pass
    monkeypatch.undo()
    assert interrupts._running is None and signal.getsignal(signal.SIGINT) is signal.default_int_handler
    with interrupts.guard() as cmd:
        assert cmd is not None  # guarded again
