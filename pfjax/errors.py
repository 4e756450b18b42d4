"""User-facing errors and the checks that raise them.

Bad input is never a traceback: every check in pfjax raises :class:`InputError` (a
``ValueError``) whose message is one line, ``"<key>: <what is wrong> ..."``, naming the config
key, function argument or command-line flag at fault. The ``pfjax`` command prints it after
``pfjax <command>: error:`` and exits with code 2; Python callers get the same message.

The checks here are shared by the configuration schema, the library functions and the command
line, so a value is judged the same way wherever it enters.
"""

from __future__ import annotations

import math
import numbers as _numbers
import re
from typing import Literal, overload

#: Exit code of a command refused for bad input (argparse's convention).
EXIT_USAGE = 2
#: Exit code of a command whose result is written and printed but counts as failed (``pfjax bench``
#: with a reference that disagrees, ``pfjax calibrate`` with no candidate that agrees): one line on
#: stderr says why.
EXIT_FAILED = 1
#: Exit code of a command stopped by Ctrl-C (128 + SIGINT).
EXIT_INTERRUPTED = 130
#: Exit code of a command stopped by SIGTERM (128 + 15, as a shell reports a process it ended).
EXIT_TERMINATED = 143
#: Exit code of a command whose standard output was closed by its reader (``pfjax ... | head``):
#: 128 + SIGPIPE, what a shell reports for a program that signal stopped.
EXIT_BROKEN_PIPE = 141

#: Largest magnitude any physical quantity in pfjax may take: far beyond anything meaningful in
#: SI units for a wheeled robot, and small enough that squares and products stay finite in float32
#: (3.4e38) and sums of a million of them in float64.
MAX_MAGNITUDE = 1e12
#: Smallest positive magnitude a step, length or tolerance may take (below it float32 flushes to
#: zero or loses every digit against quantities of order one).
MIN_POSITIVE = 1e-12
#: Seeds and counts: JAX keys take 64-bit seeds; counts above this exhaust any machine.
MAX_SEED = 2**63 - 1


class InputError(ValueError):
    """Bad input: the message is one line and starts with the key, argument or flag at fault.

    Attributes:
        key: the key, argument or flag named at the start of the message (None if unknown).
    """

    def __init__(self, message: str, key: str | None = None):
        message = " ".join(str(message).split())  # one line, whatever the parts contained
        super().__init__(message)
        first, sep, _ = message.partition(": ")
        head = first if sep and " " not in first else None
        if key is None or (head and head.startswith((f"{key}.", f"{key}["))):
            key = head  # the whole key the message names: gains.foo, not gains
        self.key = key


class ArgumentError(InputError, TypeError):
    """A call with a keyword the function does not take, or without an argument it needs: an
    :class:`InputError` naming the argument, and a ``TypeError`` as Python's own would be."""


def arguments_checked(f):
    """``f`` (a public API function) whose call is first bound to its signature: an argument it
    does not take, or one missing, is an :class:`ArgumentError` naming it, with the closest name it
    takes (``beta_r: pfjax.scenarios takes no such argument (did you mean 'beta_r_deg'?)``)."""
    import difflib
    import functools
    import inspect

    sig = inspect.signature(f)
    takes = [n for n, p in sig.parameters.items() if p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD)]
    module = f.__module__.removesuffix(".api")  # pfjax.parking.api.run: pfjax.parking.run
    where = f"pfjax.{f.__name__}" if module.startswith("pfjax.api") else f"{module}.{f.__name__}"

    @functools.wraps(f)
    def checked(*args, **kwargs):
        try:
            sig.bind(*args, **kwargs)
        except TypeError as e:
            unknown = [k for k in kwargs if k not in sig.parameters]
            if unknown:
                hint = difflib.get_close_matches(unknown[0], takes, n=1)
                raise no_such_argument(where, unknown[0], takes, hint) from None
            missing = re.search(r"missing a required argument: '(\w+)'", str(e))
            if missing:
                name = missing.group(1)
                raise ArgumentError(f"{name}: {where} needs this argument", name) from None
            raise ArgumentError(f"{where}: {e}") from None
        return f(*args, **kwargs)

    return checked


