#!/usr/bin/env python
"""Rare failures, verified and measured (docs/rare-events.md): the estimators of pfjax.rare against
a failure probability known independently, against plain Monte Carlo, their interval coverage, and
the certification study ``studies/rare_events.toml``.

    python studies/rare_events.py [--out DIR] [--quick] [--overwrite]

Parts (each entry records estimate, 95 % interval, relative error, rollouts and wall time, s):

* ``known``: state feedback on a straight line under constant Gaussian slip of standard
  deviation ``s`` from zero initial error (8 s horizon, 10 ms steps, float64): the reference is the
  Gaussian measure of the slips whose equilibrium offset leaves the 5 cm band
  (:func:`pfjax.rare.reference.line_offset_failure_probability`), at ``p`` about 1e-4, 1e-6 and
  1e-8, by importance sampling and subset simulation; plain Monte Carlo at 1e-4.
* ``coverage``: repeated independent estimates at ``p`` about 1e-4 on the known case: the share of
  95 % intervals that hold the reference (subset simulation: also the runs' observed spread
  against the levels-uncorrelated and fully-correlated errors of Au and Beck's bounds).
* ``starts``: importance sampling at ``p`` about 1e-6 on the known case from the falsifier's
  failure points, from failure points of a widened law and from ``N(0, I)``: rollouts used.
* ``study``: every controller of ``studies/rare_events.toml`` by importance sampling and subset
  simulation, for its failure (leaving the path, ``path``) and for leaving the 5 cm band
  (``band``), there also by plain Monte Carlo with ``mc_study`` runs, which resolves it.
* ``sine_check``: ``pi-table3`` leaving the path on the sine alone (``p`` about 1e-5), by plain
  Monte Carlo with ``mc_sine`` runs, importance sampling and subset simulation.

The study's importance-sampling estimates carry the reliability check of ``[rare_event] check =
"subset"`` (:mod:`pfjax.rare.check`: ``status``, ``warning`` and each stratum's ``check``).

Writes ``results/rare_events/verification.json`` (``--quick``: ``results/rare_events_quick/``; or
``--out``): the parts above, the provenance
record (pfjax version, the SHA-256 of the sizes and the known case's settings, seed, machine, CPU
settings) and a ``units`` map by field name. The parts, their sizes and budgets are
:mod:`pfjax.rare.verification`; ``--quick`` runs them on budgets of a few thousand rollouts.
"""

from __future__ import annotations

from pathlib import Path

from pfjax.cli.study import default_out, script_parser, start_script

start_script(figures=False)

from pfjax.errors import command_main  # noqa: E402
from pfjax.rare import verification  # noqa: E402

STUDY = Path(__file__).resolve().with_suffix(".toml")


def run(args) -> int:
    sizes = verification.QUICK if args.quick else verification.FULL
    out = default_out(args.out, "rare_events_quick" if args.quick else "rare_events")
    result = verification.run(sizes, out, STUDY, overwrite=args.overwrite)
    print(f"wrote {out} in {result['wall_s']:.1f} s")
    return 0


def main(argv=None) -> int:
    ap = script_parser(
        __doc__,
        config=None,
        out_default="results/rare_events, or results/rare_events_quick with --quick",
        quick="small sizes (tests)",
    )
    args = ap.parse_args(argv)
    return command_main("rare-events", lambda: run(args))


if __name__ == "__main__":
    from pfjax.interrupts import finished

    raise SystemExit(finished(main()))  # a Ctrl-C after the study ended changes nothing
