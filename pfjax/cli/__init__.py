"""The ``pfjax`` command line: a package at the top of pfjax that imports the library and is
imported by nothing in it.

    pfjax synth --method {mixed,hinf,h2} [--speed 1 --wheelbase 0.2 --alpha 10 --beta 1] [--json]
    pfjax simulate --path {line,parabola,sine,circle} --controller NAME [--gains G,...] [--x0 X Y THETA_DEG]
                   [--horizon 20] [--json]
    pfjax study CONFIG.toml [--set key=value ...] [--out DIR] [--json]
    pfjax report CONFIG.toml [--out DIR]
    pfjax rare-event CONFIG.toml [--method {is,subset,mc}] [--target-rel-error 0.1] [--json]
    pfjax tune | parking | parking-search | track | bench | calibrate ...   (pfjax SUBCOMMAND --help)

One module per subcommand (or pair of subcommands), each with ``register(sub)``. Bad arguments
print one line naming the flag, the value and what was expected, and exit with code 2 before
anything is computed or written (the checks are the library's: :mod:`pfjax.errors`). A run that
fails numerically is reported in its ``status``; it is not an error.

One spelling per quantity in every subcommand: ``--horizon`` (s), ``--speed`` (m/s),
``--wheelbase`` (m), ``--x0 X Y THETA_DEG`` (m, m, deg). The old spellings (``--T``, ``--v``,
``--L``, ``--a``, ``--t-max``) are read for one release as deprecated aliases
(:class:`pfjax.cli.common.Aliased`): each prints one line on stderr,
``pfjax <command>: warning: --T is deprecated: ...``; every other warning is printed as one such
line too (:func:`pfjax.cli.common.warnings_as_lines`).

Flags are read exactly as written (``--hor`` is not ``--horizon``); a word a subcommand does not
take is refused by that subcommand (``pfjax simulate: error: unrecognized arguments: ...``).

Controllers and paths registered by plugin modules (:mod:`pfjax.plugins`: ``PFJAX_PLUGINS`` or
the ``pfjax.plugins`` entry points) appear in every subcommand's choices.
"""

from __future__ import annotations

import importlib
import os
import sys

from pfjax.cli.common import (
    EXIT_USAGE,
    Parser,
    UsageError,
    as_flags,
    join_negative_values,
    print_human,
    warnings_as_lines,
)
from pfjax.errors import EXIT_FAILED, command_main
from pfjax.jsonio import dumps

__all__ = ["EXIT_USAGE", "UsageError", "as_flags", "build_parser", "main", "run"]

#: The subcommand modules, in the order of ``pfjax --help``.
SUBCOMMANDS = ("synth", "simulate", "study", "rare-event", "examples", "tune", "parking", "track", "bench", "calibrate")


def build_parser():
    from pfjax import __version__

    p = Parser(prog="pfjax", description="Path following in JAX: slip-robust path-following controllers.")
    p.add_argument("--version", action="version", version=f"pfjax {__version__}")
    sub = p.add_subparsers(dest="command", required=True, parser_class=Parser)
    for name in SUBCOMMANDS:
        importlib.import_module(f"pfjax.cli.{name.replace('-', '_')}").register(sub)
    return p


def main(argv=None) -> int:
    with warnings_as_lines("pfjax") as shown:  # one line per warning, named by the subcommand once known
        return _main(list(sys.argv[1:] if argv is None else argv), shown)


def _main(argv: list[str], shown) -> int:
    import argparse

    from pfjax import plugins

    loaded = command_main("pfjax", lambda: plugins.load() and 0)
    if loaded:  # a plugin that cannot be imported: one line, exit 2
        return loaded
    parser = build_parser()
    commands = next(a.choices for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    if argv and argv[0] in commands:  # the subcommand is the first word (the deprecations are read with it)
        shown.prog = f"pfjax {argv[0]}"
    args = parser.parse_args(join_negative_values(argv))
    import jax

    from pfjax import cache

    jax.config.update("jax_enable_x64", True)
    # every program cached, the small host-side ones too (a scenario's arrays, built with jax.numpy): each
    # compiles in 0.03-0.2 s in every process (measured) and loads from the cache in under 0.01 s
    cache.enable(min_compile_s=0.0)
    resume = "re-run the same command to resume" if args.command == "study" else "nothing was written"

    def body() -> int:
        out = args.func(args)
        if args.json:
            from pfjax.cli.records import stamped

            print(dumps(stamped(out, args)))
        else:
            getattr(args, "human", print_human)(out)
        # a result that is data but a failed run (a benchmark reference that disagrees): printed,
        # then one line on stderr and exit 1 (set_defaults(failure=...): out -> message or None)
        failed = getattr(args, "failure", None)
        message = failed(out) if failed is not None else None
        if message:
            sys.stdout.flush()
            print(f"pfjax {args.command}: error: {message}", file=sys.stderr, flush=True)
            return EXIT_FAILED
        return 0

    code = command_main(f"pfjax {args.command}", body, interrupted=resume)
    sharding = sys.modules.get("pfjax.sim.sharding")
    if code and sharding is not None and sharding.joined():
        # a multi-process run that failed or was interrupted: no shutdown barrier (JAX's, at exit),
        # which would wait minutes for processes that are stopping too or blocked in a collective
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)
    return code


def run() -> None:
    """The ``pfjax`` console script: :func:`main`, then the end of the process without the
    interpreter's teardown.

    Once a command has written and closed its outputs, the teardown of a process that imported JAX
    (freeing its modules, compiled programs and runtime) changes nothing, and took 0.22-0.34 s of a
    warm ``pfjax simulate`` or ``pfjax track`` (medians; 2-core AMD EPYC, jax 0.10.2;
    docs/performance.md). So the script ignores Ctrl-C from then on (:func:`pfjax.interrupts.finished`:
    the command has ended), waits for any non-daemon thread, runs the exit handlers
    (:mod:`atexit`: JAX's, logging's, multiprocessing's), flushes stdout and stderr and ends with
    :func:`os._exit` and the command's exit code (as :func:`sys.exit` would give it). If a stream
    cannot be flushed (a closed pipe), or the command raised, it exits the usual way.
    ``python -m pfjax.cli`` exits the usual way too, for tools that act after the program returns
    (``python -m cProfile``).
    """
    import atexit
    import os
    import threading

    from pfjax import interrupts

    result: int | str | None
    try:
        result = main()
    except SystemExit as e:  # argparse's --help and usage errors
        result = e.code
    interrupts.finished(result)  # the command has ended: a late Ctrl-C stops neither exit handler nor code
    if result is not None and not isinstance(result, int):
        print(result, file=sys.stderr)  # sys.exit's message form
        result = 1
    code = result or 0
    for t in threading.enumerate():
        if t is not threading.main_thread() and not t.daemon:
            t.join()
    atexit._run_exitfuncs()
    try:
        sys.stdout.flush()
        sys.stderr.flush()
    except (OSError, ValueError):
        sys.exit(code)
    os._exit(code)


if __name__ == "__main__":
    sys.exit(main())