def no_such_argument(where: str, name: str, takes, hint: list[str]) -> ArgumentError:
    """The :class:`ArgumentError` of a keyword ``name`` that ``where`` (``pfjax.simulate``) does not
    take: with the closest argument (``hint``, at most one) or, without one, every argument it takes."""
    also = f" (did you mean {hint[0]!r}?)" if hint else f"; it takes {', '.join(takes)}"
    return ArgumentError(f"{name}: {where} takes no such argument{also}", name)


def is_number(value) -> bool:
    """A real number that is not a boolean (``True`` is not 1 here): a Python or NumPy number (an
    array, even of one number, is not: a value pfjax keeps must be a plain number)."""
    return isinstance(value, _numbers.Real) and not isinstance(value, bool)


def number(
    key: str,
    value,
    *,
    positive: bool = False,
    nonnegative: bool = False,
    below: float | None = None,
    low: float | None = None,
    high: float | None = None,
    unit: str = "",
) -> float:
    """``value`` as a finite float within pfjax's magnitude bounds; :class:`InputError` otherwise.

    Args:
        key: the name the message starts with.
        value: the value to check (an int, float or NumPy scalar; not a bool, a string or an array).
        positive: require ``value > 0`` (and at least :data:`MIN_POSITIVE`).
        nonnegative: require ``value >= 0``.
        below: require ``|value| < below``.
        low: require ``value >= low``.
        high: require ``value <= high``.
        unit: appended to the bounds in the message (e.g. ``" deg"``).
    """
    if not is_number(value):
        raise InputError(f"{key}: expected a number, got {value!r}", key)
    try:
        x = float(value)
    except OverflowError:
        raise InputError(
            f"{key}: expected a number of magnitude <= {MAX_MAGNITUDE:g}{unit}, got an integer of "
            f"{len(str(abs(int(value))))} digits",
            key,
        ) from None
    if not math.isfinite(x):
        raise InputError(f"{key}: expected a finite number, got {x}", key)
    if abs(x) > MAX_MAGNITUDE:
        raise InputError(f"{key}: expected a magnitude <= {MAX_MAGNITUDE:g}{unit}, got {shown(x)}", key)
    if positive and not x > 0:
        raise InputError(f"{key}: must be > 0{unit}, got {shown(x)}", key)
    if positive and not x >= MIN_POSITIVE:
        raise InputError(f"{key}: must be at least {MIN_POSITIVE:g}{unit}, got {shown(x)}", key)
    if nonnegative and x < 0:
        raise InputError(f"{key}: must be >= 0{unit}, got {shown(x)}", key)
    if below is not None and not abs(x) < below:
        raise InputError(f"{key}: magnitude must be < {below:g}{unit}, got {shown(x)}", key)
    if low is not None and x < low:
        raise InputError(f"{key}: must be >= {low:g}{unit}, got {shown(x)}", key)
    if high is not None and x > high:
        raise InputError(f"{key}: must be <= {high:g}{unit}, got {shown(x)}", key)
    return x


def shown(x: float) -> str:
    """A number as a refusal shows it: ``:g`` (``0.1``, ``2e+04``) where that reads back as the
    same number, else every digit (``1.0000001``), so a value just past a bound never reads as
    the bound itself."""
    short = f"{x:g}"
    return short if float(short) == float(x) else repr(float(x))


def is_traced(value) -> bool:
    """Whether ``value`` is (or holds) a JAX tracer: its numbers are not known yet (inside ``jit``,
    ``grad`` or ``vmap``), so they cannot be checked here."""
    import jax

    return any(isinstance(leaf, jax.core.Tracer) for leaf in jax.tree_util.tree_leaves(value))


