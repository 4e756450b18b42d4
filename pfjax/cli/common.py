"""What every subcommand of the command line shares: the one-line parser, flag checks and the
mapping of the library's argument names to flags."""

from __future__ import annotations

import argparse
import contextlib
import re
import sys
import warnings

from pfjax.errors import EXIT_USAGE, InputError

__all__ = [
    "EXIT_USAGE",
    "NULL",
    "Aliased",
    "Parser",
    "UsageError",
    "as_flags",
    "controller_hint",
    "finite",
    "join_negative_values",
    "print_human",
    "warnings_as_lines",
]


class UsageError(InputError):
    """A bad command-line value; the message names the flag."""


#: A negative number, also in exponent form (``-1e-3``, ``-5e-1``): argparse's own pattern has no
#: exponent, so it would read such a value as an option and stop with "expected one argument".
NEGATIVE_NUMBER = re.compile(r"^-(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?$")


class Subcommands(argparse._SubParsersAction):
    """The subcommands of a :class:`Parser`: a word or flag the subcommand does not take is refused
    by the subcommand's parser (``pfjax simulate: error: unrecognized arguments: --bogus``), not by
    the top-level one, so that the error names the subcommand."""

    def __call__(self, parser, namespace, values, option_string=None):
        super().__call__(parser, namespace, values, option_string)
        extra = getattr(namespace, argparse._UNRECOGNIZED_ARGS_ATTR, None)
        if extra:
            self._name_parser_map[values[0]].error(f"unrecognized arguments: {' '.join(extra)}")


def underscore_hint(value, choices) -> str:
    """``" (did you mean pure-pursuit?)"`` for a choice spelled with ``_`` where the choice has ``-``."""
    spelled = str(value).replace("_", "-")
    return f" (did you mean {spelled}?)" if spelled != value and spelled in choices else ""


class Parser(argparse.ArgumentParser):
    """pfjax's argument parser: one-line errors with exit code 2, exact flags only (no
    abbreviations: ``--hor`` is not ``--horizon``), negative numbers in exponent form read as
    values, an unknown word refused by the subcommand that got it, and a refused choice with the
    choice it was probably meant as (``_`` for ``-``, or the action's own ``hint(value, choices)``)."""

    def __init__(self, *args, **kwargs):
        kwargs.setdefault("allow_abbrev", False)
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = NEGATIVE_NUMBER
        self.register("action", "parsers", Subcommands)

    def error(self, message):  # one line, exit code 2 (argparse's own convention)
        self.exit(EXIT_USAGE, f"{self.prog}: error: {message}\n")

    def _check_value(self, action, value):
        try:
            super()._check_value(action, value)
        except argparse.ArgumentError as e:
            hint = getattr(action, "hint", underscore_hint)(value, list(action.choices))
            e.message += hint
            raise


def controller_hint(value: str, choices) -> str:
    """``" (did you mean X?)"`` for a controller named by a spelling the command line does not take:
    its config name (``pure_pursuit``, ``lmi``: :func:`pfjax.controllers.cli_names` are the
    command line's), ``_`` for ``-``, or a design whose controller is a choice (``mixed`` designs
    ``state-feedback``'s gains); empty if none is among ``choices``."""
    from pfjax.controllers.designs import DESIGNS, design
    from pfjax.controllers.registry import REGISTRY

    cli = {e.name: e.cli_name for e in REGISTRY.values()} | {d.name: d.cli_name for d in DESIGNS.values()}
    d = design(value)
    made = None if d is None else REGISTRY[d.controller].cli_name
    for candidate, why in (
        (cli.get(value), ""),
        (str(value).replace("_", "-"), ""),
        (made, f" {value} designs its gains"),
    ):
        if candidate is not None and candidate != value and candidate in choices:
            return f" (did you mean {candidate}?{why})"
    return ""


#: How a command's plain-text output (not ``--json``) shows a missing value (JSON's null).
NULL = "none"


@contextlib.contextmanager
def warnings_as_lines(prog: str):
    """While active, every warning shown is one line on stderr, ``<prog>: warning: <message>``
    (the message's own line breaks folded), not Python's ``file:line: Category: message`` and
    source line. Yields the namespace whose ``prog`` names the lines (set it once the command is
    known). Installed by the command line's entry point only: importing pfjax leaves Python's
    warning display as it is."""
    import types

    where = types.SimpleNamespace(prog=prog)
    saved = warnings.showwarning

    def show(message, category, filename, lineno, file=None, line=None):
        text = " ".join(str(message).split())
        try:
            print(f"{where.prog}: warning: {text}", file=sys.stderr if file is None else file)
        except (OSError, ValueError):  # stderr closed: a warning is not worth an error
            pass

    warnings.showwarning = show
    try:
        yield where
    finally:
        warnings.showwarning = saved


