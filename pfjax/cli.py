"""The ``pfjax`` command line.

    pfjax synth --method {mixed,hinf,h2} [--v 1 --L 0.2 --alpha 10 --beta 1] [--json]
    pfjax simulate --path {line,parabola,sine,circle} [--x0 X Y THETA] [--beta-r-deg B] [--beta-f-deg B]
                   --controller {mixed,paper-k,pi,stanley,pure-pursuit,rear-wheel} [--gains G,...] [--T 20] [--json]

Bad arguments print one line naming the flag, the value and what was expected, and exit with
code 2 before anything is computed or written. A run that fails numerically is reported in
its ``status``; it is not an error.
"""

from __future__ import annotations

import argparse
import contextlib
import ctypes
import importlib
import json
import math
import os
import re
import sys
from pathlib import Path

from pfjax.errors import EXIT_USAGE, InputError, command_main, one_line
from pfjax.jsonio import dumps

CONTROLLER_CHOICES = ("mixed", "paper-k", "pi", "stanley", "pure-pursuit", "rear-wheel")
#: CLI controller name -> (registry name, gain names in --gains order)
GAIN_NAMES = {
    "mixed": ("state_feedback", ("k_d", "k_theta")),
    "paper-k": ("state_feedback", ("k_d", "k_theta")),
    "pi": ("pi", ("kp_d", "ki_d", "kp_theta", "ki_theta", "k_aw")),
    "stanley": ("stanley", ("k", "k_soft")),
    "pure-pursuit": ("pure_pursuit", ("ld_gain", "ld_min")),
    "rear-wheel": ("rear_wheel", ("k_theta", "k_d")),
}


#: Modules that add subcommands: each has ``register(sub)`` which calls ``sub.add_parser(...)``
#: (the parser class is this module's ``_Parser``) and ``set_defaults(func=...)``; ``func(args)``
#: returns a dict (printed as JSON with ``--json``) and raises :class:`UsageError` for bad values.
EXTENSIONS = ("pfjax.tuning.cli", "pfjax.parking.cli", "pfjax.tracking.cli", "pfjax.bench.cli")


class UsageError(InputError):
    """A bad command-line value; the message names the flag."""


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # one line, exit code 2 (argparse's own convention)
        self.exit(EXIT_USAGE, f"{self.prog}: error: {message}\n")


def _finite(flag: str, value: float, *, positive=False, below=None, unit="") -> float:
    """A flag's number checked as the library checks numbers (:func:`pfjax.errors.number`)."""
    from pfjax import errors

    return errors.number(flag, value, positive=positive, below=below, unit=unit)


@contextlib.contextmanager
def as_flags(flags: dict[str, str]):
    """Name flags, not the library's argument names, in the library's one-line errors: an
    :class:`~pfjax.errors.InputError` whose key (its first part, ``gains`` of ``gains.kp_d``) is in
    ``flags`` is raised again as ``<flag>: <rest of the key>: <message>``. The checks themselves
    are the library's, so the command line and the Python API judge a value alike."""
    try:
        yield
    except InputError as e:
        key, text = e.key or "", str(e)
        base = re.split(r"[.\[]", key, maxsplit=1)[0]
        if base not in flags:
            raise
        body = text[len(key) + 2:] if text.startswith(key + ": ") else text
        for name, other in flags.items():  # other settings the message mentions, by their flags too
            if len(name) > 1:
                body = re.sub(rf"(?<![\w.-]){re.escape(name)}(?![\w.-])", other, body)
        sub = key[len(base):]
        flag = flags[base] + (sub if sub.startswith("[") else "")
        sub = "" if sub.startswith("[") else sub.lstrip(".")
        raise UsageError(f"{flag}: {sub + ': ' if sub else ''}{body}", flags[base]) from None


# --------------------------------------------------------------------------- synth


SYNTH_FLAGS = {"method": "--method", "v": "--v", "L": "--L", "alpha": "--alpha", "beta": "--beta",
               "max_real": "--max-real", "disk_center": "--disk", "disk_radius": "--disk"}


