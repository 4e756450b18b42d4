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
from pfjax.dynamic_study.config import KinematicVsDynamic, dynamic, kinematic, kinematic_arm
from pfjax.models import single_track as st
from pfjax.montecarlo.dists import Dist
from pfjax.montecarlo.scenario_config import NoiseSpec, SimSpec
from pfjax.tables import unit_powers

ROBOT_WHEELBASE = 0.2  # m, the source robot's (the kinematic studies' L)


def froude_exponent(unit: str) -> float | None:
    """The exponent ``e`` of a gain's Froude scaling, ``gain x S^e`` (lengths x ``S``, times x
    ``sqrt(S)``): for a unit ``m^a s^b`` (``rad`` and ``1`` dimensionless), ``e = a + b / 2``
    (``rad/(m s)`` -> -1.5, ``m/s`` -> 0.5). None for a unit written otherwise (a controller
    registered without units: :data:`pfjax.controllers.UNSTATED`)."""
    powers = unit_powers(unit)
    return None if powers is None else powers[0] + powers[1] / 2


def scaled_gains(c: dict, s: float, key: str) -> dict:
    """A study's controller ``c`` (its config table) with its gains Froude-scaled by ``S = s``: every
    scalar gain of a registered controller (``K`` by its labels, ``gains``, the defaults) by its unit
    (:func:`froude_exponent`), written as ``gains``. A design made at the operating point (``lmi``,
    ...) is made at the car's speed and wheelbase, so only the gains given over it are scaled; a
    fixed design (``paper_k``) has all its gains scaled, written as ``gains`` over it. A gain whose
    unit is not in m, s and rad raises an :class:`~pfjax.errors.InputError` naming ``key``."""
    e, d = C.resolve(c["type"], f"{key}.type")
    if d is not None and not d.fixed:
        given = c.get("gains", {})
        return {**c, "gains": _scaled(e, given, s, key)} if given else c
    flat = C.flat_gains(e) if d is None else {**C.flat_gains(e), **d.make(1.0, 1.0)}  # fixed: at any point
    K = c.get("K")
    if K is not None and "K" in e.labels and len(K) == len(e.labels["K"]):  # else the config refuses it
        flat.update(zip(e.labels["K"], K))
        c = {k: v for k, v in c.items() if k != "K"}
    flat.update(c.get("gains", {}))
    return {**c, "gains": _scaled(e, flat, s, key)}


def _scaled(e, gains: dict, s: float, key: str) -> dict:
    """Scalar gains of the controller ``e`` Froude-scaled by ``S = s`` by their units."""
    from pfjax import errors

    units, out = C.gain_units(e), {}
    for k, v in gains.items():
        x = froude_exponent(units.get(k, C.UNSTATED))
        if x is None:
            raise errors.InputError(
                f"{key}.type: the car arms scale {e.name}'s gains by their units, and {k}'s is "
                f"{units.get(k, C.UNSTATED)!r}, not one in m, s and rad (pfjax.controllers.register(units=...))",
                f"{key}.type",
            )
        out[k] = v * s**x
    return out


def _dynamic(spec: dict, config: KinematicVsDynamic, mu=None) -> dict:
    return dynamic(copy.deepcopy(spec), config.dynamic_mu() if mu is None else mu)


def _kinematic(spec: dict, a: float) -> dict:
    out = kinematic(spec)  # without the dynamic vehicle's actuator and speed loop
    slip = {"dist": "uniform", "low": -a, "high": a} if a > 0 else 0.0
    out["slip"] = {"kind": "constant", "beta_r_deg": slip, "beta_f_deg": slip}
    return out


def arms(config: KinematicVsDynamic, designed: list[dict] | None = None) -> dict[str, dict]:
    """Arm name -> its study config (pfjax's study schema)."""
    base = {**copy.deepcopy(config.study), "name": config.name}
    a_max = max(config.slip_ranges_deg)
    out = {"dynamic": _dynamic(base, config), config.grip_arm: _dynamic(base, config, config.mu_grip)}
    for a in config.slip_ranges_deg:  # the config refuses ranges that name the same arm
        out[kinematic_arm(a)] = _kinematic(base, a)
    if designed:
        with_designs = {**base, "controllers": designed}
        out["designs_dynamic"] = _dynamic(with_designs, config)
        out[kinematic_arm(a_max, "designs_kinematic_")] = _kinematic(with_designs, a_max)
    if config.car.enabled:
        car = car_study(config)
        out["car_dynamic"] = _dynamic(car, config)
        out["car_dynamic"]["vehicle"].update(params=config.car.params)
        for key in ("L", "delta_max_deg", "delta_rate_max_deg"):
            out["car_dynamic"]["vehicle"].pop(key, None)
        for a in sorted({a_max, 0.0}, reverse=True):
            out[kinematic_arm(a, "car_kinematic_")] = _kinematic(car, a)
    return out


def _scale(d, f: float):
    """A length, speed or time (a number or a distribution table, :mod:`pfjax.montecarlo.dists`) in
    units ``f`` times larger (``f > 0``): a number, and every location and scale parameter of a
    table (``value``, ``low``, ``high``, ``mean``, ``std``, each of ``values``), times ``f``."""
    if not isinstance(d, dict):
        return d * f
    dist = Dist.model_validate(d)
    scaled = {k: [x * f for x in v] if k == "values" else v * f for k, v in dist.numbers().items()}
    return {"dist": dist.dist, **scaled}


