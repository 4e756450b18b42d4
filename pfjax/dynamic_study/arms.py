"""The study's arms as Monte Carlo study configs (pfjax's study schema), all on the same runs: run
``i`` of a path starts from the same pose, speed and friction in every arm of its scale (common
random numbers, so differences between arms are paired).

* robot scale (the robot parameter set, speed and friction ``mu`` sampled): the dynamic arm, the
  same vehicle on a high-friction surface (``mu_grip``), and kinematic arms with constant slip
  uniform on ``+-A`` per axle for each ``A`` of ``slip_ranges_deg``;
* designs (:mod:`pfjax.dynamic_study.designs`) on the dynamic arm and the kinematic ``+-A_max`` arm;
* passenger-car scale: CommonRoad's vehicle 2 on the source's paths scaled by the wheelbase ratio
  ``S = l_car / 0.2 m``, with Froude scaling of speed and time (``x sqrt(S)``), dynamic and kinematic.
"""

from __future__ import annotations

import copy
import math

import numpy as np

from pfjax import controllers as C
from pfjax import paths
from pfjax.dynamic_study.config import KinematicVsDynamic
from pfjax.models import single_track as st

ROBOT_WHEELBASE = 0.2  # m, the source robot's (the kinematic studies' L)
#: Froude scaling exponents of the controllers' gains (the gain's unit in m and s -> S^exponent).
GAIN_SCALING = {"kp_d": -1.0, "ki_d": -1.5, "ki_theta": -0.5, "k_aw": -0.5, "k": -0.5, "k_soft": 0.5}


def _dynamic(spec: dict, config: KinematicVsDynamic, mu=None) -> dict:
    out = copy.deepcopy(spec)
    out["vehicle"] = {**out.get("vehicle", {}), "model": "st"}
    out["vehicle"]["mu"] = mu if mu is not None else {"dist": "uniform", "low": config.mu_low, "high": config.mu_high}
    return out


def _kinematic(spec: dict, a: float) -> dict:
    out = copy.deepcopy(spec)
    for key in ("tau_delta_s", "k_v"):  # the dynamic vehicle's actuator and speed loop
        out.get("vehicle", {}).pop(key, None)
    slip = {"dist": "uniform", "low": -a, "high": a} if a > 0 else 0.0
    out["slip"] = {"kind": "constant", "beta_r_deg": slip, "beta_f_deg": slip}
    return out


def arms(config: KinematicVsDynamic, designed: list[dict] | None = None) -> dict[str, dict]:
    """Arm name -> its study config (pfjax's study schema)."""
    base = {**copy.deepcopy(config.study), "name": config.name}
    a_max = max(config.slip_ranges_deg)
    grip = f"dynamic_mu{config.mu_grip:g}"
    out = {"dynamic": _dynamic(base, config), grip: _dynamic(base, config, config.mu_grip)}
    for a in config.slip_ranges_deg:
        out[f"kinematic_{a:g}deg"] = _kinematic(base, a)
    if designed:
        with_designs = {**base, "controllers": designed}
        out["designs_dynamic"] = _dynamic(with_designs, config)
        out[f"designs_kinematic_{a_max:g}deg"] = _kinematic(with_designs, a_max)
    if config.car.enabled:
        car = car_study(config)
        out["car_dynamic"] = _dynamic(car, config)
        out["car_dynamic"]["vehicle"].update(params=config.car.params)
        for key in ("L", "delta_max_deg", "delta_rate_max_deg"):
            out["car_dynamic"]["vehicle"].pop(key, None)
        for a in sorted({a_max, 0.0}, reverse=True):
            out[f"car_kinematic_{a:g}deg"] = _kinematic(car, a)
    return out


def _scale(d, f: float):
    """A distribution table or a number, its lengths (``low``, ``high``, ``value``) times ``f``."""
    if isinstance(d, dict):
        return {k: (v * f if k in ("low", "high", "value") else v) for k, v in d.items()}
    return d * f


def car_study(config: KinematicVsDynamic) -> dict:
    """The robot study scaled to the car (module docstring): lengths x S, speeds and times x sqrt(S)
    (the horizon rounded to whole steps of the car's ``dt``), the paths as splines through the scaled source paths, the controllers' gains Froude-scaled."""
    p = st.parameter_set(config.car.params)
    s = float(p.l_f + p.l_r) / ROBOT_WHEELBASE
    rs = math.sqrt(s)
    spec = copy.deepcopy(config.study)
    spec["name"] = config.name
    spec["n_runs"] = spec["chunk_size"] = config.car.n_runs
    sim = spec["sim"]
    # the scaled horizon to whole car steps (the simulator refuses a fraction of a step)
    horizon = round(sim["horizon"] * rs / config.car.dt) * config.car.dt
    sim.update(dt=config.car.dt, horizon=horizon, steady_window=sim["steady_window"] * rs)
    spec["success"] = {"band": spec["success"]["band"] * s, "from_s": spec["success"]["from_s"] * rs}
    ini = spec["initial"]
    ini["start_along_m"], ini["lateral_offset"] = _scale(ini["start_along_m"], s), _scale(ini["lateral_offset"], s)
    spec["vehicle"] = {"speed": _scale(spec["vehicle"]["speed"], rs), "tau_delta_s": 0.05 * rs, "k_v": 5.0 / rs}
    # the kinematic arms get the car's wheelbase, steering limit and steering-rate limit (0.4 rad/s for
    # CommonRoad's cars), so that the arms differ by the tyres only
    spec["vehicle"].update(
        L=p.l_f + p.l_r, delta_max_deg=math.degrees(p.delta_max), delta_rate_max_deg=math.degrees(p.v_delta_max)
    )
    spec["paths"] = [{"kind": "spline", "name": q["kind"], "points": scaled_path(q["kind"], s)} for q in spec["paths"]]
    for c in spec["controllers"]:
        if c["type"] in ("pi", "stanley"):
            e, _ = C.resolve(c["type"], "type")
            flat = {**C.flat_gains(e), **c.get("gains", {})}
            c["gains"] = {k: v * s ** GAIN_SCALING.get(k, 0.0) for k, v in flat.items()}
    return spec


def scaled_path(kind: str, s: float, length: float = 45.0, n: int = 301) -> list[list[float]]:
    """Points of a source path (``kind``) from its study start (``start_u``) over ``length`` m of arc,
    scaled by ``s`` (m); equally spaced in arc length (``n`` points: a cubic spline through them
    reproduces the curvature to about 1e-3 relative)."""
    e = paths.entry(kind)
    assert e.build is not None
    shape = e.build()
    u = np.linspace(e.start_u, e.start_u + length, 20 * n)
    x, y = (np.asarray(a, float) for a in shape.point(u))
    arc = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(x), np.diff(y)))])
    keep = np.searchsorted(arc, np.linspace(0.0, length, n))
    keep = np.unique(np.minimum(keep, len(u) - 1))
    return [[float(s * x[i]), float(s * y[i])] for i in keep]


__all__ = ["GAIN_SCALING", "ROBOT_WHEELBASE", "arms", "car_study", "scaled_path"]
