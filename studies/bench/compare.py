"""Compare the benchmark of two revisions: ``python studies/bench/compare.py [BASE] [NEW] [--rounds 5]``.

Each revision (a git commit, branch or tag, or ``.`` for the working tree) is checked out into a
temporary git worktree and ``pfjax bench --json`` is run in it, the two alternately in one sitting,
``BASE`` first in odd rounds and ``NEW`` first in even ones (``BASE NEW``, ``NEW BASE``, ``BASE
NEW``, ...: :func:`order`), so that a slow period of the machine, or a trend in its load, slows
both alike. The summary gives, per precision, every round's million rollout-steps per second of
both, the ratio NEW / BASE of each round, its median and its spread (min-max), and the same for the
gradient's cost over the forward pass; a change to the simulator states its effect with it.

Writes ``results/bench_compare/`` (``compare.json``: every round's bench summary, the order the two
ran in each round and the ratios, with the machine, both commits, the seed of the benchmark's batch,
the comparing pfjax's version and the ``units`` of its numbers (:func:`result_units`);
``report.md``) through the one output writer.
Bad input (an unknown revision, a bad count, ``--sizes`` that ``pfjax bench`` would refuse) stops
with one line and exit code 2 before anything runs; so does a ``pfjax bench`` of either revision
that refuses its arguments. A benchmark that fails, or in which a reference disagrees with pfjax on
the per-run IAE (its summary's ``agreement``, whatever the exit code of that revision's ``pfjax
bench``: a ratio of rates of which one solves another problem compares nothing), stops the
comparison with one line naming the round, the revision and the reference (exit 1); the complete
rounds before it are written, marked ``incomplete`` (nothing is written when it is the first).
"""

from __future__ import annotations

import json
import os
import signal
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

import pfjax  # noqa: F401  (before JAX: one CPU device per core)
from pfjax import errors
from pfjax.bench.report import CONFIG_UNITS, MACHINE_UNITS, RATE, summary_units
from pfjax.bench.run import disagreement, machine
from pfjax.cli.bench import EXIT_DISAGREE
from pfjax.cli.bench import config as bench_config
from pfjax.cli.common import Parser
from pfjax.cli.records import units
from pfjax.errors import InputError, command_main
from pfjax.jsonio import dumps
from pfjax.outputs import OutputDir
from pfjax.provenance import config_hash, stamp
from pfjax.report.markdown import table

ROOT = Path(__file__).resolve().parents[2]
#: The bench summary's keys compared (higher is better for the rates, lower for the gradient cost).
RATES = ("msteps_per_s_f32", "msteps_per_s_f64")
COSTS = ("grad_over_forward",)
#: ``--sizes`` without ``--quick`` when none is given: the sizes of the performance goals.
SIZES = "10000,100000"
#: The start of a ``pfjax bench`` error line (:func:`pfjax.errors.command_main`).
_BENCH_ERROR = "pfjax bench: error: "


class BenchFailed(Exception):
    """A ``pfjax bench`` of one revision failed (not for bad input): the message is one line."""


def _git(*args: str, cwd: Path = ROOT) -> str:
    return subprocess.run(["git", *args], cwd=cwd, capture_output=True, text=True, check=True).stdout.strip()


def _commit(rev: str, key: str) -> str:
    """The commit ``rev`` names, or ``"."`` (the working tree); InputError naming ``key`` otherwise."""
    if rev == ".":
        return "."
    try:
        return _git("rev-parse", "--verify", "--quiet", f"{rev}^{{commit}}")
    except subprocess.CalledProcessError:
        raise InputError(f"{key}: {rev!r} is not a commit of this repository", key) from None


def _identity(commit: str) -> dict:
    """What was measured: ``{"commit"}`` for a commit; for the working tree (``"."``) its ``HEAD``
    and the SHA-256 of its changes against it (``git diff HEAD`` and the untracked files' names and
    contents), so that another state of the tree is another comparison (another config hash)."""
    if commit != ".":
        return {"commit": commit}
    import hashlib

    h = hashlib.sha256(_git("diff", "HEAD", "--binary").encode())
    for name in _git("ls-files", "--others", "--exclude-standard").splitlines():
        h.update(name.encode())
        try:
            h.update((ROOT / name).read_bytes())
        except OSError:
            pass
    return {"commit": "working tree", "head": _git("rev-parse", "HEAD"), "changes_sha256": h.hexdigest()}


