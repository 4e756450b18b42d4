"""``pfjax track``: one focus-point tracking run, final error, phi - p gamma and the steering used
(:func:`pfjax.tracking.run`, which checks the values; its errors name the flags here).

    pfjax track --mode {forward,backward} --p P --l L --gamma-max-deg G --leader {line,circle,sine,lane-change}
                [--speed V0] [--wheelbase A] [--horizon T] [--dt DT] --json

Every flag's default is :func:`pfjax.tracking.run`'s (``pfjax track --help`` prints them).

``--a`` and ``--T`` are deprecated spellings of ``--wheelbase`` and ``--horizon`` (read for one release).
"""

from __future__ import annotations

import inspect

from pfjax.cli.common import Aliased, as_flags
from pfjax.tables import TRACK_UNITS as UNITS
from pfjax.tracking.api import LEADERS, MODES, run
from pfjax.tracking.simulate import TrackConfig

#: Every flag's default: :func:`pfjax.tracking.run`'s (its horizon and step are ``TrackConfig``'s,
#: its wheelbase ``FollowerParams``'s and its gain ``FocusGains``'s), by argument name.
DEFAULTS = {name: q.default for name, q in inspect.signature(run).parameters.items()}


def register(sub) -> None:
    d, z_fail = DEFAULTS, TrackConfig.z_fail
    p = sub.add_parser(
        "track",
        help="simulate focus-point vehicle tracking (forward or backward) and check Lemma 8.1 on the run",
        description="One run of a car-like follower tracking a leader through its focus point "
        "P_r = P_ref + l (cos(theta + p gamma), sin(theta + p gamma)) with input-output linearisation "
        "(SI units; angles in degrees where the flag says so).",
    )
    p.add_argument(
        "--mode",
        choices=MODES,
        default=d["mode"],
        help="forward: f=+1, reference point P_f, follower drives forward; backward: f=-1, P_b, follower reverses "
        f"(default {d['mode']})",
    )
    p.add_argument("--p", type=float, help="focus turning ratio p (default 1 forward, -1 backward; nonzero)")
    p.add_argument("--l", type=float, help="focus distance l, m, signed (default 1 forward, -1 backward; nonzero)")
    p.add_argument(
        "--gamma-max-deg",
        type=float,
        default=d["gamma_max_deg"],
        help=f"steering limit, deg, in (0, 90) (default {d['gamma_max_deg']:g})",
    )
    p.add_argument(
        "--leader",
        choices=LEADERS,
        default=d["leader"],
        help=f"the leader's motion: {', '.join(LEADERS[:-1])} or {LEADERS[-1]} (default {d['leader']})",
    )
    p.add_argument("--speed", type=float, default=d["speed"], help=f"leader speed V0, m/s (default {d['speed']:g})")
    p.add_argument(
        "--stop-and-go",
        type=float,
        default=d["stop_and_go"],
        metavar="DEPTH",
        help=f"stop-and-go depth in [0, 1] of the leader's speed profile, period 10 s (default {d['stop_and_go']:g})",
    )
    p.add_argument(
        "--wheelbase",
        "--a",
        action=Aliased,
        dest="wheelbase",
        type=float,
        default=d["a"],
        help=f"wheelbase, m (default {d['a']:g})",
    )
    p.add_argument("--k", type=float, default=d["k"], help=f"error decay rate, 1/s (default {d['k']:g})")
    p.add_argument("--v-max", type=float, default=d["v_max"], help=f"speed limit, m/s (default {d['v_max']:g})")
    p.add_argument(
        "--omega-max-deg",
        type=float,
        default=d["omega_max_deg"],
        help=f"steering-rate limit, deg/s (default {d['omega_max_deg']:g})",
    )
    p.add_argument(
        "--offset",
        type=float,
        nargs=2,
        default=d["offset"],
        metavar=("ALONG", "LEFT"),
        help=f"initial displacement of the follower in the leader's frame, m, less than {z_fail:g} m long: a run "
        f"whose tracking error passes {z_fail:g} m ends as diverged (default {' '.join(f'{v:g}' for v in d['offset'])})",
    )
    p.add_argument(
        "--heading-error-deg",
        type=float,
        default=d["heading_error_deg"],
        help=f"initial heading error, deg (default {d['heading_error_deg']:g})",
    )
    p.add_argument(
        "--beta-r-deg",
        type=float,
        default=d["beta_r_deg"],
        help=f"constant rear slip, deg (default {d['beta_r_deg']:g})",
    )
    p.add_argument(
        "--beta-f-deg",
        type=float,
        default=d["beta_f_deg"],
        help=f"constant front slip, deg (default {d['beta_f_deg']:g})",
    )
    p.add_argument(
        "--horizon",
        "--T",
        action=Aliased,
        dest="horizon",
        type=float,
        default=d["horizon"],
        help=f"horizon, s (default {d['horizon']:g})",
    )
    p.add_argument("--dt", type=float, default=d["dt"], help=f"step, s (default {d['dt']:g})")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=_cmd, units=UNITS)


#: ``pfjax track``'s flags by the :func:`pfjax.tracking.run` argument they set (``horizon/dt``: the step count).
FLAGS = {
    "mode": "--mode",
    "p": "--p",
    "l": "--l",
    "gamma_max_deg": "--gamma-max-deg",
    "leader": "--leader",
    "speed": "--speed",
    "stop_and_go": "--stop-and-go",
    "a": "--wheelbase",
    "k": "--k",
    "v_max": "--v-max",
    "omega_max_deg": "--omega-max-deg",
    "offset": "--offset",
    "heading_error_deg": "--heading-error-deg",
    "beta_r_deg": "--beta-r-deg",
    "beta_f_deg": "--beta-f-deg",
    "horizon": "--horizon",
    "dt": "--dt",
    "horizon/dt": "--horizon/--dt",
}


def _cmd(args) -> dict:
    with as_flags(FLAGS):
        out = run(
            args.mode,
            p=args.p,
            l=args.l,
            gamma_max_deg=args.gamma_max_deg,
            leader=args.leader,
            speed=args.speed,
            stop_and_go=args.stop_and_go,
            a=args.wheelbase,
            k=args.k,
            v_max=args.v_max,
            omega_max_deg=args.omega_max_deg,
            offset=tuple(args.offset),
            heading_error_deg=args.heading_error_deg,
            beta_r_deg=args.beta_r_deg,
            beta_f_deg=args.beta_f_deg,
            horizon=args.horizon,
            dt=args.dt,
        )
    args.p, args.l = out["p"], out["l"]  # as they ran (the mode's defaults): one config hash, given or not
    return out