def _cmd_synth(args) -> dict:
    from pfjax.synthesis import PoleRegion, SynthesisError, synthesize

    region = None
    with as_flags(SYNTH_FLAGS):
        if args.sector_deg is not None and not 0 < _finite("--sector-deg", args.sector_deg) < 90:
            raise UsageError(f"--sector-deg: expected a half-angle in (0, 90), got {args.sector_deg:g}")
        if args.max_real is not None or args.disk is not None or args.sector_deg is not None:
            region = PoleRegion(
                max_real=args.max_real,
                disk_center=None if args.disk is None else args.disk[0],
                disk_radius=None if args.disk is None else args.disk[1],
                sector_angle=None if args.sector_deg is None else math.radians(args.sector_deg),
            )
        try:
            design = synthesize(args.method, v=args.v, L=args.L, alpha=args.alpha, beta=args.beta, region=region)
        except SynthesisError as e:
            flags = "--max-real/--disk/--sector-deg" if region is not None else f"--method {args.method}"
            raise UsageError(f"{flags}: no design exists ({e})") from None
    out = design.to_dict()
    out.update(v=args.v, L=args.L)
    return out


# --------------------------------------------------------------------------- simulate


def _parse_gains(controller: str, text: str | None) -> dict:
    """``--gains``: every gain of the controller as comma-separated numbers in order, or some of
    them as ``name=value`` pairs (the others keep their defaults); values checked by the library."""
    names = GAIN_NAMES[controller][1]
    if text is None:
        return {}
    parts = [p.strip() for p in text.split(",")]
    if not any(parts):
        raise UsageError(f"--gains: empty; expected {','.join(names)} or name=value pairs")
    if "" in parts:
        raise UsageError(f"--gains: an empty item in {text!r}")
    named = ["=" in p for p in parts]
    if any(named) and not all(named):
        raise UsageError(f"--gains: mixes name=value pairs and bare numbers in {text!r}; use one form")
    if all(named):
        pairs = [tuple(s.strip() for s in p.split("=", 1)) for p in parts]
    else:
        if len(parts) != len(names):
            raise UsageError(f"--gains: expected all {len(names)} gains of --controller {controller} in order "
                             f"({','.join(names)}), got {len(parts)}; give some as name=value pairs instead")
        pairs = list(zip(names, parts))
    out = {}
    for k, v in pairs:
        if k not in names:
            raise UsageError(f"--gains: unknown gain {k!r} for --controller {controller}; expected {', '.join(names)}")
        if k in out:
            raise UsageError(f"--gains: {k} is given twice")
        try:
            out[k] = float(v)
        except ValueError:
            raise UsageError(f"--gains: {k}={v!r} is not a number") from None
    return out


def _controller_and_gains(args):
    from pfjax import controllers as C

    registry_name, names = GAIN_NAMES[args.controller]
    given = _parse_gains(args.controller, args.gains)
    controller, factory = C.REGISTRY[registry_name]
    with as_flags({"gains": "--gains", "K": "--gains"}):
        if args.controller in ("mixed", "paper-k"):
            if given:
                K = (given.get("k_d", C.PAPER_K[0]), given.get("k_theta", C.PAPER_K[1]))
            elif args.controller == "paper-k":
                K = C.PAPER_K
            else:
                from pfjax.synthesis import synthesize

                with as_flags(SYNTH_FLAGS):
                    K = tuple(float(k) for k in synthesize("mixed", v=args.v, L=args.L).K.ravel())
            gains = factory(K=K)
            shown = {"k_d": K[0], "k_theta": K[1]}
        else:
            gains = factory(**given)
            shown = {k: float(v) for k, v in gains._asdict().items()}
    return controller, gains, shown


#: ``pfjax simulate``'s flags by the library argument they set.
SIMULATE_FLAGS = {"v": "--v", "L": "--L", "beta_r_deg": "--beta-r-deg", "beta_f_deg": "--beta-f-deg",
                  "delta_max_deg": "--delta-max-deg", "pose0": "--x0", "horizon": "--T", "dt": "--dt",
                  "control_every": "--control-every", "convention": "--convention", "gains": "--gains"}