def car_study(config: KinematicVsDynamic) -> dict:
    """The robot study scaled to the car (module docstring): lengths x S, speeds and times x sqrt(S)
    (the horizon rounded to whole steps of the car's ``dt``; the failure, settling and success bands
    and the lateral noise are lengths too), the paths as splines through the scaled source paths, the
    controllers' gains Froude-scaled by their units (:func:`scaled_gains`); the steering actuator's
    time constant (s) and the speed loop's gain (1/s) are the dynamic arms' (``study.vehicle``, the
    schema's defaults where not given), times ``sqrt(S)`` and ``1 / sqrt(S)``."""
    p = st.parameter_set(config.car.params)
    vehicle = config.dynamic_vehicle()
    s = float(p.l_f + p.l_r) / ROBOT_WHEELBASE
    rs = math.sqrt(s)
    spec = copy.deepcopy(config.study)
    spec["name"] = config.name
    spec["n_runs"] = spec["chunk_size"] = config.car.n_runs
    sim = spec["sim"]
    # the scaled horizon to whole car steps (the simulator refuses a fraction of a step)
    horizon = round(sim["horizon"] * rs / config.car.dt) * config.car.dt
    given = lambda section, table, key: table.get(key, section.model_fields[key].default)  # or the schema's default
    sim.update(dt=config.car.dt, horizon=horizon, steady_window=given(SimSpec, sim, "steady_window") * rs)
    for key in ("d_fail", "settle_band"):  # lengths: the failure and settling bands
        sim[key] = given(SimSpec, sim, key) * s
    if "noise" in spec:  # the measured lateral position's noise is a length; the heading's an angle
        spec["noise"] = {**spec["noise"], "sigma_d": given(NoiseSpec, spec["noise"], "sigma_d") * s}
    spec["success"] = {"band": spec["success"]["band"] * s, "from_s": spec["success"]["from_s"] * rs}
    ini = spec["initial"]
    ini["start_along_m"], ini["lateral_offset"] = _scale(ini["start_along_m"], s), _scale(ini["lateral_offset"], s)
    spec["vehicle"] = {
        "speed": _scale(spec["vehicle"]["speed"], rs),
        "tau_delta_s": vehicle.tau_delta_s * rs,
        "k_v": vehicle.k_v / rs,
    }
    # the kinematic arms get the car's wheelbase, steering limit and steering-rate limit (0.4 rad/s for
    # CommonRoad's cars), so that the arms differ by the tyres only
    spec["vehicle"].update(
        L=p.l_f + p.l_r, delta_max_deg=math.degrees(p.delta_max), delta_rate_max_deg=math.degrees(p.v_delta_max)
    )
    spec["paths"] = [{"kind": "spline", "name": q["kind"], "points": scaled_path(q["kind"], s)} for q in spec["paths"]]
    spec["controllers"] = [scaled_gains(c, s, f"study.controllers[{i}]") for i, c in enumerate(spec["controllers"])]
    return spec


def _config_key(arm: str, key: str, grip: str) -> str:
    """The study config's key behind the key ``key`` of arm ``arm``'s study config (``grip``: the
    high-friction arm's name): the dynamic arms' friction comes from ``mu_low``, ``mu_high`` and
    ``mu_grip``, the kinematic arms' slip from ``slip_ranges_deg``; every other key is
    ``study.<key>``."""
    if arm.startswith("car_"):
        if key in ("sim.dt", "sim.horizon"):  # the car's step, and its horizon in whole steps of it
            return "car.dt"
        if key in ("n_runs", "chunk_size"):
            return "car.n_runs"
        if key == "vehicle.params":
            return "car.params"
    kinematic = "kinematic_" in arm
    if key == "vehicle.mu" and not kinematic:
        return "mu_grip" if arm == grip else "mu_high"
    if key.startswith("slip.") and kinematic:
        return "slip_ranges_deg"
    return f"study.{key}"


def check(config: KinematicVsDynamic) -> None:
    """Every arm's study config (:func:`arms`, the designs' arms as their source arms) checked as
    :func:`pfjax.run_study` checks it before it simulates (the study schema, the simulation step,
    the memory of a chunk);
    :class:`pfjax.config.ConfigError` with one line naming the key of ``config`` (``study.sim.dt``,
    ``car.dt``, ...) and the arm. :func:`pfjax.dynamic_study.runs.run` calls it before anything else."""
    from pydantic import ValidationError

    from pfjax.config import ConfigError, format_error
    from pfjax.errors import InputError
    from pfjax.montecarlo.checks import check_resources
    from pfjax.montecarlo.config import StudySpec

    grip = config.grip_arm
    if config.car.enabled:
        for i, q in enumerate(config.study["paths"]):
            e = paths.PATHS.get(q.get("kind"))
            if e is None or e.build is None or e.parametric or set(q) - {"kind", "name"}:
                raise ConfigError(
                    f"study.paths[{i}].kind: the car arms scale fixed paths "
                    f"({', '.join(k for k in paths.fixed_paths() if not paths.PATHS[k].parametric)}) given by their "
                    f"kind alone, got {q!r}; set car.enabled = false to run a study of other paths"
                )
    for arm, spec in arms(config).items():
        try:
            validated = StudySpec.model_validate(spec)
            check_resources(validated, report=False)
        except ValidationError as e:
            message = format_error(e, StudySpec)
        except InputError as e:
            message = str(e)
        else:
            continue
        key, _, what = message.partition(": ")
        raise ConfigError(f"{_config_key(arm, key, grip)}: {what} (arm {arm})")


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


__all__ = ["ROBOT_WHEELBASE", "arms", "car_study", "check", "froude_exponent", "scaled_gains", "scaled_path"]
