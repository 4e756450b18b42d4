"""The paper reproduction's runs: the mixed H2/Hinf synthesis against the source's published gain,
the three source tests for every controller, and the 24 readings of the source's Table 3 PI gains
scored against its claims (:mod:`pfjax.reproduce.paper_study` runs them in order).

Each part takes the validated config as a dict (:class:`~pfjax.reproduce.paper_config.PaperStudy`
dumped) and a progress bar with an ``update(n)`` method.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import pandas as pd

from pfjax import controllers as C
from pfjax import paths
from pfjax.controllers.union import shared
from pfjax.paths import global_parameter, tangent_angle
from pfjax.reproduce.paper_config import sim_config
from pfjax.reproduce.run_claims import PI_THRESHOLDS, settled
from pfjax.sim import (
    STATUS_NAMES,
    SimConfig,
    constant_slip,
    simulate_batch,
    stack,
    unstack,
)
from pfjax.sim.scenario import PAPER_TESTS, make_scenario
from pfjax.synthesis import mixed_bounds_for_gain, mixed_h2_hinf, slip_design_plant
from pfjax.synthesis.norms import closed_loop, h2_norm, hinf_norm

TRACKERS = ("stanley", "pure-pursuit", "rear-wheel")
#: The reading of Table 3 adopted as the source's PI (:data:`pfjax.controllers.PAPER_PI`) as positions
#: in the printed order: gain -> index into ``source.table3``.
ADOPTED = {k: C.TABLE3_GAINS.index(v) for k, v in C.PAPER_PI.items()}


def source_pi(cfg) -> dict[str, float]:
    """The source's PI gains: the adopted reading (:data:`ADOPTED`) of the config's ``source.table3``."""
    t3 = cfg["source"]["table3"]
    return {k: float(t3[i]) for k, i in ADOPTED.items()}


def rel(a, b):
    return abs(a - b) / abs(b)


def fixed_path(name: str):
    """The fixed path ``name`` of the path registry (one of the source's tests;
    :func:`pfjax.paths.fixed_entry` refuses any other)."""
    build = paths.fixed_entry(name).build
    assert build is not None  # a fixed path (fixed_entry)
    return build()


class SourceTest(NamedTuple):
    """One of the source's tests travelled in the study's direction (``model.direction``)."""

    path: paths.Graph  # the source's graph y = f(x) as drawn, on the domain the run may use
    run_path: paths.Graph  # what the simulator follows, towards increasing x: path, or path turned (half_turn)
    pose0: tuple[float, float, float]  # start (x, y, theta) in run_path's frame, m, m, rad
    u0: float | None  # decreasing_x: x of the start's closest point on path (the mirror's foot), m

    @property
    def turned(self) -> bool:
        """``run_path`` is ``path`` turned half a turn (decreasing_x): :func:`to_world` turns the
        run's ``x``, ``y``, ``theta`` back."""
        return self.u0 is not None


def half_turn(path: paths.Graph) -> paths.Graph:
    """The graph ``y = f(x)`` turned half a turn about the origin, ``(x, y) -> (-x, -y)``: the graph
    ``y = -f(-x)`` (``y0``, ``a`` and the phase negated) on ``[-u_max, -u_min]``. Travelled towards
    increasing ``x``, it is ``path`` travelled towards decreasing ``x``, turned as a rigid body: the
    run's lateral error, heading error, curvature and metrics are those on ``path``."""
    return path._replace(y0=-path.y0, a=-path.a, phase=-path.phase, u_min=-path.u_max, u_max=-path.u_min)


