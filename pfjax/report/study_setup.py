"""The Monte Carlo study report's set-up section: what was varied and how, what was held fixed,
the paths, the controllers and their gains, the simulation and the success criterion, in words."""

from __future__ import annotations

from pfjax.controllers import style
from pfjax.models import DYNAMIC_MODELS
from pfjax.montecarlo.sampling import SLIP_COLUMNS
from pfjax.report.study_format import fmt_dist, fmt_gains, missing

__all__ = ["controller_rows", "path_rows", "setup", "uncertain_rows"]


def _path_description(kind: str) -> str:
    """A registered path's one-line description (:data:`pfjax.paths.PATHS`)."""
    from pfjax.paths import PATHS

    return PATHS[kind].description if kind in PATHS else kind


def uncertain_rows(cfg: dict) -> list[dict]:
    """Every quantity of a run, its distribution in words, and whether it varies between runs."""
    veh, slip, ini, noise = cfg["vehicle"], cfg["slip"], cfg["initial"], cfg["noise"]
    rate = veh["delta_rate_max_deg"]
    rows = [
        ("speed v [m/s]", veh["speed"]),
        ("wheelbase L [m]", veh["L"]),
        ("steering limit δ_max [deg]", veh["delta_max_deg"]),
        ("steering rate limit [deg/s]", "none" if rate is None or missing(rate) or rate == "inf" else rate),
        ("slip model", f"{slip['kind']} (convention: {veh['convention']})"),
        ("rear slip β_r [deg]", slip["beta_r_deg"]),
        ("front slip β_f [deg]", slip["beta_f_deg"]),
    ]
    units = {
        "step_time_s": "step time [s]",
        "step_r_deg": "rear step [deg]",
        "step_f_deg": "front step [deg]",
        "amp_r_deg": "rear sinusoid amplitude [deg]",
        "amp_f_deg": "front sinusoid amplitude [deg]",
        "freq_hz": "sinusoid frequency [Hz]",
        "ou_sigma_deg": "OU stationary std [deg]",
        "ou_tau_s": "OU time constant [s]",
    }
    rows += [(units[k], slip[k]) for k in SLIP_COLUMNS[slip["kind"]]]
    if veh.get("model", "kinematic") in DYNAMIC_MODELS:  # slip from the tyre forces: the model's settings instead
        rows = [
            ("speed reference v [m/s]", veh["speed"]),
            ("vehicle model", f"single-track (CommonRoad {veh['model'].upper()}), parameter set {veh['params']}"),
            ("friction μ", "the parameter set's" if veh["mu"] is None else veh["mu"]),
            ("steering actuator time constant [s]", veh["tau_delta_s"]),
            ("speed loop gain [1/s]", veh["k_v"]),
        ]
    if slip["kind"] == "sinusoid":
        rows.append(("sinusoid phase", "uniform on [0, 2π), per axle"))
    if slip["kind"] == "ou":
        rows.append(("OU sampling period [s]", slip["seq_dt"]))
    rows += [
        ("start along the path [m]", ini["start_along_m"]),
        ("initial lateral offset [m]", ini["lateral_offset"]),
        ("initial heading error [deg]", ini["heading_error_deg"]),
        ("measurement noise on d [m]", f"normal, std {noise['sigma_d']:g}" if noise["sigma_d"] else "none"),
        (
            "measurement noise on θ_e [deg]",
            f"normal, std {noise['sigma_theta_e_deg']:g}" if noise["sigma_theta_e_deg"] else "none",
        ),
    ]
    uncertain = [
        {"name": n, "dist": fmt_dist(d), "varies": isinstance(d, dict) and d.get("dist") not in (None, "constant")}
        for n, d in rows
    ]
    return uncertain


def path_rows(cfg: dict) -> list[dict]:
    """The study's paths: name, kind and geometry in words."""
    paths = []
    for p in cfg["paths"]:
        extra = {
            "circle": f"radius {fmt_dist(p['radius'])} m",
            "random": f"random smooth spline, length {p['length']:g} m, |κ| ≤ {p['curvature_margin']:g} · tan(δ_max)/L, "
            f"{p['n_waypoints']} waypoints, one per run",
            "spline": f"user-defined: natural cubic spline through {len(p.get('points') or [])} points, "
            f"from ({(p.get('points') or [[0, 0]])[0][0]:g}, {(p.get('points') or [[0, 0]])[0][1]:g}) m",
        }
        paths.append(
            {
                "name": p.get("name") or p["kind"],
                "kind": p["kind"],
                "detail": extra.get(p["kind"]) or _path_description(p["kind"]),
            }
        )
    return paths


def controller_rows(cfg: dict, summary: dict) -> list[dict]:
    """The study's controllers: name, type, how it was designed, its gains."""
    ctrls = []
    for c in cfg["controllers"]:
        gains = summary["controllers"].get(c["name"], {}).get("gains", {})
        how = {
            "lmi": f"mixed H2/H∞ LMI design (α = {c['alpha']:g}, β = {c['beta']:g}) at the nominal speed and wheelbase",
            "state_feedback": "state feedback δ = K [d, θ_e]",
        }.get(c["type"]) or style(c["type"])["label"]
        ctrls.append(
            {
                "name": c["name"],
                "type": c["type"],
                "how": how,
                "gains": fmt_gains(gains, "defaults"),
            }
        )
    return ctrls


def setup(cfg: dict, summary: dict) -> dict:
    """The study set-up: what was varied and how, what was held fixed, and the success criterion."""
    sim, m = cfg["sim"], cfg["margin"]
    return {
        "uncertain": uncertain_rows(cfg),
        "paths": path_rows(cfg),
        "controllers": controller_rows(cfg, summary),
        "n_runs": cfg["n_runs"],
        "seed": cfg["seed"],
        "dtype": cfg["dtype"],
        "chunk_size": cfg["chunk_size"],
        "sim": f"horizon {sim['horizon']:g} s, RK4 step {1000 * sim['dt']:g} ms, controller every {sim['control_every']} step(s); "
        f"failure when |d| > {sim['d_fail']:g} m; steady state = last {sim['steady_window']:g} s; "
        f"settled within ±{100 * sim['settle_band']:g} cm",
        "success": f"|d| ≤ {100 * cfg['success']['band']:g} cm at every sample from t = {cfg['success']['from_s']:g} s "
        f"to the end of the horizon, and no failure flag (status 'ok')",
        "margin": (
            f"{m['n_per_amplitude']} runs per amplitude, per path and per controller at constant slip of magnitude A "
            f"(random sign) on {', '.join(m['axes'])}, A ∈ {{{', '.join(f'{a:g}' for a in m['amplitudes_deg'])}}} deg, "
            f"everything else sampled as above; margin = largest A with success ≥ 1 − ε = {100 * (1 - m['eps']):g} % "
            f"there and at every smaller A"
        )
        if m["enabled"]
        else "not run",
    }