class _Tree:
    """A checkout of one revision (a temporary worktree; the repository itself for ``"."``)."""

    def __init__(self, commit: str, parent: Path, role: str):
        self.commit = commit
        if commit == ".":
            self.path, self._temporary = ROOT, False
        else:  # by role too: BASE and NEW may name the same commit (a comparison of the noise)
            self.path, self._temporary = parent / f"{role}-{commit[:12]}", True
            _git("worktree", "add", "--detach", "--quiet", str(self.path), commit)

    def bench(self, args: list[str], out: Path) -> dict:
        """One ``pfjax bench --json`` of this checkout (its own code: ``PYTHONPATH``); its summary.
        :class:`~pfjax.errors.InputError` when it refuses its arguments (exit 2), :class:`BenchFailed`
        when a reference disagrees with pfjax (the summary's agreement, whatever the exit code: a
        revision's pfjax bench may exit 0 on it) or it fails otherwise."""
        env = {**os.environ, "PYTHONPATH": str(self.path)}
        cmd = [sys.executable, "-m", "pfjax.cli", "bench", *args, "--out", str(out), "--json"]
        r = subprocess.run(cmd, cwd=self.path, env=env, capture_output=True, text=True)
        where = "the working tree" if self.commit == "." else self.commit[:12]
        tail = (r.stderr.strip().splitlines() or ["(no output)"])[-1]
        if r.returncode == errors.EXIT_USAGE:
            raise InputError(f"{tail.removeprefix(_BENCH_ERROR)} (pfjax bench of {where})")
        summary = _summary(r.stdout) if r.returncode in (0, EXIT_DISAGREE) else None
        if summary is not None and disagreement(summary):
            raise BenchFailed(f"pfjax bench of {where}: references disagree with pfjax: {disagreement(summary)}")
        if r.returncode != 0 or summary is None:
            raise BenchFailed(f"pfjax bench of {where} failed (exit {r.returncode}): {tail}")
        return summary

    def remove(self) -> None:
        if self._temporary:
            _git("worktree", "remove", "--force", str(self.path))


def _summary(stdout: str) -> dict | None:
    """The summary ``pfjax bench --json`` printed (one JSON object), or None."""
    try:
        summary = json.loads(stdout)
    except ValueError:
        return None
    return summary if isinstance(summary, dict) else None


def order(i: int) -> tuple[str, str]:
    """The order the two revisions run in round ``i`` (from 0): BASE first in even ``i`` (the odd
    rounds counted from 1), NEW first in odd ``i``."""
    return ("base", "new") if i % 2 == 0 else ("new", "base")


def _spread(values: list[float]) -> dict:
    return {"median": statistics.median(values), "min": min(values), "max": max(values)}


def compare(rounds: list[dict]) -> dict:
    """Per key: NEW / BASE of every round, their median and spread (``rounds``: ``{"base", "new"}``
    bench summaries)."""
    out = {}
    for key in RATES + COSTS:
        pairs = [(r["base"].get(key), r["new"].get(key)) for r in rounds]
        ratios = [n / b for b, n in pairs if b and n]
        out[key] = {
            "base": [b for b, _ in pairs],
            "new": [n for _, n in pairs],
            "ratio_new_over_base": ratios,
            **({"ratio": _spread(ratios)} if ratios else {}),
        }
    return out


def result_units(result: dict) -> dict:
    """``compare.json``'s ``units`` (:func:`pfjax.cli.records.units`): the rates in
    :data:`~pfjax.bench.report.RATE`, the gradient's cost and every ratio ``"1"``, each round's bench
    summaries by :func:`~pfjax.bench.report.summary_units`, the machine's numbers by
    :data:`~pfjax.bench.report.MACHINE_UNITS`, the round counts and the seed."""
    table: dict = {**MACHINE_UNITS, "rounds": "rounds", "rounds_requested": "rounds", "seed": CONFIG_UNITS["seed"]}
    for key in RATES + COSTS:
        unit = RATE if key in RATES else "1"
        table[f"comparison.{key}.*"] = {"base": unit, "new": unit, "ratio_new_over_base": "1"}
        table[f"comparison.{key}.ratio.*"] = dict.fromkeys(("median", "min", "max"), "1")
    for r in result["bench_summaries"]:
        for name, summary in r.items():
            table.update(summary_units(summary, f"bench_summaries.{name}."))
            table.update({f"bench_summaries.{name}.{k}": u for k, u in MACHINE_UNITS.items()})
    return units(result, table)


def markdown(result: dict) -> str:
    rows = []
    for key, c in result["comparison"].items():
        if "ratio" not in c:
            continue
        s = c["ratio"]
        rows.append(
            [
                key,
                " / ".join(f"{v:.3g}" for v in c["base"]),
                " / ".join(f"{v:.3g}" for v in c["new"]),
                f"{s['median']:.3f}",
                f"{s['min']:.3f}-{s['max']:.3f}",
            ]
        )
    m = result["machine"]
    return "\n".join(
        [
            "# Benchmark comparison",
            "",
            f"BASE `{result['base']['rev']}` ({result['base']['commit'][:12]}) against NEW `{result['new']['rev']}` "
            f"({result['new']['commit'][:12]}), {result['rounds']} rounds of `pfjax bench "
            f"{' '.join(result['bench_args'])}` on {m.get('cpu_model') or m.get('processor')}, {m.get('cpus')} CPUs, "
            "BASE first in odd rounds and NEW first in even ones.",
            "",
            *(
                [
                    f"**Incomplete**: {result['rounds']} of {result['rounds_requested']} rounds; {result['incomplete']}.",
                    "",
                ]
                if result.get("incomplete")
                else []
            ),
            table(["quantity", "BASE per round", "NEW per round", "NEW / BASE median", "spread"], rows),
            "",
            "Rates are million rollout-steps per second (higher is better); `grad_over_forward` is the "
            "gradient's cost in forward passes (lower is better).",
            "",
        ]
    )


