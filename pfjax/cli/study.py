"""``pfjax study`` and ``pfjax report``: a Monte Carlo robustness study from a TOML config (or a
study packaged with pfjax, ``--example NAME``: :mod:`pfjax.examples`), on one process or several,
and its report rebuilt without simulating."""

from __future__ import annotations

import contextlib
import ctypes
import os
import re
import sys
from pathlib import Path

from pfjax.cli.common import Parser, UsageError, as_flags
from pfjax.errors import InputError, one_line

#: ``--overwrite`` of a command that writes a new output (``pfjax study``, the study scripts)
OVERWRITE_HELP = (
    "replace a pfjax output of another config or command in --out, or one whose files changed since "
    "pfjax wrote them (pfjax never replaces anything it did not write)"
)
#: ``--overwrite`` of ``pfjax report``: the study in --out must be this config's (checked first), so
#: what it allows is only replacing files changed since pfjax wrote them (:func:`_cmd_report`)
REPORT_OVERWRITE_HELP = (
    "rebuild the report even if files in --out changed since pfjax wrote them (an edited report.md, "
    "report.html or redrawn figure is replaced, other files are kept as they are, an edited one then "
    "yours, which later runs refuse to replace); the study in --out "
    "must still be of this config"
)


#: the default ``--out`` of a command whose config has a ``name``, in its help (:func:`default_out`)
NAMED_OUT = "results/<name> (<name>: the config's name)"


def default_out(out, name: str):
    """The output directory a command writes: ``out`` (``--out``), else ``results/<name>`` under the
    current directory (``pfjax study``, ``pfjax report`` and the study scripts alike). An empty
    ``--out ''`` (a variable that was not set) is refused as ``pfjax study`` refuses it
    (:func:`pfjax.outputs.target_path`), never read as the default."""
    from pfjax.outputs import default_target, target_path

    if out is not None:
        target_path(out, "--out")  # an empty or '.'-ending name: InputError naming --out
    return default_target(name, out)


def add_output_flags(parser, *, set_help: str | None, out_default: str, overwrite_help: str = OVERWRITE_HELP) -> None:
    """``--set`` (unless ``set_help`` is None), ``--out`` and ``--overwrite``, with their help texts:
    the flags ``pfjax study``, ``pfjax report`` and the study scripts share."""
    if set_help is not None:
        parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help=set_help)
    parser.add_argument(
        "--out", metavar="DIR", help=f"output directory (default: {out_default}, under the current directory)"
    )
    parser.add_argument("--overwrite", action="store_true", help=overwrite_help)


def first_paragraph(doc: str | None) -> str:
    """A docstring's first paragraph on one line, its reST markup (``:mod:`x```, ````x````) as
    plain text: a parser's description."""
    text = re.split(r"\n\s*\n", (doc or "").strip(), maxsplit=1)[0]
    text = re.sub(r":\w+:`~?([^`]*)`", r"\1", text).replace("``", "")
    return " ".join(text.split())


def start_script(*, x64: bool = True, figures: bool = True) -> None:
    """The start of a study script (``studies/*.py``), before anything imports the simulator (importing
    this module has imported :mod:`pfjax`: one CPU device per core): float64 for the whole process (``x64``: the
    studies compare to references at 1e-9), pfjax's persistent compilation cache
    (:func:`pfjax.cache.enable`), and figures drawn without a display (``figures``: matplotlib's Agg)."""
    import jax

    import pfjax.cache

    if x64:
        jax.config.update("jax_enable_x64", True)
    pfjax.cache.enable()
    if figures:
        import matplotlib

        matplotlib.use("Agg")


def script_parser(doc: str | None, *, config: Path | None, out_default: str, quick: str) -> Parser:
    """The parser of a study script (``studies/*.py``): its docstring's first paragraph as the
    description; ``--config`` (default ``config``, the TOML beside the script) and ``--set`` (both
    left out where ``config`` is None: a script without a config), ``--out`` (default
    ``out_default`` under the current directory, as ``pfjax study``; :func:`default_out`),
    ``--quick`` (``quick``: what it shrinks) and ``--overwrite``."""
    ap = Parser(description=first_paragraph(doc))
    if config is not None:
        ap.add_argument(
            "--config",
            metavar="TOML",
            default=str(config),
            help=f"the study's config, a TOML file (default {config.name} beside this script)",
        )
    add_output_flags(
        ap,
        set_help=None
        if config is None
        else "override a config value, applied after --config and --quick: a dotted key (table.key) or "
        "list item (key[0].name) and a TOML value (repeatable)",
        out_default=out_default,
    )
    ap.add_argument("--quick", action="store_true", help=quick)
    return ap


def add_study_flags(parser, config_help: str) -> None:
    """The study a command reads: the positional CONFIG (``config_help``) or ``--example NAME``, a
    study packaged with pfjax (:func:`load_study_flags` reads them)."""
    parser.add_argument("config", nargs="?", help=f"{config_help}; or give --example NAME instead")
    parser.add_argument(
        "--example",
        metavar="NAME",
        help="a study packaged with pfjax instead of CONFIG (pfjax examples lists them: default, heldout, ...)",
    )