def numbers(
    key: str,
    value,
    *,
    positive: bool = False,
    nonnegative: bool = False,
    below: float | None = None,
    low: float | None = None,
    high: float | None = None,
    unit: str = "",
):
    """Like :func:`number` for a scalar or an array of numbers (every element checked; the first
    bad one is named). Values under a JAX transformation are not checked (:func:`is_traced`).
    Returns ``value`` unchanged."""
    import numpy as np

    if value is None or is_traced(value):
        return value
    if is_number(value):
        number(key, value, positive=positive, nonnegative=nonnegative, below=below, low=low, high=high, unit=unit)
        return value
    try:
        a = np.asarray(value)
    except (TypeError, ValueError):
        raise InputError(f"{key}: expected numbers, got {value!r}", key) from None
    if a.dtype == bool or a.dtype.kind not in "iuf":
        raise InputError(f"{key}: expected numbers, got an array of {a.dtype}", key)
    flat = a.reshape(-1)
    bad = ~np.isfinite(flat.astype(float))
    for check, fail in (
        (True, bad),
        (True, np.abs(flat) > MAX_MAGNITUDE),
        (positive, flat < MIN_POSITIVE),
        (nonnegative, flat < 0),
        (below is not None, np.abs(flat) >= (below or 0)),
        (low is not None, flat < (low if low is not None else 0)),
        (high is not None, flat > (high if high is not None else 0)),
    ):
        if check and np.any(fail):
            i = int(np.argmax(fail))
            index = ", ".join(str(int(j)) for j in np.unravel_index(i, a.shape))
            where = f"{key}[{index}]" if a.ndim else key
            number(
                where,
                flat[i].item(),
                positive=positive,
                nonnegative=nonnegative,
                below=below,
                low=low,
                high=high,
                unit=unit,
            )
    return value


def integer(key: str, value, *, low: int | None = None, high: int | None = None) -> int:
    """``value`` as an int within ``[low, high]``; :class:`InputError` for booleans, floats and
    values out of range (the message shows at most 20 digits of a huge integer)."""
    if isinstance(value, bool) or not isinstance(value, _numbers.Integral):
        raise InputError(f"{key}: expected an integer, got {value!r}", key)
    n = int(value)
    shown = str(n) if len(str(n)) <= 20 else f"an integer of {len(str(abs(n)))} digits"
    if low is not None and n < low:
        raise InputError(f"{key}: must be >= {low}, got {shown}", key)
    if high is not None and n > high:
        raise InputError(f"{key}: must be <= {high}, got {shown}", key)
    return n


def box(lower, upper):
    """A tuner's box ``(lower, upper)`` as two flat float64 arrays: of one size, finite, with
    ``lower < upper`` in every coordinate; :class:`InputError` naming ``lower``, or ``upper`` where
    only it is at fault (not numbers, not finite), otherwise."""
    import numpy as np

    corners = []
    for name, b in (("lower", lower), ("upper", upper)):
        try:
            c = np.asarray(b, np.float64).reshape(-1)
        except (TypeError, ValueError):
            raise InputError(f"{name}: expected an array of numbers, got a {type(b).__name__}", name) from None
        if c.size == 0 or not np.all(np.isfinite(c)):
            raise InputError(f"{name}: expected finite numbers, got {c.tolist()}", name)
        corners.append(c)
    lo, hi = corners
    if lo.shape != hi.shape or not np.all(lo < hi):
        raise InputError(
            f"lower: expected corners of one size with lower < upper, got {lo.tolist()} and {hi.tolist()}", "lower"
        )
    return lo, hi


def seed(key: str, value) -> int:
    """A PRNG seed: an integer in ``[0, 2**63 - 1]``."""
    return integer(key, value, low=0, high=MAX_SEED)


@overload
def boolean(key: str, value, *, or_none: Literal[False] = False) -> bool: ...
@overload
def boolean(key: str, value, *, or_none: Literal[True]) -> bool | None: ...
def boolean(key: str, value, *, or_none: bool = False) -> bool | None:
    """``value`` as a bool (a NumPy boolean too; None where ``or_none``); :class:`InputError` naming
    ``key`` for anything else (``"no"``, ``0``), which Python's truth would read as a choice."""
    if value is None and or_none:
        return None
    numpy_bool = type(value).__module__ == "numpy" and type(value).__name__ in ("bool", "bool_")
    if not (isinstance(value, bool) or numpy_bool):  # NumPy's (np.bool, np.bool_), without importing it
        expected = "True, False or None" if or_none else "True or False"
        raise InputError(f"{key}: expected {expected}, got {value!r:.80}", key)
    return bool(value)


def unique(key: str, names) -> None:
    """:class:`InputError` naming the first repeated name in ``names`` (controllers, paths, obstacles)."""
    seen: dict = {}
    for i, name in enumerate(names):
        if name in seen:
            raise InputError(f"{key}[{i}]: name {name!r} repeats {key}[{seen[name]}]; names must be unique", key)
        seen[name] = i


