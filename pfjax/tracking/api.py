"""One focus-point tracking run from plain arguments: :func:`run`, the library behind ``pfjax track``.

Every argument is checked before anything is compiled or simulated; a bad one raises
:class:`~pfjax.errors.InputError` whose one-line message starts with the argument's name
(``"p: must be nonzero ..."``). The command line calls :func:`run` and names its flags instead
(:func:`pfjax.cli.common.as_flags`), so both judge a value alike.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

from pfjax import errors
from pfjax.errors import InputError
from pfjax.resources import MAX_STEPS, check_fits, check_steps, whole_steps
from pfjax.tables import TRACK_UNITS as UNITS
from pfjax.tracking.controller import FocusGains
from pfjax.tracking.model import FollowerParams
from pfjax.tracking.simulate import TrackConfig

__all__ = ["LEADERS", "MAX_STEPS", "MODES", "UNITS", "check_time", "nonzero", "run"]

#: The follower's driving modes: ``forward`` (f = +1, reference point P_f) and ``backward`` (f = -1, P_b).
MODES = ("forward", "backward")
#: The leader motions :func:`pfjax.tracking.leader.by_name` builds.
LEADERS = ("line", "circle", "sine", "lane-change")


def check_offset(key: str, distance: float, of: str = "") -> None:
    """:class:`InputError` naming ``key`` when a start ``distance`` m from the leading vehicle's
    start point reaches ``TrackConfig.z_fail``: the run would end at once as diverged (``of``: what
    the distance is of, in the message). The one check of :func:`run`'s ``offset`` and the study
    config's (``lemma.offsets``, ``mc.offset_max``)."""
    z_fail = TrackConfig.z_fail
    if distance >= z_fail:
        raise InputError(
            f"{key}: must start less than {z_fail:g} m from the leading vehicle's start point (a run whose "
            f"tracking error passes {z_fail:g} m ends as diverged), got {distance:g} m{of}",
            key,
        )


def nonzero(key: str, value: float, symbol: str) -> float:
    """``value``, or :class:`InputError` naming ``key`` when it is 0 or smaller in magnitude than
    :data:`pfjax.errors.MIN_POSITIVE`: the input matrix ``M`` is singular at ``p = 0`` and at
    ``l = 0`` (``symbol``: which of the two ``value`` is), and ``1 / p`` overflows near it."""
    if value == 0:
        raise InputError(f"{key}: must be nonzero (M is singular at {symbol} = 0), got 0", key)
    if abs(value) < errors.MIN_POSITIVE:
        raise InputError(
            f"{key}: must be at least {errors.MIN_POSITIVE:g} in magnitude (M is singular at {symbol} = 0), "
            f"got {value!r}",
            key,
        )
    return value


def check_time(horizon: float, dt: float, window: float | None = None) -> int:
    """The number of integrator steps of a run of ``horizon`` s at step ``dt`` s (both > 0).

    :class:`InputError` when ``dt > horizon`` (:func:`pfjax.resources.check_fits`); ``horizon/dt`` above
    :data:`pfjax.resources.MAX_STEPS` steps; when ``dt`` does not divide ``horizon`` into whole steps
    (:func:`pfjax.resources.whole_steps`: a run is never rounded), ``dt`` if only the step differs
    from its default (``horizon`` is ``TrackConfig.horizon``), else ``horizon`` (the rule of
    :class:`pfjax.sim.settings.SimConfig`); ``window`` when the final window over which the limits
    are checked is longer than the horizon.
    """
    named = check_fits(horizon, dt, (TrackConfig.horizon, TrackConfig.dt))
    check_steps(horizon, dt, "horizon/dt")  # names both: the command line shows it as --horizon/--dt
    n = whole_steps(horizon, dt, named)
    if window is not None and window > horizon:
        raise InputError(f"window: must be <= horizon ({horizon:g} s), got {window:g}", "window")
    return n


def _choice(key: str, value, choices: tuple[str, ...]) -> str:
    if not isinstance(value, str) or value not in choices:
        raise InputError(f"{key}: expected one of {', '.join(choices)}, got {value!r}", key)
    return value


def _depth(value) -> float:
    """The stop-and-go depth in [0, 1] (nan and inf are out of range, as on the command line)."""
    if not errors.is_number(value):
        errors.number("stop_and_go", value)  # raises: not a number
    try:
        x = float(value)
    except OverflowError:
        x = math.inf if value > 0 else -math.inf
    if not 0.0 <= x <= 1.0:
        raise InputError(f"stop_and_go: expected a depth in [0, 1], got {errors.shown(x)}", "stop_and_go")
    return x


def _pair(key: str, value) -> tuple[float, float]:
    try:
        n = len(value)
    except TypeError:
        n = None
    if n != 2 or isinstance(value, (str, Mapping)):
        raise InputError(f"{key}: expected two numbers (along, left), got {value!r}", key)
    a, b = (errors.number(key, v) for v in value)
    return a, b


