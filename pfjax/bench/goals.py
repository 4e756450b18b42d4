"""pfjax's performance goals, checked by every run of ``pfjax bench`` on the machine it runs on.

Each :class:`Goal` is one number of the benchmark's result against a target, at the batch size the
goal is stated for. :func:`check` evaluates them all: ``summary["goals"]`` in ``bench.json`` and
the "Goals on this machine" table of ``report.md``. A goal whose number the run did not measure
(its batch size was not among ``--sizes``, or Numba is not installed) is reported as not measured,
never as met or missed. The goals and what was measured against them on the machines pfjax was
tuned on are in docs/performance.md (Scale targets).

Rates are million rollout-steps per second (runs x RK4 steps over wall time); fractions are
pfjax's throughput over the minimal JAX implementation's (:mod:`pfjax.bench.minimal`) at the same
batch size, in the same process; ratios over Numba are pfjax at the goal's batch over the Numba
reference (run once per precision, on ``BenchConfig.ref_size`` runs of the largest batch), so they
are measured whatever larger batches the run adds; the gradient costs are the value and gradient of
the batch-mean IAE with respect to the gains over the forward pass, at the gradient's batch of 2,000
runs. The goals are stated for the benchmark's problem at its full horizon (20 s), so a ``--quick``
run measures none of them. A goal read against a reference (the minimal implementation, Numba) is
not measured where that reference disagrees with pfjax on the per-run IAE in the run
(:func:`pfjax.bench.run.disagreeing`): a ratio to a program that solves another problem measures
nothing. Each goal's ``not_measured`` says why it was not measured.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import NamedTuple

from pfjax.bench.problem import HORIZON, RATE

__all__ = ["GOALS", "Goal", "check"]


class Goal(NamedTuple):
    """One performance goal: ``value(result, batch) >= target`` (``at_least``) or ``<= target``."""

    name: str  # key of the goal in ``summary["goals"]``
    text: str  # what is measured, in words
    target: float
    at_least: bool  # True: the value must reach the target; False: stay at or below it
    batch: int  # the batch size the goal is stated for (the gradient's batch for gradient costs)
    value: Callable[[dict, int], float | None]  # from the result (``rows``, ``summary``, ``config``)
    unit: str = "1"  # of the target and the value
    reference: str | None = None  # the agreement entry the value is measured against ("numba_float32")


def _rate(impl: str, dtype: str):
    def value(result: dict, batch: int) -> float | None:
        rows = [r for r in result["rows"] if r["impl"] == impl and r["dtype"] == dtype and r["batch"] == batch]
        return rows[0]["msteps_per_s"] if rows else None

    return value


def _fraction(bits: int):
    def value(result: dict, batch: int) -> float | None:
        found = [f[f"f{bits}"] for f in result["summary"]["fraction_of_minimal_by_batch"] if f["batch"] == batch]
        return found[0] if found else None

    return value


def _gradient(key: str, mode: str | None = None):
    """A gradient cost, where the run's gradient batch is the goal's (and, given ``mode``, where the
    tuner's gradient was taken in that mode)."""

    def value(result: dict, batch: int) -> float | None:
        s = result["summary"]
        if result["config"]["grad_size"] != batch or (mode is not None and s.get("grad_mode") != mode):
            return None
        return s.get(key)

    return value


def _over_reference(impl: str, dtype: str):
    """pfjax's rate at the goal's batch over a reference's (``impl``: measured once per precision,
    at its own batch, :func:`pfjax.bench.run._reference_rows`), whatever other batches were run."""

    def value(result: dict, batch: int) -> float | None:
        ours = _rate("pfjax", dtype)(result, batch)
        ref = [r["msteps_per_s"] for r in result["rows"] if r["impl"] == impl and r["dtype"] == dtype]
        return None if ours is None or not ref else ours / ref[0]

    return value


#: The goals, in the order the report lists them.
GOALS: tuple[Goal, ...] = (
    Goal("throughput_f32", "pfjax float32, M rollout-steps/s", 150.0, True, 100_000, _rate("pfjax", "float32"), RATE),
    Goal("throughput_f64", "pfjax float64, M rollout-steps/s", 70.0, True, 100_000, _rate("pfjax", "float64"), RATE),
    *(
        Goal(
            f"fraction_of_minimal_f{bits}_{batch}",
            f"pfjax float{bits} over the minimal JAX implementation",
            target,
            True,
            batch,
            _fraction(bits),
            reference=f"jax_minimal_float{bits}",
        )
        for bits, target in ((32, 0.90), (64, 0.85))
        for batch in (10_000, 100_000)
    ),
    *(
        Goal(
            f"numba_f{bits}",
            f"pfjax over Numba, float{bits}",
            target,
            True,
            100_000,
            _over_reference("numba", f"float{bits}"),
            reference=f"numba_float{bits}",
        )
        for bits, target in ((32, 12.0), (64, 8.0))
    ),
    Goal(
        "gradient_forward_mode",
        "value and gradient over the forward pass, forward mode",
        2.0,
        False,
        2_000,
        _gradient("grad_over_forward", mode="forward"),
    ),
    Goal(
        "gradient_reverse_mode",
        "value and gradient over the forward pass, reverse mode",
        3.0,
        False,
        2_000,
        _gradient("grad_over_forward_reverse"),
    ),
)


def _measured(result: dict, g: Goal) -> tuple[float | None, str | None]:
    """``(value, None)``, or ``(None, why it was not measured)``."""
    agreement = (result["summary"].get("agreement") or {}).get(g.reference or "", {})
    if agreement.get("ok") is False:  # first: what no other setting of the run would mend
        return None, f"reference {g.reference} disagrees"
    horizon = result["config"]["horizon"]
    if horizon != HORIZON:
        return None, f"{horizon:g} s horizon, the goals' is {HORIZON:g} s"
    value = g.value(result, g.batch)
    if value is None:
        return None, "not in this run (its batch size, the gradient's batch or mode, or its reference)"
    if not math.isfinite(value):
        return None, "not finite (its reference not run)"
    return value, None


def check(result: dict, goals: tuple[Goal, ...] = GOALS) -> list[dict]:
    """Every goal against ``result`` (:func:`pfjax.bench.run.run`'s, with its ``rows``,
    ``summary`` and ``config``): ``{"goal", "text", "target", "unit", "at_least", "batch", "value",
    "met", "not_measured"}`` per goal, ``value`` and ``met`` None where the run did not measure it,
    and ``not_measured`` then saying why: the goal's reference disagrees with pfjax (``"reference
    numba_float32 disagrees"``), the run's horizon is not the benchmark problem's
    (:data:`pfjax.bench.problem.HORIZON`, e.g. ``--quick``), its batch size was not run or, for the
    forward-mode gradient, the tuner's mode was reverse, or the number is not finite (Numba skipped)."""
    out = []
    for g in goals:
        value, why = _measured(result, g)
        met = None if value is None else (value >= g.target if g.at_least else value <= g.target)
        out.append(
            {
                "goal": g.name,
                "text": g.text,
                "target": g.target,
                "unit": g.unit,
                "at_least": g.at_least,
                "batch": g.batch,
                "value": value,
                "met": met,
                "not_measured": why,
            }
        )
    return out