def _config(args):
    """The study TOML the flags name: the CONFIG path, or the packaged example ``--example NAME``
    (one of the two)."""
    if args.example is None:
        if args.config is None:
            raise UsageError("config: expected a study TOML path or --example NAME (pfjax examples lists them)")
        return args.config
    if args.config is not None:
        raise UsageError(f"--example: give a study TOML ({args.config}) or --example {args.example}, not both")
    from pfjax import examples

    if args.example not in examples.FILES:
        raise UsageError(f"--example: unknown example {args.example!r}; expected one of {', '.join(examples.names())}")
    return examples.path(args.example)


def _source(args) -> str:
    """How the command line named the study, for messages."""
    return f"--example {args.example}" if args.example is not None else str(args.config)


def load_study_flags(args):
    """The study of :func:`add_study_flags`' CONFIG or ``--example``, with ``--set`` applied."""
    from pfjax.montecarlo.config import load_study

    spec, _ = load_study(_config(args), args.set)
    return spec


#: The per-controller numbers of ``pfjax study --json``.
HEADLINE = (
    "success_rate",
    "success_ci95",
    "iae_mean",
    "iae_p95",
    "steady_abs_d_p95",
    "slip_margin_deg",
    "slip_margin_fails_at_deg",
)


def _headline(summary: dict, out) -> dict:
    """``pfjax study --json``: the summary's headline numbers, with their units (summary.json's)."""
    units = summary.get("units", {})
    return {
        "study": summary["study"],
        "out": str(out),
        "n_runs_total": summary["n_runs_total"],
        "seed": summary["seed"],
        "config_sha256": summary["config_sha256"],
        "wall_s": summary["wall_s"],
        "controllers": {k: {f: c[f] for f in HEADLINE} for k, c in summary["controllers"].items()},
        "units": {f: units[f] for f in ("n_runs_total", "seed", "wall_s", *HEADLINE) if f in units},
    }


@contextlib.contextmanager
def _stdout_to_stderr(active: bool):
    """Send everything written to file descriptor 1 (by Python or by C++ libraries) to stderr."""
    if not active:
        yield
        return
    sys.stdout.flush()
    saved = os.dup(1)
    os.dup2(2, 1)
    try:
        yield
    finally:
        sys.stdout.flush()
        ctypes.CDLL(None).fflush(None)  # C stdio buffers (std::cout writes through them)
        os.dup2(saved, 1)
        os.close(saved)


#: The library's names of the distributed run's settings, by flag (:func:`pfjax.sim.sharding.check_distributed`).
DISTRIBUTED_FLAGS = {
    "coordinator": "--coordinator",
    "num_processes": "--num-processes",
    "process_id": "--process-id",
    "timeout_s": "--coordinator-timeout",
}


def _joining(args) -> bool:
    """Whether the flags ask to join a multi-process study."""
    return args.distributed or any(v is not None for v in (args.coordinator, args.num_processes, args.process_id))


def _distributed(args) -> tuple[int, int]:
    """Join a multi-process study if the flags ask for one; ``(process index, process count)``."""
    from pfjax.sim import sharding

    flags = {"--coordinator": args.coordinator, "--num-processes": args.num_processes, "--process-id": args.process_id}
    given = [k for k, v in flags.items() if v is not None]
    with as_flags(DISTRIBUTED_FLAGS):  # --coordinator-timeout given alone too
        sharding.check_distributed(args.coordinator, args.num_processes, args.process_id, args.coordinator_timeout)
    if not _joining(args):
        return 0, 1
    if given and len(given) < 3:
        missing = next(k for k, v in flags.items() if v is None)
        raise UsageError(
            f"{missing}: required with {given[0]} (give --coordinator, --num-processes and --process-id "
            f"together, or --distributed to detect them)"
        )
    import jax

    try:
        with as_flags(DISTRIBUTED_FLAGS):
            sharding.initialize_distributed(
                args.coordinator, args.num_processes, args.process_id, timeout_s=args.coordinator_timeout
            )
    except InputError:
        raise
    except Exception as e:  # no cluster to detect, or JAX refused the settings
        flag = "--coordinator" if given else "--distributed"
        raise UsageError(f"{flag}: could not join the distributed run ({one_line(e)})") from None
    return jax.process_index(), jax.process_count()


def _cmd_study(args) -> dict:
    # A distributed run's libraries (Gloo) print to stdout: there it carries only the result (--json)
    with _stdout_to_stderr(_joining(args)):
        return _study(args)