def _check(
    mode,
    p,
    l,
    gamma_max_deg,
    leader,
    speed,
    stop_and_go,
    a,
    k,
    v_max,
    omega_max_deg,
    offset,
    heading_error_deg,
    beta_r_deg,
    beta_f_deg,
    horizon,
    dt,
) -> dict:
    """Every argument checked and converted to float, in the order the command line checks its flags."""
    mode = _choice("mode", mode, MODES)
    leader = _choice("leader", leader, LEADERS)
    f = 1.0 if mode == "forward" else -1.0
    p = f if p is None else errors.number("p", p)
    l = f if l is None else errors.number("l", l)
    nonzero("p", p, "p")
    nonzero("l", l, "l")
    out = {
        "mode": mode,
        "leader": leader,
        "p": p,
        "l": l,
        "gamma_max_deg": errors.number("gamma_max_deg", gamma_max_deg, positive=True, below=90, unit=" deg"),
    }
    for key, v in (
        ("speed", speed),
        ("a", a),
        ("k", k),
        ("v_max", v_max),
        ("omega_max_deg", omega_max_deg),
        ("horizon", horizon),
        ("dt", dt),
    ):
        out[key] = errors.number(key, v, positive=True)
    out["stop_and_go"] = _depth(stop_and_go)
    out["offset"] = _pair("offset", offset)
    check_offset("offset", math.hypot(*out["offset"]))
    out["heading_error_deg"] = errors.number("heading_error_deg", heading_error_deg)
    out["beta_r_deg"] = errors.number("beta_r_deg", beta_r_deg, below=90, unit=" deg")
    out["beta_f_deg"] = errors.number("beta_f_deg", beta_f_deg, below=90, unit=" deg")
    check_time(out["horizon"], out["dt"])
    return out


@errors.arguments_checked
def run(
    mode="forward",
    *,
    p=None,
    l=None,
    gamma_max_deg=30.0,
    leader="line",
    speed=1.0,
    stop_and_go=0.0,
    a=FollowerParams().a,
    k=FocusGains().k,
    v_max=3.0,
    omega_max_deg=90.0,
    offset=(-0.5, 0.5),
    heading_error_deg=10.0,
    beta_r_deg=0.0,
    beta_f_deg=0.0,
    horizon=TrackConfig.horizon,
    dt=TrackConfig.dt,
) -> dict:
    """One run of a car-like follower tracking a leader through its focus point.

    The follower steers its reference point towards the focus point
    ``P_r = P_ref + l (cos(theta + p gamma), sin(theta + p gamma))`` by input-output linearisation
    with speed, steering and steering-rate limits, and the run is checked against Lemma 8.1
    (``lemma_consistent``: inside the lemma's bound, a run that ends ok has ``converged`` equal to
    ``phi_converged``; null outside the bound or for a failed run, where the lemma says nothing). The
    simulation runs in float64 (as ``pfjax track`` does), whatever ``jax_enable_x64`` says.
    All arguments are checked first (see Raises).

    Args:
        mode: ``"forward"`` (f = +1: reference point P_f, the follower drives forward) or
            ``"backward"`` (f = -1: P_b, the follower reverses).
        p: focus turning ratio, dimensionless, nonzero (default: 1 forward, -1 backward).
        l: focus distance, m, signed and nonzero (default: 1 forward, -1 backward).
        gamma_max_deg: steering limit, deg, in (0, 90).
        leader: the leader's motion: ``"line"``, ``"circle"``, ``"sine"`` or ``"lane-change"``.
        speed: the leader's speed V0, m/s, > 0.
        stop_and_go: depth of the leader's stop-and-go speed profile (period 10 s), dimensionless,
            in [0, 1] (0: constant speed; 1: the leader stops once a period).
        a: the follower's wheelbase, m, > 0 (default ``FollowerParams.a``).
        k: error decay rate of the linearised loop, 1/s, > 0 (default ``FocusGains.k``).
        v_max: the follower's speed limit, m/s, > 0.
        omega_max_deg: steering-rate limit, deg/s, > 0.
        offset: the follower's initial displacement ``(along, left)`` in the leader's frame, m
            (two numbers; a sequence, not a mapping), less than 50 m long: a run whose tracking
            error passes ``TrackConfig.z_fail`` (50 m) ends as ``diverged``.
        heading_error_deg: initial heading error, deg.
        beta_r_deg: constant rear-wheel slip angle, deg, |beta_r_deg| < 90.
        beta_f_deg: constant front-wheel slip angle, deg, |beta_f_deg| < 90.
        horizon: simulated time, s, > 0 (the command line's ``--horizon``): a whole number of
            steps ``dt`` (to a relative 1e-9, :data:`pfjax.resources.STEPS_RTOL`), never rounded; the result's
            ``T`` is ``round(horizon / dt) * dt``, equal to it up to float round-off (default
            ``TrackConfig.horizon``).
        dt: integrator step, s, in (0, horizon], at most 2e6 steps in ``horizon`` (default
            ``TrackConfig.dt``).

    Returns:
        The result ``pfjax track --json`` prints, beside which the command records its arguments,
        config hash, machine and the ``units`` of every number (:mod:`pfjax.cli.records`; the
        units by key: :data:`pfjax.tables.TRACK_UNITS`): the arguments used (``mode``, ``f``, ``p``, ``l``,
        ``gamma_max_deg``, ``leader``); the outcome (``converged``, ``phi_converged``, ``status``,
        ``status_code``, ``fail_time`` in s or None); the errors, of a failed run at its last step
        before the failure, as every metric (``final_error_norm``, m;
        ``final_phi_minus_pgamma``, rad; ``window_max_z``, m; ``window_max_phi_err``,
        rad; ``iae``, m s; ``final_d``, m); the steering (``max_abs_gamma_deg``, deg;
        ``limit_fraction``; ``min_abs_factor``); Lemma 8.1 (``lemma_p_bound``,
        ``inside_lemma_bound``, ``input_matrix_invertible_for_all_gamma``,
        ``zero_dynamics_stable_straight``, ``lemma_consistent``); ``tolerances`` (``window_s``, s; ``tol_z_m``, m;
        ``tol_phi_rad``, rad); ``final`` (the follower's final state); ``T`` (the simulated time, s)
        and ``dt`` (s).

    Raises:
        InputError: a bad argument; the message starts with its name (``"p: must be nonzero ..."``),
            or ``horizon/dt`` when the run would take more than 2e6 steps; ``horizon`` when it is
            not a whole number of steps, ``dt`` when only the step was changed from its default
            (:func:`check_time`).
    """
    c = _check(**locals())  # exactly the arguments above, by name
    import jax

    with jax.enable_x64(True):
        return _simulate(c)