def _cmd_simulate(args) -> dict:
    import numpy as np

    from pfjax.metrics import METRIC_NAMES
    from pfjax.scenarios import SCENARIOS, paper_scenario
    from pfjax.sim import STATUS_NAMES, SimConfig, simulate_batch, stack, unstack

    if args.continuous and args.control_every is not None:
        raise UsageError("--control-every: not with --continuous (a continuous controller is evaluated inside every "
                         "RK4 stage, not sampled)")
    with as_flags(SIMULATE_FLAGS):
        cfg = SimConfig(dt=args.dt, horizon=args.T, record=False,
                        control_every=None if args.continuous else (1 if args.control_every is None else args.control_every))
        controller, gains, shown = _controller_and_gains(args)
        sc = paper_scenario(
            args.path, gains, beta_r_deg=args.beta_r_deg, beta_f_deg=args.beta_f_deg,
            pose0=None if args.x0 is None else tuple(args.x0), v=args.v, L=args.L,
            delta_max_deg=args.delta_max_deg, convention=args.convention,
        )
    r = unstack(simulate_batch(stack([sc]), controller=controller, config=cfg), 0)
    status = int(r.status)
    metrics = {k: (bool if k == "success" else float)(getattr(r.metrics, k)) for k in METRIC_NAMES}
    metrics["status"] = STATUS_NAMES[status]
    x0 = SCENARIOS[args.path][1] if args.x0 is None else args.x0
    return {
        "path": args.path,
        "controller": args.controller,
        "gains": shown,
        "x0": {"x": x0[0], "y": x0[1], "theta": x0[2]},
        "beta_r": math.radians(args.beta_r_deg),
        "beta_f": math.radians(args.beta_f_deg),
        "T": cfg.n_steps * cfg.dt,
        "dt": cfg.dt,
        "final": {k: float(v) for k, v in r.final._asdict().items()},
        "metrics": metrics,
        "status_code": status,
        "fail_time": float(r.fail_time) if np.isfinite(r.fail_time) else None,
    }


# --------------------------------------------------------------------------- study / report


def _load_study_or_usage(args):
    from pfjax.montecarlo.config import load_study

    spec, _ = load_study(args.config, args.set)
    return spec