def source_test(test: str, direction: str, path: paths.Graph | None = None) -> SourceTest:
    """The source's test ``test`` (its registered graph, or ``path``, and start pose) travelled in
    ``direction``. ``"increasing_x"``: as registered. ``"decreasing_x"``: from the same start point,
    the heading mirrored in the path's normal at the closest point ``u*``, ``theta -> 2 theta_p(u*) + pi
    - theta`` (the start's ``d`` and ``theta_e`` change sign: on the line, the mirror image of the
    run towards increasing ``x`` under the opposite slip), and the domain reflected about ``u*`` (as
    much path ahead as towards increasing ``x``); simulated on :func:`half_turn` of the path."""
    e = paths.entry(test)
    path = fixed_path(test) if path is None else path
    if e.start_pose is None or not isinstance(path, paths.Graph):
        raise ValueError(f"path {test!r}: the source's tests are graphs with a start pose")
    x0, y0, theta0 = e.start_pose
    if direction == "increasing_x":
        return SourceTest(path, path, (x0, y0, theta0), None)
    u = jax.jit(global_parameter)(path, jnp.asarray(x0), jnp.asarray(y0))
    theta = 2 * float(tangent_angle(path, u)) + math.pi - theta0
    lo, hi = 2 * u - path.u_max, 2 * u - path.u_min
    path = path._replace(u_min=lo.astype(path.u_min.dtype), u_max=hi.astype(path.u_max.dtype))
    pose0 = (-x0, -y0, math.remainder(theta + math.pi, 2 * math.pi))
    return SourceTest(path, half_turn(path), pose0, float(u))


def source_scenario(st: SourceTest, gains, cfg):
    """The run of ``st`` with ``gains`` and the config's vehicle and constant slip."""
    m = cfg["model"]
    return make_scenario(
        st.run_path,
        st.pose0,
        gains,
        slip=constant_slip(math.radians(m["beta_r_deg"]), math.radians(m["beta_f_deg"])),
        v=m["v"],
        L=m["L"],
        delta_max_deg=m["delta_max_deg"],
        convention=m["convention"],
    )


def run_batch(controller, gains_list, test, cfg, config: SimConfig):
    st = source_test(test, cfg["model"]["direction"])
    scs = stack([source_scenario(st, g, cfg) for g in gains_list])
    return simulate_batch(scs, controller=controller, config=config)


def traj_dict(r) -> dict:
    t = r.trajectory
    return {
        k: np.asarray(getattr(t, k))
        for k in ("t", "x", "y", "theta", "d", "theta_e", "kappa", "s", "delta_cmd", "delta")
    }


def to_world(traj: dict, st: SourceTest) -> dict:
    """A :func:`traj_dict` of a run of ``st`` in the frame of ``st.path`` (turned back if it ran on
    the turned path); ``d``, ``theta_e``, ``kappa`` and the steering are the same in both frames."""
    if not st.turned:
        return traj
    return {**traj, "x": -traj["x"], "y": -traj["y"], "theta": np.remainder(traj["theta"], 2 * np.pi) - np.pi}


def row_of(r, test, name, gains: dict, delta_max) -> dict:
    m = {k: float(v) for k, v in r.metrics._asdict().items()}
    tr = r.trajectory
    return {
        "path": test,
        "controller": name,
        **{f"gain_{k}": float(v) for k, v in gains.items()},
        **m,
        "status": STATUS_NAMES[int(r.status)],
        "final_d": float(r.final.d),
        "final_theta_e": float(r.final.theta_e),
        "final_delta": float(r.final.delta),
        "max_abs_delta_cmd": float(np.max(np.abs(np.asarray(tr.delta_cmd)))) if tr is not None else math.nan,
        "max_abs_delta": float(np.max(np.abs(np.asarray(tr.delta)))) if tr is not None else math.nan,
        "delta_max": delta_max,
    }


# ---------------------------------------------------------------------------------- parts