class Aliased(argparse._StoreAction):
    """A flag with deprecated spellings, read for one release: the first option string is the
    canonical flag, every later one an old spelling that sets the same ``dest`` and issues one
    :class:`~pfjax.errors.PfjaxDeprecationWarning` naming both (once per spelling, by
    :func:`pfjax.errors.deprecated`; the command line prints it as one line,
    ``pfjax <command>: warning: ...``, :func:`warnings_as_lines`)::

        p.add_argument("--horizon", "--T", action=Aliased, dest="horizon", type=float, default=20.0,
                       help="horizon, s (default 20)")

    ``--help`` lists the canonical flag first and adds ``(--T: deprecated spelling)``; both
    spellings on one command line are a usage error naming them."""

    def __init__(self, option_strings, dest, help=None, **kwargs):
        old = list(option_strings[1:])
        if old and help is not None and help is not argparse.SUPPRESS:
            help = f"{help} ({', '.join(old)}: deprecated spelling{'s' if len(old) > 1 else ''})"
        super().__init__(option_strings, dest, help=help, **kwargs)

    def __call__(self, parser, namespace, values, option_string=None):
        # both spellings on one command line: which one wins would be argparse's order, not the user's
        earlier = getattr(self, "_given", None)
        if earlier is not None and earlier[0] is namespace and earlier[1] != option_string:
            parser.error(
                f"{option_string}: not with {earlier[1]} (two spellings of one setting); give {self.option_strings[0]} once"
            )
        self._given = (namespace, option_string)
        if option_string is not None and option_string != self.option_strings[0]:
            from pfjax.errors import deprecated

            deprecated(option_string, self.option_strings[0])
        super().__call__(parser, namespace, values, option_string)


def add_pose(parser: argparse.ArgumentParser, help: str) -> None:
    """The start pose flag every one-run command shares: ``--x0 X Y THETA_DEG`` (metres, metres,
    degrees), three floats, default None (the command's own default start)."""
    parser.add_argument("--x0", type=float, nargs=3, metavar=("X", "Y", "THETA_DEG"), help=help)


def finite(flag: str, value: float, *, positive=False, below=None, unit="") -> float:
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
        body = text[len(key) + 2 :] if text.startswith(key + ": ") else text
        # other settings the message mentions, by their flags too; not in an error about a config
        # file's own key (``--scenario: sim.dt: ...``), whose words are the file's, not the flags'
        if not re.match(r"[\w\[\]]+(\.[\w\[\]]+)+: ", body):
            for name, other in flags.items():
                if len(name) > 1:
                    body = re.sub(rf"(?<![\w.-]){re.escape(name)}(?![\w.-])", other, body)
        sub = key[len(base) :]
        flag = flags[base] + (sub if sub.startswith("[") else "")
        sub = "" if sub.startswith("[") else sub.lstrip(".")
        raise UsageError(f"{flag}: {sub + ': ' if sub else ''}{body}", flags[base]) from None


def print_human(out: dict) -> None:
    """A command's result without ``--json``: ``key value`` lines, a nested dict's keys indented
    under its name, a list of dicts one ``- key value, ...`` line per item (a command with a
    report of its own prints that instead: its parser's ``human`` default)."""
    for line in _human_lines(out, 0):
        print(line)


def _human_lines(d: dict, depth: int):
    pad, width = "  " * depth, max(22 - 2 * depth, 1)
    for k, v in d.items():
        if isinstance(v, dict) and v:
            yield f"{pad}{k}:"
            yield from _human_lines(v, depth + 1)
        elif isinstance(v, list) and v and all(isinstance(x, dict) for x in v):
            yield f"{pad}{k}:"
            yield from (f"{pad}  - " + ", ".join(f"{kk} {_shown(vv)}" for kk, vv in x.items()) for x in v)
        else:
            yield f"{pad}{k:{width}s} {_shown(v)}"


def _shown(v) -> str:
    """A value of a plain-text listing: a missing one (None) as :data:`NULL`, in lists too."""
    if v is None:
        return NULL
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_shown(x) for x in v) + "]"
    return str(v)


def join_negative_values(argv: list[str]) -> list[str]:
    """``--gains -4,-1.5`` -> ``--gains=-4,-1.5`` (and ``--check``; argparse would read ``-4,...`` as an option)."""
    out, i = [], 0
    while i < len(argv):
        if (
            argv[i] in ("--gains", "--check")
            and i + 1 < len(argv)
            and argv[i + 1].startswith("-")
            and argv[i + 1][1:2].isdigit()
        ):
            out.append(f"{argv[i]}={argv[i + 1]}")
            i += 2
        else:
            out.append(argv[i])
            i += 1
    return out
