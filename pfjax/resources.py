"""Memory guards: refuse, before allocating, work that cannot fit in this machine's memory.

A batch of runs, a recorded trajectory or a run table whose size the user sets (``n_runs``,
``chunk_size``, ``--population``, ``--sizes``, horizons) is estimated from those sizes first; if
the estimate exceeds :func:`memory_budget` the command stops with one line naming the key or flag
(an :class:`~pfjax.errors.InputError`), instead of swapping or being killed by the operating
system an hour later. Work that streams (a study's runs, chunk by chunk) is bounded by its chunk,
not its total.

The estimates are upper bounds of the arrays pfjax itself holds (inputs, per-run state, outputs,
and XLA's temporaries counted as a factor); they are meant to catch orders of magnitude, not to
predict the peak to the byte.
"""

from __future__ import annotations

import math
import os

from pfjax.errors import InputError, shown

#: Environment variable: the memory budget in bytes (default: half the machine's physical memory).
ENV = "PFJAX_MEMORY_BUDGET"
#: Bytes a float64 run of the slip simulator holds besides its slip sequence and path: scenario,
#: loop carry, running metrics and XLA's temporaries in the scan body. Measured (peak resident
#: memory of ``simulate_batch`` on the benchmark problem, metrics only): 2.4 kB per run at 10^5
#: runs, 1.1 kB at 10^6.
RUN_BYTES = 2400
#: Bytes one run of :func:`pfjax.scenarios` takes at the peak of drawing it (its scenario arrays,
#: its row of the table and the draws' temporaries). Measured: 293-295 B per run at 10^6 runs.
SCENARIO_BYTES = 300
#: Bytes per recorded sample of a trajectory (12 float64 fields).
SAMPLE_BYTES = 8 * 12
#: Most integrator steps one run may take (``horizon / dt``): a 20 s run at 10 us.
MAX_STEPS = 2_000_000
#: Largest population and number of generations a genetic algorithm accepts
#: (:func:`pfjax.tuning.ga.ga`, the parking search).
MAX_POPULATION = 1_000_000
MAX_GENERATIONS = 1_000_000


def check_steps(horizon: float, dt: float, key: str = "dt") -> int:
    """The number of integrator steps ``horizon / dt``; :class:`~pfjax.errors.InputError` naming
    ``key`` above :data:`MAX_STEPS`."""
    n = horizon / dt
    if n > MAX_STEPS:
        raise InputError(
            f"{key}: horizon / dt (a run's integrator step count) may be at most {MAX_STEPS:.0e}, "
            f"got {shown(horizon)} / {shown(dt)} = {shown(n)}",
            key,
        )
    return int(round(n))


#: Relative tolerance of a whole number of steps: ``horizon / dt`` within this of an integer (the
#: rounding of a decimal horizon and step, e.g. 20 / 0.005) is that integer.
STEPS_RTOL = 1e-9


def named_setting(horizon: float, dt: float, defaults: tuple[float, float]) -> str:
    """Which setting a step that does not fit the horizon is told by: ``"dt"`` when only the step
    differs from its default (``defaults``: the default horizon and step, s), else ``"horizon"``:
    the error names what the caller changed."""
    return "dt" if horizon == defaults[0] and dt != defaults[1] else "horizon"


def check_fits(horizon: float, dt: float, defaults: tuple[float, float]) -> str:
    """``horizon >= dt`` (s), else :class:`~pfjax.errors.InputError` naming the setting the caller
    changed (:func:`named_setting`); returns that setting's name, for the whole-steps check."""
    key = named_setting(horizon, dt, defaults)
    if not horizon >= dt:
        if key == "dt":
            raise InputError(f"dt: must be <= horizon ({horizon:g} s), got {shown(dt)}", "dt")
        raise InputError(f"horizon: must be >= dt ({dt:g} s), got {shown(horizon)}", "horizon")
    return key


def whole_steps(horizon: float, dt: float, key: str = "horizon") -> int:
    """The number of integrator steps ``horizon / dt`` when it is a whole number (to a relative
    :data:`STEPS_RTOL`); :class:`~pfjax.errors.InputError` naming ``key`` otherwise, with the two
    nearest values of the named setting that are (horizons, or steps when ``key`` names the step,
    ``dt`` or ``<prefix>.dt``): a run is never silently lengthened or shortened to whole steps."""
    n = horizon / dt
    if abs(n - round(n)) > STEPS_RTOL * n:
        g = lambda x: f"{x:.15g}"  # every digit the value has (20.0000001 is not 20), not float noise
        if key.rpartition(".")[2] == "dt":  # the step was given: the steps that divide the horizon
            lo, hi = horizon / math.ceil(n), horizon / max(math.floor(n), 1)
            raise InputError(  # every digit of the steps it suggests: each divides the horizon as written
                f"{key}: must divide horizon = {g(horizon)} s into whole steps, got {g(dt)} s = {n:.10g} steps "
                f"(e.g. {g(lo)} or {g(hi)} s)",
                key,
            )
        lo, hi = math.floor(n) * dt, math.ceil(n) * dt
        raise InputError(
            f"{key}: must be a whole number of steps dt = {g(dt)} s, got {g(horizon)} s = {n:.10g} steps "
            f"(e.g. {g(lo)} or {g(hi)} s)",
            key,
        )
    return int(round(n))


def physical_memory() -> int:
    """This machine's physical memory, bytes (0 if the platform does not say)."""
    try:
        return int(os.sysconf("SC_PAGE_SIZE")) * int(os.sysconf("SC_PHYS_PAGES"))
    except (AttributeError, OSError, ValueError):
        return 0


def memory_budget(environ=None) -> int:
    """The most memory one allocation plan may take: ``$PFJAX_MEMORY_BUDGET`` bytes if set, else
    half the physical memory (the rest is the operating system's, XLA's code and the user's)."""
    from pfjax.host import whole_number

    environ = os.environ if environ is None else environ
    total = physical_memory()
    return whole_number(environ, ENV, "bytes", total // 2 if total else 1 << 62)


def fmt_bytes(n: float) -> str:
    for unit, size in (("TiB", 1 << 40), ("GiB", 1 << 30), ("MiB", 1 << 20), ("kiB", 1 << 10)):
        if n >= size:
            return f"{n / size:.3g} {unit}"
    return f"{n:.0f} B"


def check_memory(key: str, nbytes: float, what: str, hint: str = "") -> None:
    """:class:`~pfjax.errors.InputError` naming ``key`` if ``nbytes`` exceeds :func:`memory_budget`.

    Args:
        key: the key or flag whose value sets the size.
        nbytes: the estimate, bytes.
        what: what needs it (``"a chunk of 10^8 runs"``).
        hint: what to do instead (``"lower chunk_size"``).
    """
    budget = memory_budget()
    if nbytes > budget:
        raise InputError(
            f"{key}: {what} needs about {fmt_bytes(nbytes)}, more than the memory budget of "
            f"{fmt_bytes(budget)} (half this machine's memory, or ${ENV})" + (f"; {hint}" if hint else ""),
            key,
        )


def run_bytes(n_steps: int, *, record: bool = False, seq_len: int = 0, path_numbers: int = 0) -> int:
    """Upper bound of the bytes one run of the slip simulator holds: its state and metrics, its
    slip sequence (``seq_len`` samples of two axes), its path (``path_numbers`` numbers) and, with
    ``record``, its trajectory (``n_steps + 1`` samples)."""
    return RUN_BYTES + 8 * (2 * seq_len + path_numbers) + (SAMPLE_BYTES * (n_steps + 1) if record else 0)