def part_synthesis(cfg) -> dict:
    m, src = cfg["model"], cfg["source"]
    plant = slip_design_plant(v=m["v"], L=m["L"])
    design = mixed_h2_hinf(plant, alpha=cfg["synthesis"]["alpha"], beta=cfg["synthesis"]["beta"])
    K_src = np.array(src["K"]).reshape(1, 2)
    A, Bw, Ci, C2 = closed_loop(plant, K_src)
    g_src = mixed_bounds_for_gain(plant, K_src, cfg["synthesis"]["alpha"], cfg["synthesis"]["beta"])
    a, b = cfg["synthesis"]["alpha"], cfg["synthesis"]["beta"]
    ours = design.to_dict()
    gi, g2 = design.gamma_inf, design.gamma_2
    if gi is None or g2 is None:
        raise ValueError("synthesis: the mixed design returned no bounds")
    K = [float(k) for k in design.K.ravel()]
    return {
        "ours": {**ours, "K": K, "objective": a * gi**2 + b * g2**2},
        "source_published": {"K": src["K"], "gamma_inf": src["gamma_inf"], "gamma_2": src["gamma_2"]},
        "source_K_checked_by_pfjax": {
            "gamma_inf_certified": g_src[0],
            "gamma_2_certified": g_src[1],
            "objective": a * g_src[0] ** 2 + b * g_src[1] ** 2,
            "hinf_norm": hinf_norm(A, Bw, Ci),
            "h2_norm": h2_norm(A, Bw, C2),
            "closed_loop_poles": [[p.real, p.imag] for p in np.linalg.eigvals(A)],
        },
        "rel_diff": {
            "K_d": rel(K[0], src["K"][0]),
            "K_theta": rel(K[1], src["K"][1]),
            "gamma_inf": rel(design.gamma_inf, src["gamma_inf"]),
            "gamma_2": rel(design.gamma_2, src["gamma_2"]),
        },
    }


def part_paper_runs(cfg, K_ours, pbar) -> tuple[list[dict], dict]:
    """The three tests for every controller; returns metric rows and trajectories[test][controller]."""
    config = sim_config(cfg)
    dmax = math.radians(cfg["model"]["delta_max_deg"])
    K_src, pi = cfg["source"]["K"], source_pi(cfg)
    entries = {
        "mixed": (C.state_feedback_params(K_ours), {"k_d": K_ours[0], "k_theta": K_ours[1]}),
        "paper-k": (C.state_feedback_params(K_src), {"k_d": K_src[0], "k_theta": K_src[1]}),
        "pi": (C.pi_params(**pi), pi),
    }
    if cfg["trackers"]:  # their gain columns carry the controller's name: k_d, k_theta are another gain's here
        entries.update(
            {
                k: (
                    C.entry(k).make_params(),
                    {f"{k.replace('-', '_')}_{g}": v for g, v in C.flat_gains(C.entry(k)).items()},
                )
                for k in TRACKERS
            }
        )
    rows: list[dict] = []
    trajs: dict[str, dict] = {t: {} for t in PAPER_TESTS}
    tests = {t: source_test(t, cfg["model"]["direction"]) for t in PAPER_TESTS}
    # every controller through the union of their kinds: one compiled program for all the runs
    runs = shared({name: (C.resolve(name)[0].controller, gains, shown) for name, (gains, shown) in entries.items()})
    for name, (controller, gains, shown) in runs.items():
        for test in PAPER_TESTS:
            r = unstack(run_batch(controller, [gains], test, cfg, config), 0)
            rows.append(row_of(r, test, name, shown, dmax))
            trajs[test][name] = to_world(traj_dict(r), tests[test])
            pbar.update(1)
    return rows, trajs


