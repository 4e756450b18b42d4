"""``pfjax rare-event``: each controller's failure probability under a study's uncertain inputs,
down to 1e-6 and below, with its 95 % interval (:func:`pfjax.rare_event`).

    pfjax rare-event CONFIG.toml | --example NAME [--set key=value ...] [--controller NAME]
                     [--method {is,subset,mc}] [--target-rel-error 0.1] [--max-rollouts N] [--seed S] [--json]

With ``--json`` prints ``{"study", "pfjax_version", "config_sha256", "seed", "machine",
"cpu_settings", "config", "units", "controllers": {name: {"p_fail", "ci95", "rel_error",
"n_rollouts", "method", ...}}}`` (:func:`pfjax.rare_event`'s result), else one line per controller;
a progress bar of rollouts on stderr when it is a terminal and ``--json`` is not given. Nothing
is written to disk.
"""

from __future__ import annotations

import math
import sys

from pfjax.cli.common import NULL, as_flags
from pfjax.cli.study import add_study_flags, load_study_flags

#: ``pfjax rare-event``'s flags by the library argument they set.
FLAGS = {
    "config": "CONFIG",
    "controller": "--controller",
    "method": "--method",
    "target_rel_error": "--target-rel-error",
    "max_rollouts": "--max-rollouts",
    "seed": "--seed",
}


def register(sub) -> None:
    p = sub.add_parser(
        "rare-event",
        help="small failure probabilities (1e-6 and below) with intervals",
        description="Estimate each controller's probability of failure under a study's uncertain inputs by "
        "importance sampling (cross-entropy Gaussian mixture), subset simulation or plain Monte Carlo; "
        "prints the estimate, its 95 % interval, relative error and rollouts.",
    )
    add_study_flags(
        p,
        "study TOML (its [rare_event] table sets the defaults; its enabled key only tells pfjax study whether to "
        "estimate too)",
    )
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="override a config value")
    p.add_argument("--controller", default=None, help="only this controller of the study (default: all)")
    p.add_argument("--method", default=None, help="is | subset | mc (default: the config's rare_event.method, else is)")
    p.add_argument(
        "--target-rel-error",
        type=float,
        default=None,
        help="is, subset: stop at this relative error (default: the config's rare_event.target_rel_error, else "
        "0.1); plain Monte Carlo (mc) runs all of --max-rollouts (its strata's even shares)",
    )
    p.add_argument(
        "--max-rollouts",
        type=int,
        default=None,
        help="rollouts per controller, split over the strata; subset simulation completes a run it has started "
        "(default: the config's rare_event.max_rollouts, else 100000); at least 100, at most 100000000",
    )
    p.add_argument(
        "--seed",
        type=int,
        default=None,
        help="seed of the estimator's draws (default: the config's rare_event.seed, else 0)",
    )
    p.add_argument("--json", action="store_true", help="print one JSON object (else one line per controller)")
    p.set_defaults(func=_cmd, human=_human)


def _human(out: dict) -> None:
    """One line per controller: the estimate, its interval, relative error, rollouts and status."""
    print(f"study {out['study']} (config {out['config_sha256'][:12]}), estimator seed {out['seed']}")
    for name, c in out["controllers"].items():
        lo, hi = c["ci95"]
        r = c["rel_error"]  # infinite (null in JSON) where no failure was seen
        rel = NULL if r is None or not math.isfinite(r) else f"{100 * r:.1f} %"
        line = (
            f"  {name}: p_fail {c['p_fail']:.3g} [{lo:.3g}, {hi:.3g}], rel. error {rel}, "
            f"{c['n_rollouts']} rollouts ({c['method']}), status {c['status']}"
        )
        print(line + (f": {c['warning']}" if c.get("warning") else ""))
    print("(--json: every number, the strata and the failure modes, with units)")


def _cmd(args) -> dict:

    from pfjax.api import rare_event

    spec = load_study_flags(args)  # a missing file or a directory, an unknown example: as pfjax study says it
    with as_flags(FLAGS):
        return rare_event(
            spec,
            controller=args.controller,
            method=args.method,
            target_rel_error=args.target_rel_error,
            max_rollouts=args.max_rollouts,
            seed=args.seed,
            progress=(not args.json) and sys.stderr.isatty(),
        )
