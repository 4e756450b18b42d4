"""``pfjax track``: one focus-point tracking run, final error, phi - p gamma and the steering used
(:func:`pfjax.tracking.run`, which checks the values; its errors name the flags here).

    pfjax track --mode {forward,backward} --p P --l L --gamma-max-deg G --leader {line,circle,sine,lane-change}
                [--speed 1] [--wheelbase 1] [--horizon 30] [--dt 0.01] --json

``--a`` and ``--T`` are deprecated spellings of ``--wheelbase`` and ``--horizon`` (read for one release).
"""

from __future__ import annotations

from pfjax.cli.common import Aliased, as_flags
from pfjax.tables import TRACK_UNITS as UNITS

#: The ``--leader`` choices: :data:`pfjax.tracking.api.LEADERS`, written out so that building the
#: parser does not import the simulator (a test checks that the two agree).
LEADERS = ("line", "circle", "sine", "lane-change")


def register(sub) -> None:
    p = sub.add_parser(
        "track",
        help="simulate focus-point vehicle tracking (forward or backward) and check Lemma 8.1 on the run",
        description="One run of a car-like follower tracking a leader through its focus point "
        "P_r = P_ref + l (cos(theta + p gamma), sin(theta + p gamma)) with input-output linearisation "
        "(SI units; angles in degrees where the flag says so).",
    )
    p.add_argument(
        "--mode",
        choices=("forward", "backward"),
        default="forward",
        help="forward: f=+1, reference point P_f, follower drives forward; backward: f=-1, P_b, follower reverses "
        "(default forward)",
    )
    p.add_argument("--p", type=float, help="focus turning ratio p (default 1 forward, -1 backward; nonzero)")
    p.add_argument("--l", type=float, help="focus distance l, m, signed (default 1 forward, -1 backward; nonzero)")
    p.add_argument("--gamma-max-deg", type=float, default=30.0, help="steering limit, deg, in (0, 90) (default 30)")
    p.add_argument(
        "--leader",
        choices=LEADERS,
        default="line",
        help="the leader's motion: line, circle, sine or lane-change (default line)",
    )
    p.add_argument("--speed", type=float, default=1.0, help="leader speed V0, m/s (default 1)")
    p.add_argument(
        "--stop-and-go",
        type=float,
        default=0.0,
        metavar="DEPTH",
        help="stop-and-go depth in [0, 1] of the leader's speed profile, period 10 s (default 0)",
    )
    p.add_argument(
        "--wheelbase", "--a", action=Aliased, dest="wheelbase", type=float, default=1.0, help="wheelbase, m (default 1)"
    )
    p.add_argument("--k", type=float, default=1.0, help="error decay rate, 1/s (default 1)")
    p.add_argument("--v-max", type=float, default=3.0, help="speed limit, m/s (default 3)")
    p.add_argument("--omega-max-deg", type=float, default=90.0, help="steering-rate limit, deg/s (default 90)")
    p.add_argument(
        "--offset",
        type=float,
        nargs=2,
        default=(-0.5, 0.5),
        metavar=("ALONG", "LEFT"),
        help="initial displacement of the follower in the leader's frame, m, less than 50 m long: a run whose "
        "tracking error passes 50 m ends as diverged (default -0.5 0.5)",
    )
    p.add_argument("--heading-error-deg", type=float, default=10.0, help="initial heading error, deg (default 10)")
    p.add_argument("--beta-r-deg", type=float, default=0.0, help="constant rear slip, deg (default 0)")
    p.add_argument("--beta-f-deg", type=float, default=0.0, help="constant front slip, deg (default 0)")
    p.add_argument(
        "--horizon", "--T", action=Aliased, dest="horizon", type=float, default=30.0, help="horizon, s (default 30)"
    )
    p.add_argument("--dt", type=float, default=0.01, help="step, s (default 0.01)")
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
    from pfjax.tracking.api import run

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