def _headline(summary: dict, out) -> dict:
    return {
        "study": summary["study"], "out": str(out), "n_runs_total": summary["n_runs_total"], "seed": summary["seed"],
        "config_sha256": summary["config_sha256"], "wall_s": summary["wall_s"],
        "controllers": {k: {f: c[f] for f in ("success_rate", "success_ci95", "iae_mean", "iae_p95", "steady_abs_d_p95",
                                               "slip_margin_deg", "slip_margin_fails_at_deg")}
                        for k, c in summary["controllers"].items()},
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


def _distributed(args) -> tuple[int, int]:
    """Join a multi-process study if the flags ask for one; ``(process index, process count)``."""
    flags = {"--coordinator": args.coordinator, "--num-processes": args.num_processes, "--process-id": args.process_id}
    given = [k for k, v in flags.items() if v is not None]
    if not given and not args.distributed:
        return 0, 1
    if given and len(given) < 3:
        missing = next(k for k, v in flags.items() if v is None)
        raise UsageError(f"{missing}: required with {given[0]} (give --coordinator, --num-processes and --process-id "
                         f"together, or --distributed to detect them)")
    if given:
        host, _, port = args.coordinator.rpartition(":")
        if not host or not port.isdigit():
            raise UsageError(f"--coordinator: expected HOST:PORT, got {args.coordinator!r}")
        if args.num_processes < 1:
            raise UsageError(f"--num-processes: expected >= 1, got {args.num_processes}")
        if not 0 <= args.process_id < args.num_processes:
            raise UsageError(f"--process-id: expected 0..{args.num_processes - 1}, got {args.process_id}")
    timeout = _finite("--coordinator-timeout", args.coordinator_timeout, positive=True, unit=" s")
    import jax

    from pfjax.sim import sharding

    try:
        with as_flags({"coordinator": "--coordinator"}):
            sharding.initialize_distributed(args.coordinator, args.num_processes, args.process_id, timeout_s=timeout)
    except InputError:
        raise
    except Exception as e:  # no cluster to detect, or JAX refused the settings
        flag = "--coordinator" if given else "--distributed"
        raise UsageError(f"{flag}: could not join the distributed run ({one_line(e)})") from None
    return jax.process_index(), jax.process_count()


def _cmd_study(args) -> dict:
    # A distributed run's libraries (Gloo) print to stdout: there it carries only the result (--json)
    distributed = args.distributed or any(v is not None for v in (args.coordinator, args.num_processes, args.process_id))
    with _stdout_to_stderr(distributed):
        return _study(args)


def _study(args) -> dict:
    from pfjax.montecarlo.runner import study_output
    from pfjax.outputs import check_target
    from pfjax.report import figure_worker

    from pfjax.montecarlo.checks import check_resources

    spec = _load_study_or_usage(args)
    check_resources(spec, report=not args.no_report)  # every process alike, before any joins
    output = study_output(spec, args.out, overwrite=args.overwrite)
    index, count = _distributed(args)
    lead = index == 0  # the process that writes; the others only lend their devices
    if lead and count == 1:  # refused before anything starts (several processes: process 0 tells the others)
        check_target(output.target, command=output.command, config_sha256=output.config_sha256,
                     overwrite=args.overwrite)
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
    summary = run(spec, output, progress=None if not args.quiet else False, report=report, fresh=args.fresh,
                  warn=warn, overlap=not args.no_overlap, worker=worker, distributed=count > 1)
    head = _headline(summary, output.target)
    head.update(warnings=summary.get("warnings", []), chunks=summary.get("chunks"))
    if count > 1:
        head.update(process_count=count)
    return head


def _cmd_report(args) -> dict:
    from pfjax.montecarlo.config import study_hash
    from pfjax.montecarlo.study import rewrite_report
    from pfjax.outputs import read_marker

    spec = _load_study_or_usage(args)
    out = Path(args.out) if args.out else Path("results") / spec.name
    marker = read_marker(out) if out.is_dir() else None
    if marker is None or marker.get("command") != "study":
        raise UsageError(f"--out: no finished study in {out} (run `pfjax study {args.config}` first)")
    if marker.get("config_sha256") != study_hash(spec):
        raise UsageError(f"config: {args.config} (with --set) does not match the study in {out} (config hash differs)")
    return {"report": str(rewrite_report(out, spec, overwrite=args.overwrite) / "report.html")}


# --------------------------------------------------------------------------- main


def build_parser() -> argparse.ArgumentParser:
    from pfjax import __version__

    p = _Parser(prog="pfjax", description="Path following in JAX: slip-robust path-following controllers.")
    p.add_argument("--version", action="version", version=f"pfjax {__version__}")
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)

    s = sub.add_parser("synth", help="design a state feedback by LMIs (spec §4) and print K, bounds, true norms",
                       description="State-feedback H-inf, H2 or mixed H2/H-inf design for the slip model (msfsyn convention).")
    s.add_argument("--method", choices=("mixed", "hinf", "h2"), default="mixed")
    s.add_argument("--v", type=float, default=1.0, help="speed, m/s (default 1)")
    s.add_argument("--L", type=float, default=0.2, help="wheelbase, m (default 0.2)")
    s.add_argument("--alpha", type=float, default=10.0, help="weight on gamma_inf^2 (mixed; default 10)")
    s.add_argument("--beta", type=float, default=1.0, help="weight on gamma_2^2 (mixed; default 1)")
    s.add_argument("--max-real", type=float, help="pole region: Re(s) < MAX_REAL")
    s.add_argument("--disk", type=float, nargs=2, metavar=("CENTER", "RADIUS"), help="pole region: |s - CENTER| < RADIUS")
    s.add_argument("--sector-deg", type=float, help="pole region: conic sector of this half-angle about the negative real axis")
    s.add_argument("--json", action="store_true", help="print one JSON object")
    s.set_defaults(func=_cmd_synth)

    m = sub.add_parser("simulate", help="simulate one run of a paper scenario and print final state and metrics",
                       description="One closed-loop run of the slip model on a path (SI units; THETA in rad).")
    m.add_argument("--path", choices=("line", "parabola", "sine", "circle"), required=True)
    m.add_argument("--x0", type=float, nargs=3, metavar=("X", "Y", "THETA"), help="initial pose (m, m, rad); default: the source's")
    m.add_argument("--beta-r-deg", type=float, default=5.0, help="rear slip angle, deg (default 5)")
    m.add_argument("--beta-f-deg", type=float, default=5.0, help="front slip angle, deg (default 5)")
    m.add_argument("--controller", choices=CONTROLLER_CHOICES, required=True,
                   help="mixed: the LMI design with the source's weights; paper-k: the source's published K")
    m.add_argument("--gains", help="comma-separated gains (or name=value pairs): " +
                   "; ".join(f"{c}: {','.join(n)}" for c, (_, n) in GAIN_NAMES.items()))
    m.add_argument("--T", type=float, default=20.0, help="horizon, s (default 20)")
    m.add_argument("--dt", type=float, default=0.005, help="RK4 step, s (default 0.005)")
    m.add_argument("--control-every", type=int, help="controller sampling period in steps (default 1)")
    m.add_argument("--continuous", action="store_true", help="evaluate the controller inside every RK4 stage")
    m.add_argument("--v", type=float, default=1.0, help="speed, m/s")
    m.add_argument("--L", type=float, default=0.2, help="wheelbase, m")
    m.add_argument("--delta-max-deg", type=float, default=30.0, help="steering limit, deg")
    m.add_argument("--convention", choices=("source", "lenain"), default="source", help="front-slip sign convention")
    m.add_argument("--json", action="store_true", help="print one JSON object")
    m.set_defaults(func=_cmd_simulate)

    for name, helptext in (("study", "run a Monte Carlo robustness study from a TOML config (runs, margins, summary, report)"),
                           ("report", "rebuild the HTML report of a finished study without re-simulating")):
        st = sub.add_parser(name, help=helptext, description=helptext)
        st.add_argument("config", help="study TOML (e.g. studies/robustness_default.toml)")
        st.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                        help="override a config value; dotted keys, list items as controllers[0].gains.k (repeatable)")
        st.add_argument("--out", help="output directory (default results/<name>)")
        st.add_argument("--overwrite", action="store_true",
                        help="replace a pfjax output of another config or command in --out (pfjax never replaces "
                             "anything it did not write)")
        if name == "study":
            st.add_argument("--no-report", action="store_true", help="skip report.html")
            st.add_argument("--quiet", action="store_true", help="no progress bar")
            st.add_argument("--no-overlap", action="store_true",
                            help="run the worst-case search and the float64 check after the runs instead of "
                                 "alongside them in a background thread (same results; slower)")
            st.add_argument("--fresh", action="store_true",
                            help="discard the finished chunks of an interrupted run into --out and start over "
                                 "(default: resume them; refused if the config changed)")
            dist = st.add_argument_group(
                "several processes or hosts", "every process runs the same command with its own --process-id; "
                "the runs are sharded over the devices of all of them and process 0 writes the results "
                "(and resumes an interrupted run from its --out; the others follow it)")
            dist.add_argument("--coordinator", metavar="HOST:PORT", help="address of process 0 (jax.distributed)")
            dist.add_argument("--num-processes", type=int, metavar="N", help="number of processes")
            dist.add_argument("--process-id", type=int, metavar="I", help="this process, 0..N-1 (0 writes)")
            dist.add_argument("--coordinator-timeout", type=float, default=60.0, metavar="S",
                              help="seconds to wait for the coordinator and the other processes (default 60)")
            dist.add_argument("--distributed", action="store_true",
                              help="join a distributed run whose coordinator, size and rank JAX detects (SLURM, Open MPI)")
        st.add_argument("--json", action="store_true", help="print one JSON object")
        st.set_defaults(func=_cmd_study if name == "study" else _cmd_report)
    for module in EXTENSIONS:
        try:
            ext = importlib.import_module(module)
        except ModuleNotFoundError as e:  # while the subsystems are being written in parallel
            if e.name is not None and module.startswith(e.name):
                continue
            raise
        ext.register(sub)
    return p


