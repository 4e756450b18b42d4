"""``pfjax synth``: a state feedback designed by LMIs, with its bounds and true norms.

    pfjax synth --method {mixed,hinf,h2} [--speed 1] [--wheelbase 0.2] [--alpha 10] [--beta 1]
                [--max-real R] [--disk CENTER RADIUS] [--sector-deg DEG] [--json]

A design whose fastest closed-loop pole is beyond 100 v/L (:func:`pfjax.synthesis.lmi.gain_warnings`),
or whose solver status is not ``optimal``, is printed with a warning (one line on stderr, and in
``warnings``).

``--alpha`` and ``--beta`` weigh the mixed design's objective and are refused with ``--method hinf``
or ``h2``, which do not read them (by :func:`pfjax.synthesis.synthesize`, as from Python; nor are
they recorded in the output's ``arguments``).

``--v`` and ``--L`` are deprecated spellings of ``--speed`` and ``--wheelbase`` (read for one release).
"""

from __future__ import annotations

import math

from pfjax.cli.common import Aliased, UsageError, as_flags, finite

SYNTH_FLAGS = {
    "method": "--method",
    "v": "--speed",
    "L": "--wheelbase",
    "alpha": "--alpha",
    "beta": "--beta",
    "max_real": "--max-real",
    "disk_center": "--disk",
    "disk_radius": "--disk",
    # no design at the operating point, with the weights where they are not the source's
    # (pfjax.api.design.synthesized)
    "v/L": "--speed/--wheelbase",
    "v/L/alpha": "--speed/--wheelbase/--alpha",
    "v/L/beta": "--speed/--wheelbase/--beta",
    "v/L/alpha/beta": "--speed/--wheelbase/--alpha/--beta",
    "region": "--max-real/--disk/--sector-deg",  # no design in the pole region
}


#: The unit of each number ``cmd`` returns (:func:`pfjax.cli.records.units`). The norms are of the
#: source's performance channels of :func:`pfjax.synthesis.slip_design_plant`, from all of its
#: exogenous inputs w = [beta_r (rad), beta_f (rad), kappa (1/m)] to z = x = [d (m), theta_e (rad)],
#: and to z_2 = [x; delta (rad)], unweighted; poles and pole regions in 1/s, as
#: :class:`pfjax.synthesis.PoleRegion` takes them.
INPUTS = "w = [beta_r rad, beta_f rad, kappa 1/m]"
UNITS = {
    "arguments.*": {
        "speed": "m/s",
        "wheelbase": "m",
        "alpha": "1",
        "beta": "1",
        "max_real": "1/s",
        "disk": "1/s (center, radius)",
        "sector_deg": "deg",
    },
    "K": "rad/m (d), rad/rad (theta_e)",
    "gamma_inf": f"H-infinity bound, {INPUTS} to [d m, theta_e rad]",
    "hinf_norm": f"H-infinity norm, {INPUTS} to [d m, theta_e rad]",
    "gamma_2": f"H2 bound, {INPUTS} to [d m, theta_e rad, delta rad]",
    "h2_norm": f"H2 norm, {INPUTS} to [d m, theta_e rad, delta rad]",
    "closed_loop_poles": "1/s (real, imaginary)",
    "alpha": "1",
    "beta": "1",
    "v": "m/s",
    "L": "m",
    "region.*": {"max_real": "1/s", "disk_center": "1/s", "disk_radius": "1/s", "sector_deg": "deg"},
}


def cmd(args) -> dict:
    from pfjax.api.design import synthesized
    from pfjax.synthesis import PoleRegion

    region = None
    with as_flags(SYNTH_FLAGS):
        # the mixed design's weights, checked (and refused with hinf and h2, which do not read them) by
        # the synthesis, as the library checks them
        weights = {name: getattr(args, name) for name in ("alpha", "beta") if getattr(args, name) is not None}
        if args.method != "mixed":
            for name in ("alpha", "beta"):
                delattr(args, name)  # not an argument of this design: not recorded, not hashed
        # PoleRegion's bound on sector_angle, (0, pi/2] rad, in the flag's degrees
        if args.sector_deg is not None and not 0 < finite("--sector-deg", args.sector_deg) <= 90:
            raise UsageError(f"--sector-deg: expected a half-angle in (0, 90], got {args.sector_deg:g}")
        if args.max_real is not None or args.disk is not None or args.sector_deg is not None:
            region = PoleRegion(
                max_real=args.max_real,
                disk_center=None if args.disk is None else args.disk[0],
                disk_radius=None if args.disk is None else args.disk[1],
                sector_angle=None if args.sector_deg is None else math.radians(args.sector_deg),
            )
        design = synthesized(args.method, v=args.speed, L=args.wheelbase, region=region, **weights)
    out = design.to_dict()
    if args.method == "mixed":  # recorded as run, the synthesis's defaults filled in
        args.alpha, args.beta = out["alpha"], out["beta"]
    out.update(
        v=args.speed,
        L=args.wheelbase,
        region={
            "max_real": args.max_real,
            "disk_center": None if args.disk is None else args.disk[0],
            "disk_radius": None if args.disk is None else args.disk[1],
            "sector_deg": args.sector_deg,
        },
    )
    return out


def register(sub) -> None:
    s = sub.add_parser(
        "synth",
        help="design a state feedback by LMIs (docs/reproductions/path-following.md §4) and print K, bounds, true norms",
        description="State-feedback H-inf, H2 or mixed H2/H-inf design for the slip model (msfsyn convention).",
    )
    s.add_argument(
        "--method",
        choices=("mixed", "hinf", "h2"),
        default="mixed",
        help="mixed: minimise alpha gamma_inf^2 + beta gamma_2^2 (the source's design); hinf: minimise "
        "gamma_inf; h2: minimise gamma_2 (default mixed)",
    )
    s.add_argument(
        "--speed", "--v", action=Aliased, dest="speed", type=float, default=1.0, help="speed, m/s (default 1)"
    )
    s.add_argument(
        "--wheelbase",
        "--L",
        action=Aliased,
        dest="wheelbase",
        type=float,
        default=0.2,
        help="wheelbase, m (default 0.2)",
    )
    s.add_argument("--alpha", type=float, help="weight on gamma_inf^2 (--method mixed only; default 10)")
    s.add_argument("--beta", type=float, help="weight on gamma_2^2 (--method mixed only; default 1)")
    s.add_argument("--max-real", type=float, help="pole region: Re(s) < MAX_REAL, 1/s")
    s.add_argument(
        "--disk",
        type=float,
        nargs=2,
        metavar=("CENTER", "RADIUS"),
        help="pole region: |s - CENTER| < RADIUS, both 1/s",
    )
    s.add_argument(
        "--sector-deg",
        type=float,
        help="pole region: conic sector of this half-angle (deg) about the negative real axis",
    )
    s.add_argument("--json", action="store_true", help="print one JSON object")
    s.set_defaults(func=cmd, units=UNITS)