def part_pi_readings(cfg, rows, pbar) -> tuple[pd.DataFrame, dict]:
    """Score each of the 24 readings of Table 3 against the source's claims about its PI."""
    src = cfg["source"]
    readings = C.table3_assignments(src["table3"])
    adopted, th = C.table3_label(source_pi(cfg)), PI_THRESHOLDS
    config = sim_config(cfg)
    res = {t: run_batch(C.pi, list(readings.values()), t, cfg, config) for t in PAPER_TESTS}
    pbar.update(1)
    mixed = {r["path"]: r for r in rows if r["controller"] == "mixed"}
    out, line_traces = [], {}
    line_test = source_test("line", cfg["model"]["direction"])
    for i, (label, g) in enumerate(readings.items()):
        per = {t: unstack(res[t], i) for t in PAPER_TESTS}
        line_traces[label] = to_world(traj_dict(per["line"]), line_test)
        rec: dict = {"reading": label, **{k: float(v) for k, v in g._asdict().items() if k != "k_aw"}}
        conv, sat_ok, better = True, True, True
        for t, r in per.items():
            conv &= settled(
                int(r.status) == 0, float(r.metrics.settling_time), cfg["sim"]["horizon"], cfg["sim"]["steady_window"]
            )
            sat_ok &= float(r.metrics.sat_fraction) < th["sat"]
            better &= mixed[t]["iae"] < float(r.metrics.iae)
            rec[f"{t}_status"] = STATUS_NAMES[int(r.status)]
            rec[f"{t}_settling_time"] = float(r.metrics.settling_time)
            rec[f"{t}_steady_abs_d_mm"] = 1000 * float(r.metrics.steady_abs_d)
            rec[f"{t}_sat_fraction"] = float(r.metrics.sat_fraction)
            rec[f"{t}_iae"] = float(r.metrics.iae)
        line = per["line"]
        ss_mm = 1000 * float(line.metrics.steady_abs_d)
        rec["line_final_delta_deg"] = math.degrees(float(line.final.delta))
        rec["max_sat_fraction"] = max(rec[f"{t}_sat_fraction"] for t in PAPER_TESTS)
        rec["c_converges_all"] = conv
        rec["c_steering_within_limit"] = sat_ok
        rec["c_line_delta_near_source"] = (
            abs(math.degrees(float(line.final.delta)) - src["line_delta_deg"]) < th["delta_deg"]
        )
        rec["c_line_ss_near_source"] = (
            src["line_ss_pi_mm"] / th["ss_factor"] <= ss_mm <= th["ss_factor"] * src["line_ss_pi_mm"]
        )
        # Not a criterion: "mixed beats PI" is a claim under test, so it must not pick the reading.
        rec["info_mixed_better_iae_all"] = better
        crit = [k for k in rec if k.startswith("c_")]
        rec["n_criteria_met"] = sum(bool(rec[k]) for k in crit)
        rec["consistent"] = all(bool(rec[k]) for k in crit)
        rec["is_default"] = label == adopted
        out.append(rec)
    df = pd.DataFrame(out).sort_values(["n_criteria_met", "line_iae"], ascending=[False, True])
    df.attrs["filters"] = pi_filter_stats(df, src)
    return df, line_traces


def _pi_consistent(df: pd.DataFrame, src: dict, sat: float, delta_deg: float, ss_factor: float) -> pd.Series:
    ss = df["line_steady_abs_d_mm"]
    return (
        df.c_converges_all
        & (df.max_sat_fraction < sat)
        & ((df.line_final_delta_deg - src["line_delta_deg"]).abs() < delta_deg)
        & (ss >= src["line_ss_pi_mm"] / ss_factor)
        & (ss <= src["line_ss_pi_mm"] * ss_factor)
    )


def pi_filter_stats(df: pd.DataFrame, src: dict) -> dict:
    """How many of the 24 readings pass each filter, which pass all, and whether the choice holds
    when each threshold is halved or doubled (the others at their values)."""
    t = PI_THRESHOLDS
    passing = {
        "converges on all three paths": int(df.c_converges_all.sum()),
        f"saturated < {100 * t['sat']:g} % of every run": int(df.c_steering_within_limit.sum()),
        f"line steering within {t['delta_deg']:g}° of {src['line_delta_deg']:g}°": int(
            df.c_line_delta_near_source.sum()
        ),
        f"line steady |d| within a factor {t['ss_factor']:g} of {src['line_ss_pi_mm']:g} mm": int(
            df.c_line_ss_near_source.sum()
        ),
    }
    chosen = set(df[df.consistent].reading)
    adopted = df[df.is_default].reading.tolist()
    cases, unique = 0, 0
    for name in t:
        for f in (0.5, 2.0):
            ok = _pi_consistent(df, src, **{**t, name: t[name] * f})
            cases += 1
            unique += int(set(df[ok].reading) == chosen and len(chosen) == 1)
    return {
        "passing": passing,
        "consistent": len(chosen),
        "consistent_readings": sorted(chosen),
        "adopted_reading": adopted[0] if adopted else None,  # the reading the study's PI rows run
        "sensitivity_cases": cases,
        "sensitivity_unique": unique,
        "thresholds": dict(t),
    }