def _print_human(out: dict) -> None:
    for k, v in out.items():
        if isinstance(v, dict):
            print(f"{k}:")
            for kk, vv in v.items():
                print(f"  {kk:20s} {vv}")
        else:
            print(f"{k:22s} {v}")


def _join_negative_values(argv: list[str]) -> list[str]:
    """``--gains -4,-1.5`` -> ``--gains=-4,-1.5`` (argparse would read ``-4,...`` as an option)."""
    out, i = [], 0
    while i < len(argv):
        if argv[i] == "--gains" and i + 1 < len(argv) and argv[i + 1].startswith("-") and argv[i + 1][1:2].isdigit():
            out.append(f"--gains={argv[i + 1]}")
            i += 2
        else:
            out.append(argv[i])
            i += 1
    return out


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(_join_negative_values(list(sys.argv[1:] if argv is None else argv)))
    import jax

    from pfjax import cache

    jax.config.update("jax_enable_x64", True)
    cache.enable()
    resume = "re-run the same command to resume" if args.command == "study" else "nothing was written"

    def body() -> int:
        out = args.func(args)
        if args.json:
            print(dumps(out))
        else:
            _print_human(out)
        return 0

    return command_main(f"pfjax {args.command}", body, interrupted=resume)


if __name__ == "__main__":
    sys.exit(main())
