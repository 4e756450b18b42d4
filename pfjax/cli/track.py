"""``pfjax track``: one focus-point tracking run, final error, phi - p gamma and the steering used.

    pfjax track --mode {forward,backward} --p P --l L --gamma-max-deg G --leader {line,circle,sine,lane-change} --json
"""

from __future__ import annotations

import math

from pfjax.cli.common import UsageError, finite

LEADERS = ("line", "circle", "sine", "lane-change")


def register(sub) -> None:
    p = sub.add_parser(
        "track", help="simulate focus-point vehicle tracking (forward or backward) and check Lemma 8.1 on the run",
        description="One run of a car-like follower tracking a leader through its focus point "
                    "P_r = P_ref + l (cos(theta + p gamma), sin(theta + p gamma)) with input-output linearisation "
                    "(SI units; angles in degrees where the flag says so).")
    p.add_argument("--mode", choices=("forward", "backward"), default="forward",
                   help="forward: f=+1, reference point P_f, follower drives forward; backward: f=-1, P_b, follower reverses")
    p.add_argument("--p", type=float, help="focus turning ratio p (default 1 forward, -1 backward; nonzero)")
    p.add_argument("--l", type=float, help="focus distance l, m, signed (default 1 forward, -1 backward; nonzero)")
    p.add_argument("--gamma-max-deg", type=float, default=30.0, help="steering limit, deg, in (0, 90) (default 30)")
    p.add_argument("--leader", choices=LEADERS, default="line")
    p.add_argument("--speed", type=float, default=1.0, help="leader speed V0, m/s (default 1)")
    p.add_argument("--stop-and-go", type=float, default=0.0, metavar="DEPTH",
                   help="stop-and-go depth in [0, 1] of the leader's speed profile, period 10 s (default 0)")
    p.add_argument("--a", type=float, default=1.0, help="wheelbase, m (default 1)")
    p.add_argument("--k", type=float, default=1.0, help="error decay rate, 1/s (default 1)")
    p.add_argument("--v-max", type=float, default=3.0, help="speed limit, m/s (default 3)")
    p.add_argument("--omega-max-deg", type=float, default=90.0, help="steering-rate limit, deg/s (default 90)")
    p.add_argument("--offset", type=float, nargs=2, default=(-0.5, 0.5), metavar=("ALONG", "LEFT"),
                   help="initial displacement of the follower in the leader's frame, m (default -0.5 0.5)")
    p.add_argument("--heading-error-deg", type=float, default=10.0, help="initial heading error, deg (default 10)")
    p.add_argument("--beta-r-deg", type=float, default=0.0, help="constant rear slip, deg (default 0)")
    p.add_argument("--beta-f-deg", type=float, default=0.0, help="constant front slip, deg (default 0)")
    p.add_argument("--T", type=float, default=30.0, help="horizon, s (default 30)")
    p.add_argument("--dt", type=float, default=0.01, help="step, s (default 0.01)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=_cmd)


def _check(args) -> tuple[float, float]:
    f = 1 if args.mode == "forward" else -1
    pp = float(f) if args.p is None else finite("--p", args.p)
    ll = float(f) if args.l is None else finite("--l", args.l)
    if pp == 0:
        raise UsageError("--p: must be nonzero (M is singular at p = 0), got 0")
    if ll == 0:
        raise UsageError("--l: must be nonzero (M is singular at l = 0), got 0")
    finite("--gamma-max-deg", args.gamma_max_deg, positive=True, below=90, unit=" deg")
    for flag, v in (("--speed", args.speed), ("--a", args.a), ("--k", args.k), ("--v-max", args.v_max),
                    ("--omega-max-deg", args.omega_max_deg), ("--T", args.T), ("--dt", args.dt)):
        finite(flag, v, positive=True)
    if not 0.0 <= args.stop_and_go <= 1.0:
        raise UsageError(f"--stop-and-go: expected a depth in [0, 1], got {args.stop_and_go:g}")
    for flag, v in (("--offset", args.offset[0]), ("--offset", args.offset[1]), ("--heading-error-deg", args.heading_error_deg)):
        finite(flag, v)
    finite("--beta-r-deg", args.beta_r_deg, below=90, unit=" deg")
    finite("--beta-f-deg", args.beta_f_deg, below=90, unit=" deg")
    if args.dt > args.T:
        raise UsageError(f"--dt: must be <= --T ({args.T:g} s), got {args.dt:g}")
    if args.T / args.dt > 2_000_000:
        raise UsageError(f"--T/--dt: at most 2e6 steps, got {args.T / args.dt:.3g}")
    return pp, ll


def _cmd(args) -> dict:
    pp, ll = _check(args)
    import jax

    import numpy as np

    from pfjax.sim.slip_profiles import constant_slip
    from pfjax.tracking import leader as L
    from pfjax.tracking.controller import FocusGains
    from pfjax.tracking.geometry import lemma_bound, p_bound
    from pfjax.tracking.lemma import zero_dynamics_stable
    from pfjax.tracking.model import FollowerParams
    from pfjax.tracking.simulate import (TRACK_STATUS_NAMES, TrackConfig, initial_states, scenario, simulate_batch,
                                         stack, unstack)

    f = 1 if args.mode == "forward" else -1
    gmax = math.radians(args.gamma_max_deg)
    params = FollowerParams(a=args.a, f=float(f), l=ll, p=pp, gamma_max=gmax, v_max=args.v_max,
                            omega_max=math.radians(args.omega_max_deg))
    ld = L.by_name(args.leader, speed=args.speed, depth=args.stop_and_go)
    host = lambda tree: jax.tree_util.tree_map(np.asarray, tree)  # noqa: E731  (index in NumPy, not op by op)
    init = unstack(host(initial_states(stack([ld]), stack([params]), np.asarray([args.offset], dtype=float),
                                       np.asarray([math.radians(args.heading_error_deg)]))), 0)
    slip = constant_slip(math.radians(args.beta_r_deg), math.radians(args.beta_f_deg))
    sc = scenario(params, ld, gains=FocusGains(k=args.k), init=init, slip=slip)
    cfg = TrackConfig(dt=args.dt, horizon=args.T, window=min(5.0, args.T / 3))
    r = unstack(host(simulate_batch(stack([sc]), config=cfg)), 0)
    m = r.metrics
    lo, hi = p_bound(gmax, f)
    status = int(r.status)
    return {
        "mode": args.mode, "f": f, "p": pp, "l": ll, "gamma_max_deg": args.gamma_max_deg, "leader": args.leader,
        "converged": bool(m.converged), "phi_converged": bool(m.phi_converged),
        "final_error_norm": float(m.final_error_norm), "final_phi_minus_pgamma": float(m.final_phi_minus_pgamma),
        "max_abs_gamma_deg": math.degrees(float(m.max_abs_gamma)),
        "window_max_error": float(m.window_max_z), "window_max_abs_phi_minus_pgamma": float(m.window_max_phi_err),
        "iae": float(m.iae), "final_d": float(m.final_d), "limit_fraction": float(m.limit_fraction),
        "min_abs_det_factor": float(m.min_abs_factor), "status": TRACK_STATUS_NAMES[status], "status_code": status,
        "fail_time": float(r.fail_time) if math.isfinite(float(r.fail_time)) else None,
        "lemma_p_bound": lemma_bound(gmax), "inside_lemma_bound": abs(pp) < lemma_bound(gmax),
        "input_matrix_invertible_for_all_gamma": bool(lo < pp < hi),
        "zero_dynamics_stable_straight": zero_dynamics_stable(args.speed, float(f), params),
        "tolerances": {"window_s": cfg.window, "tol_z_m": cfg.tol_z, "tol_phi_rad": cfg.tol_phi},
        "final": {k: float(v) for k, v in r.final._asdict().items()},
        "T": cfg.n_steps * cfg.dt, "dt": cfg.dt,
    }