def _study(args) -> dict:
    from pfjax.montecarlo.checks import check_resources
    from pfjax.montecarlo.runner import study_output
    from pfjax.outputs import check_target
    from pfjax.report import figure_worker

    spec = load_study_flags(args)
    default_out(args.out, spec.name)  # --out checked as given (an empty one is not '.')
    check_resources(spec, report=not args.no_report)  # every process alike, before any joins
    # one process: --out refused before anything starts; several: by process 0 once all have joined,
    # which tells the others (pfjax.montecarlo.processes), so that none waits for a process that stopped
    output = None if _joining(args) else study_output(spec, args.out, overwrite=args.overwrite)
    index, count = _distributed(args)
    lead = index == 0  # the process that writes; the others only lend their devices
    if count > 1:
        from pfjax.montecarlo.processes import check_same_study

        check_same_study(spec)  # every process stops alike if another was given another config or --set
    if lead and output is None:
        from pfjax.montecarlo.processes import refused

        with refused(count):
            output = study_output(spec, args.out, overwrite=args.overwrite)
    if lead and count == 1:  # refused before anything starts (several processes: process 0 tells the others)
        assert output is not None
        check_target(
            output.target, command=output.command, config_sha256=output.config_sha256, overwrite=args.overwrite
        )
    report = not args.no_report and lead
    # the figure worker imports matplotlib while this process imports JAX (both about 2 s)
    worker = figure_worker.FigureWorker() if report and not args.no_overlap and figure_worker.enabled() else None
    from pfjax.montecarlo.study import run

    warn = lambda m: print(f"pfjax study: warning: {m}", file=sys.stderr)
    if not lead:  # simulates process 0's unfinished chunks with it, keeps nothing
        if worker is not None:
            worker.close()
        from pfjax.montecarlo.processes import follow

        return {"process_index": index, "process_count": count, "written_by": "process 0", "chunks": follow(spec)}
    assert output is not None  # process 0 has opened it (or refused above)
    summary = run(
        spec,
        output,
        progress=None if not args.quiet else False,
        report=report,
        fresh=args.fresh,
        warn=warn,
        overlap=not args.no_overlap,
        worker=worker,
        distributed=count > 1,
    )
    head = _headline(summary, output.target)
    head.update(warnings=summary.get("warnings", []), chunks=summary.get("chunks"))
    if count > 1:
        head.update(process_count=count)
    return head


def _cmd_report(args) -> dict:
    import shlex

    from pfjax.montecarlo.config import study_hash
    from pfjax.montecarlo.study import rewrite_report, study_marker

    spec = load_study_flags(args)
    out = default_out(args.out, spec.name)
    again = [*(a for kv in args.set for a in ("--set", kv)), *(("--out", str(args.out)) if args.out else ())]
    command = " ".join(["pfjax study", _source(args), *map(shlex.quote, again)])
    marker = study_marker(out, "--out", f"run `{command}` first")
    if marker.get("config_sha256") != study_hash(spec):
        raise UsageError(
            f"config: {_source(args)}{' (with --set)' if args.set else ''} does not match the study in {out} "
            "(config hash differs)"
        )
    report = rewrite_report(out, spec, overwrite=args.overwrite) / "report.html"
    return {"report": str(report), "config_sha256": marker["config_sha256"]}  # the study's, which it matched


def register(sub) -> None:
    for name, helptext in (
        ("study", "run a Monte Carlo robustness study from a TOML config (runs, margins, summary, report)"),
        ("report", "rebuild the report (report.md and report.html) of a finished study without re-simulating"),
    ):
        st = sub.add_parser(name, help=helptext, description=helptext)
        add_study_flags(st, "study TOML (e.g. studies/robustness_default.toml)")
        add_output_flags(
            st,
            set_help="override a config value; dotted keys, list items as controllers[0].gains.k (repeatable)",
            out_default=NAMED_OUT,
            overwrite_help=OVERWRITE_HELP if name == "study" else REPORT_OVERWRITE_HELP,
        )
        if name == "study":
            st.add_argument(
                "--no-report", action="store_true", help="skip the report (report.md, report.html and figures/)"
            )
            st.add_argument("--quiet", action="store_true", help="no progress bar")
            st.add_argument(
                "--no-overlap",
                action="store_true",
                help="run the worst-case search and the float64 check after the runs instead of "
                "alongside them in a background thread (same results; slower)",
            )
            st.add_argument(
                "--fresh",
                action="store_true",
                help="discard the finished chunks of an interrupted run into --out and start over "
                "(default: resume them; refused if the config changed)",
            )
            dist = st.add_argument_group(
                "several processes or hosts",
                "every process runs the same command with its own --process-id; "
                "the runs are sharded over the devices of all of them and process 0 writes the results "
                "(and resumes an interrupted run from its --out; the others follow it)",
            )
            dist.add_argument("--coordinator", metavar="HOST:PORT", help="address of process 0 (jax.distributed)")
            dist.add_argument("--num-processes", type=int, metavar="N", help="number of processes")
            dist.add_argument("--process-id", type=int, metavar="I", help="this process, 0..N-1 (0 writes)")
            dist.add_argument(
                "--coordinator-timeout",
                type=float,
                default=60.0,
                metavar="S",
                help="seconds to wait for the coordinator and the other processes (default 60)",
            )
            dist.add_argument(
                "--distributed",
                action="store_true",
                help="join a distributed run whose coordinator, size and rank JAX detects (SLURM, Open MPI)",
            )
        st.add_argument("--json", action="store_true", help="print one JSON object")
        st.set_defaults(func=_cmd_study if name == "study" else _cmd_report)