def main(argv=None) -> int:
    ap = Parser(description=__doc__.splitlines()[0])
    ap.add_argument("base", nargs="?", default="HEAD", help="the revision compared against (default HEAD)")
    ap.add_argument("new", nargs="?", default=".", help="the revision compared (default . : the working tree)")
    ap.add_argument("--rounds", type=int, default=5, help="alternating rounds (default 5)")
    ap.add_argument(
        "--sizes",
        default=None,
        help=f"pfjax batch sizes, as pfjax bench's --sizes (default {SIZES}; with --quick, pfjax bench --quick's)",
    )
    ap.add_argument("--quick", action="store_true", help="pfjax bench --quick (small batches, 2 s horizon)")
    ap.add_argument("--out", default="results/bench_compare", help="output directory (default results/bench_compare)")
    ap.add_argument("--overwrite", action="store_true", help="replace a pfjax output of another config in --out")
    args = ap.parse_args(argv)
    # SIGTERM (kill, timeout, a batch system) as an exit, so that the worktrees are removed (finally)
    signal.signal(signal.SIGTERM, lambda signum, frame: sys.exit(128 + signum))
    return command_main("bench-compare", lambda: main_checked(args))


def bench_arguments(args) -> list[str]:
    """The arguments of every ``pfjax bench``, checked as pfjax bench checks them (a one-line
    :class:`~pfjax.errors.InputError` naming the flag): ``--sizes`` only where given (else
    :data:`SIZES` without ``--quick``; ``--quick``'s own sizes with it)."""
    sizes = args.sizes if args.sizes is not None or args.quick else SIZES
    bench_config(args.quick, sizes)
    return (["--sizes", sizes] if sizes is not None else []) + (["--quick"] if args.quick else [])


def main_checked(args) -> int:
    errors.integer("--rounds", args.rounds, low=1, high=100)
    bench_args = bench_arguments(args)
    base, new = _commit(args.base, "base"), _commit(args.new, "new")
    trees_measured = {k: _identity(c) for k, c in (("base", base), ("new", new))}
    cfg = {**trees_measured, "rounds": args.rounds, "bench_args": bench_args}
    with OutputDir(args.out, command="bench-compare", config_sha256=config_hash(cfg), overwrite=args.overwrite) as out:
        rounds, failure = [], None
        with tempfile.TemporaryDirectory(prefix="pfjax-compare-") as tmp:
            trees: dict = {}
            try:
                trees["base"] = _Tree(base, Path(tmp), "base")
                trees["new"] = _Tree(new, Path(tmp), "new")
                for i in range(args.rounds):
                    ran = {name: trees[name].bench(bench_args, Path(tmp) / f"bench-{name}-{i}") for name in order(i)}
                    rounds.append({name: ran[name] for name in ("base", "new")})
                    print(f"round {i + 1}/{args.rounds} done", file=sys.stderr, flush=True)
            except BenchFailed as e:
                failure = f"round {len(rounds) + 1}/{args.rounds}: {e}"
            except InputError as e:  # a revision's pfjax bench refused its arguments
                if not rounds:
                    raise
                failure = f"round {len(rounds) + 1}/{args.rounds}: {errors.one_line(e)}"
            finally:
                for tree in trees.values():
                    tree.remove()
        if failure is not None and not rounds:
            print(f"bench-compare: error: {failure}; nothing was measured or written", file=sys.stderr)
            return 1
        # the seed of pfjax bench's batch (compare passes none: pfjax bench's default) and this
        # checkout's pfjax version (each bench summary carries its own revision's)
        prov = stamp(cfg, bench_config(args.quick).seed)
        result = {
            "base": {"rev": args.base, **trees_measured["base"]},
            "new": {"rev": args.new, **trees_measured["new"]},
            "rounds": len(rounds),
            "rounds_requested": args.rounds,
            **({"incomplete": failure} if failure is not None else {}),
            "bench_args": bench_args,
            "order": [list(order(i)) for i in range(len(rounds))],  # the revisions of each round, in turn
            "comparison": compare(rounds),
            "bench_summaries": rounds,
            "machine": machine(),
            "config_sha256": prov["config_sha256"],
            "seed": prov["seed"],
            "pfjax_version": prov["pfjax_version"],
        }
        result["units"] = result_units(result)
        (out.staging / "compare.json").write_text(dumps(result) + "\n")
        (out.staging / "report.md").write_text(markdown(result))
        path = out.commit()
    ratios = {k: c.get("ratio") for k, c in result["comparison"].items()}
    print(dumps({"out": str(path), "rounds": len(rounds), "ratios": ratios}))
    if failure is not None:
        print(
            f"bench-compare: error: {failure}; the {len(rounds)} complete round(s) are written to {path}",
            file=sys.stderr,
        )
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