def one_line(exc: BaseException) -> str:
    """The first non-empty line of an exception's message (its type name if it has none)."""
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__


def command_main(prog: str, body, *, interrupted: str = "nothing was written") -> int:
    """Run ``body()`` (which returns an exit code) as a command's main function: bad input
    (:class:`InputError`) prints one line ``<prog>: error: <message>`` on stderr and returns
    :data:`EXIT_USAGE`; Ctrl-C prints ``<prog>: interrupted; <interrupted>`` and returns
    :data:`EXIT_INTERRUPTED`, SIGTERM ``<prog>: terminated; <interrupted>`` and
    :data:`EXIT_TERMINATED`; standard output closed by its reader (``| head``) returns
    :data:`EXIT_BROKEN_PIPE` quietly, the rest of the output going nowhere. No traceback in any
    case. Ctrl-C is never lost, even where Python drops its exception (:mod:`pfjax.interrupts`)."""
    import os
    import sys

    from pfjax import interrupts

    cmd = None
    try:
        with interrupts.guard() as cmd:
            code = body()
            sys.stdout.flush()  # here, so that a closed pipe is met inside this try
            return code
    except BrokenPipeError:
        # what is still buffered, and any later write, goes to /dev/null instead of raising again
        # (Python's own flush at exit would print "Exception ignored ... BrokenPipeError")
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return EXIT_BROKEN_PIPE
    except InputError as e:
        print(f"{prog}: error: {one_line(e)}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt as e:
        if sys.stderr.isatty():  # below a progress bar's partial line (bars are drawn on a terminal only)
            sys.stderr.write("\n")
        term = isinstance(e, interrupts.Terminated)
        word, written = "terminated" if term else "interrupted", None if cmd is None else cmd.written
        if written is not None:  # held over the final renames: the output is complete
            print(f"{prog}: {word} after writing {written}; its output is complete", file=sys.stderr)
        else:
            print(f"{prog}: {word}; {interrupted}", file=sys.stderr)
        return EXIT_TERMINATED if term else EXIT_INTERRUPTED


def renamed(e: InputError, old: str, new: str) -> InputError:
    """``e`` told by another name for its key: the same one-line message with its leading ``old``
    (a flag, a config key) as ``new`` (the argument a caller gave); ``e`` itself if its key is another."""
    if e.key != old:
        return e
    return type(e)(new + str(e).removeprefix(old), new)


class SynthesisError(ValueError):
    """An LMI synthesis problem was infeasible, unbounded, numerically ill-conditioned or the solver
    failed. ``status`` carries the solver's status (``"infeasible"``, ``"unbounded"``,
    ``"infeasible_inaccurate"``, ``"solver_error"``, ...) or ``"ill_conditioned"``. Raised by
    :mod:`pfjax.synthesis` (which re-exports it); defined here so that code that only calls a
    design can catch it without importing the solver."""

    def __init__(self, message: str, status: str | None = None):
        super().__init__(message)
        self.status = status


class NoDesignError(InputError, SynthesisError):
    """A synthesis that finds no design for the values a caller gave (the operating point, the pole
    region): an :class:`InputError` naming what the caller can change, and a :class:`SynthesisError`
    with the solver's ``status``, so that code catching either catches it."""

    def __init__(self, message: str, key: str | None = None, status: str | None = None):
        super().__init__(message, key)
        self.status = status


class PfjaxDeprecationWarning(FutureWarning):
    """An old spelling of a config key, flag or argument that pfjax still reads (for one release)."""


def deprecated(old: str, new: str) -> None:
    """Warn once per spelling that ``old`` is read as ``new`` and will be removed."""
    import warnings

    if (old, new) in _DEPRECATIONS:
        return
    _DEPRECATIONS.add((old, new))
    # one line on stderr, not the location inside pydantic or argparse that read the old spelling
    warnings.warn_explicit(
        f"{old} is deprecated: it is read as {new}, and will be refused in the next release",
        PfjaxDeprecationWarning,
        "pfjax",
        0,
        module="pfjax",
    )


_DEPRECATIONS: set = set()