def _simulate(c: dict) -> dict:
    import jax
    import numpy as np

    from pfjax.sim.slip_profiles import constant_slip
    from pfjax.tracking.geometry import lemma_bound, p_bound
    from pfjax.tracking.leader import by_name
    from pfjax.tracking.lemma import zero_dynamics_stable
    from pfjax.tracking.simulate import (
        TRACK_STATUS_NAMES,
        initial_states,
        scenario,
        simulate_one,
        stack,
        unstack,
    )

    f = 1 if c["mode"] == "forward" else -1
    pp, ll = c["p"], c["l"]
    gmax = math.radians(c["gamma_max_deg"])
    params = FollowerParams(
        a=c["a"], f=float(f), l=ll, p=pp, gamma_max=gmax, v_max=c["v_max"], omega_max=math.radians(c["omega_max_deg"])
    )
    ld = by_name(c["leader"], speed=c["speed"], depth=c["stop_and_go"])
    host = lambda tree: jax.tree_util.tree_map(np.asarray, tree)
    init = unstack(
        host(
            initial_states(
                stack([ld]),
                stack([params]),
                np.asarray([c["offset"]], dtype=float),
                np.asarray([math.radians(c["heading_error_deg"])]),
            )
        ),
        0,
    )
    slip = constant_slip(math.radians(c["beta_r_deg"]), math.radians(c["beta_f_deg"]))
    sc = scenario(params, ld, gains=FocusGains(k=c["k"]), init=init, slip=slip)
    cfg = TrackConfig(dt=c["dt"], horizon=c["horizon"], window=min(TrackConfig.window, c["horizon"] / 3))
    r = host(simulate_one(sc, config=cfg))
    m = r.metrics
    lo, hi = p_bound(gmax, f)
    status = int(r.status)
    return {
        "mode": c["mode"],
        "f": f,
        "p": pp,
        "l": ll,
        "gamma_max_deg": c["gamma_max_deg"],
        "leader": c["leader"],
        "converged": bool(m.converged),
        "phi_converged": bool(m.phi_converged),
        "final_error_norm": float(m.final_error_norm),
        "final_phi_minus_pgamma": float(m.final_phi_minus_pgamma),
        "max_abs_gamma_deg": math.degrees(float(m.max_abs_gamma)),
        "window_max_z": float(m.window_max_z),
        "window_max_phi_err": float(m.window_max_phi_err),
        "iae": float(m.iae),
        "final_d": float(m.final_d),
        "limit_fraction": float(m.limit_fraction),
        "min_abs_factor": float(m.min_abs_factor),
        "status": TRACK_STATUS_NAMES[status],
        "status_code": status,
        "fail_time": float(r.fail_time) if math.isfinite(float(r.fail_time)) else None,
        "lemma_p_bound": lemma_bound(gmax),
        "inside_lemma_bound": abs(pp) < lemma_bound(gmax),
        "input_matrix_invertible_for_all_gamma": bool(lo < pp < hi),
        # the lemma on this run: inside its bound a run that ends ok has z~ -> 0 exactly when
        # phi - p gamma -> 0 (false: a counterexample at these tolerances); null where it claims nothing
        "lemma_consistent": (
            bool(m.converged) == bool(m.phi_converged)
            if abs(pp) < lemma_bound(gmax) and TRACK_STATUS_NAMES[status] == "ok"
            else None
        ),
        "zero_dynamics_stable_straight": zero_dynamics_stable(c["speed"], float(f), params),
        "tolerances": {"window_s": cfg.window, "tol_z_m": cfg.tol_z, "tol_phi_rad": cfg.tol_phi},
        "final": {key: float(v) for key, v in r.final._asdict().items()},
        "T": cfg.n_steps * cfg.dt,
        "dt": cfg.dt,
    }
