"""``pfjax synth``: a state feedback designed by LMIs, with its bounds and true norms.

    pfjax synth --method {mixed,hinf,h2} [--speed 1] [--wheelbase 0.2] [--alpha 10] [--beta 1]
                [--max-real R] [--disk CENTER RADIUS] [--sector-deg DEG] [--json]

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
}


#: The unit of each number ``cmd`` returns (:func:`pfjax.cli.records.units`; the norms are of the
#: source's performance channels, from the slip w (rad) to z = x = [d (m), theta_e (rad)], and to
#: z_2 = [x; delta (rad)], unweighted).
UNITS = {
    "K": "rad/m (d), rad/rad (theta_e)",
    "gamma_inf": "H-infinity bound, slip (rad) to [d m, theta_e rad]",
    "hinf_norm": "H-infinity norm, slip (rad) to [d m, theta_e rad]",
    "gamma_2": "H2 bound, slip (rad) to [d m, theta_e rad, delta rad]",
    "h2_norm": "H2 norm, slip (rad) to [d m, theta_e rad, delta rad]",
    "closed_loop_poles": "rad/s (real, imaginary)",
    "alpha": "1",
    "beta": "1",
    "v": "m/s",
    "L": "m",
}


def cmd(args) -> dict:
    from pfjax import errors
    from pfjax.synthesis import PoleRegion, SynthesisError, synthesize

    region = None
    with as_flags(SYNTH_FLAGS):
        for name in ("alpha", "beta"):  # flags whatever the method (the designs read them for mixed only)
            errors.number(name, getattr(args, name), nonnegative=True)
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
        try:
            design = synthesize(
                args.method, v=args.speed, L=args.wheelbase, alpha=args.alpha, beta=args.beta, region=region
            )
        except SynthesisError as e:
            flags = "--max-real/--disk/--sector-deg" if region is not None else f"--method {args.method}"
            raise UsageError(f"{flags}: no design exists ({e})") from None
    out = design.to_dict()
    out.update(v=args.speed, L=args.wheelbase)
    return out


def register(sub) -> None:
    s = sub.add_parser(
        "synth",
        help="design a state feedback by LMIs (docs/reproductions/path-following.md §4) and print K, bounds, true norms",
        description="State-feedback H-inf, H2 or mixed H2/H-inf design for the slip model (msfsyn convention).",
    )
    s.add_argument("--method", choices=("mixed", "hinf", "h2"), default="mixed")
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
    s.add_argument("--alpha", type=float, default=10.0, help="weight on gamma_inf^2 (mixed; default 10)")
    s.add_argument("--beta", type=float, default=1.0, help="weight on gamma_2^2 (mixed; default 1)")
    s.add_argument("--max-real", type=float, help="pole region: Re(s) < MAX_REAL")
    s.add_argument(
        "--disk", type=float, nargs=2, metavar=("CENTER", "RADIUS"), help="pole region: |s - CENTER| < RADIUS"
    )
    s.add_argument(
        "--sector-deg", type=float, help="pole region: conic sector of this half-angle about the negative real axis"
    )
    s.add_argument("--json", action="store_true", help="print one JSON object")
    s.set_defaults(func=cmd, units=UNITS)
