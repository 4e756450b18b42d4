"""The drift model (CommonRoad's STD) on the path-following loop: in the tyres' linear range it follows
the ST model (the two share the cornering stiffness: ``mu C_S = p_ky1`` at CommonRoad's ``mu``); at low
friction its tyres saturate where the ST model's linear tyres do not; the study config, the API and the
command line take ``model = "std"`` and refuse the robot set."""

from __future__ import annotations

import numpy as np
import pytest

from pfjax import controllers as C
from pfjax.errors import InputError
from pfjax.paths import shapes
from pfjax.sim import SimConfig, stack, unstack
from pfjax.sim import dynamic as dyn
from pfjax.sim.scenario import make_dynamic_scenario


def _run(model, mu, radius, v=10.0, horizon=8.0):
    e, _ = C.resolve("stanley", "--controller")
    gains = C.params_from_flat(e, C.flat_gains(e))
    path = shapes.circle(radius=radius, cy=radius)
    sc = make_dynamic_scenario(path, (0.0, 0.5, 0.0), gains, params="vehicle2", mu=mu, v=v, model=model)
    cfg = SimConfig(dt=0.002, horizon=horizon, record=True, control_every=1)
    return unstack(dyn.simulate_batch(stack([sc]), controller=e.controller, config=cfg), 0)


def test_drift_model_follows_the_st_model_in_the_linear_range():
    """Vehicle 2 at 10 m/s on a 100 m circle (lateral acceleration 1 m/s^2, a tenth of the friction
    limit): the lateral errors of the two models agree to 5 mm over 8 s (the ST model's slip angles
    are the linearised ones, and its speed loop acts on the speed directly, the STD's through the tyres)."""
    st_run, std_run = _run("st", 1.0489, 100.0), _run("std", 1.0489, 100.0)
    assert int(std_run.status) == 0 and int(st_run.status) == 0
    gap = np.max(np.abs(np.asarray(st_run.trajectory.d) - np.asarray(std_run.trajectory.d)))
    assert gap < 0.005, gap
    assert float(std_run.slip.max_abs_beta_r_deg) > 0.05  # the tyres slipped
    assert abs(float(std_run.trajectory.v[-1]) - 10.0) < 0.05  # the speed loop holds through the wheels


def test_drift_tyres_saturate_at_low_friction():
    """At mu = 0.2 on a 30 m circle at 10 m/s (3.3 m/s^2 asked, 2 m/s^2 available) the drift model
    cannot hold the path (its tyres saturate); the ST model's linear tyres can: their lateral force
    grows without bound."""
    st_run, std_run = _run("st", 0.2, 30.0), _run("std", 0.2, 30.0)
    late = lambda r: float(np.max(np.abs(np.asarray(r.trajectory.d)[-500:])))
    assert late(st_run) < 0.5
    assert late(std_run) > 1.0 or int(std_run.status) != 0


def test_std_is_refused_for_the_robot_and_for_a_too_long_step():
    with pytest.raises(InputError, match="params"):
        make_dynamic_scenario(shapes.line(), (0.0, 0.0, 0.0), None, params="robot", model="std")
    from pfjax.montecarlo.config import load_study

    base = {
        "name": "s",
        "n_runs": 2,
        "seed": 1,
        "paths": [{"kind": "line"}],
        "controllers": [{"name": "s", "type": "stanley"}],
    }
    veh = {"model": "std", "params": "vehicle2", "speed": 10.0}
    with pytest.raises(InputError, match="params"):
        load_study(data={**base, "vehicle": {**veh, "params": "robot"}, "margin": {"enabled": False}})
    with pytest.raises(InputError, match="sim.dt"):
        load_study(data={**base, "vehicle": veh, "margin": {"enabled": False}, "sim": {"dt": 0.005}})
    spec, _ = load_study(data={**base, "vehicle": veh, "margin": {"enabled": False}, "sim": {"dt": 0.002}})
    assert spec.vehicle.model == "std"


def test_std_without_a_parameter_set_takes_vehicle2_everywhere():
    """``params`` not given: the study config, :func:`pfjax.scenarios` and the command line (one table,
    ``DEFAULT_PARAMETER_SET``) take vehicle2 for the drift model and the robot for the ST model; the
    kinematic model's dumped config keeps the robot (its default), so its hash does not move."""
    import pfjax
    from pfjax.montecarlo.config import load_study, study_hash
    from pfjax.montecarlo.scenario_config import DEFAULT_PARAMETER_SET

    assert DEFAULT_PARAMETER_SET == {"st": "robot", "std": "vehicle2"}
    base = {"name": "s", "n_runs": 2, "seed": 1, "paths": [{"kind": "line"}], "margin": {"enabled": False}}
    base["controllers"] = [{"name": "s", "type": "stanley"}]
    for model, dt, want in (("std", 0.0002, "vehicle2"), ("st", 0.002, "robot"), ("kinematic", 0.005, "robot")):
        spec, _ = load_study(data={**base, "vehicle": {"model": model}, "sim": {"dt": dt}})
        assert spec.vehicle.params == want
        given, _ = load_study(data={**base, "vehicle": {"model": model, "params": want}, "sim": {"dt": dt}})
        assert study_hash(given) == study_hash(spec)
    assert pfjax.scenarios("line", 2, model="std").spec.vehicle.params == "vehicle2"
    assert pfjax.scenarios("line", 2, model="std", vehicle_params="vehicle1").spec.vehicle.params == "vehicle1"
    with pytest.raises(InputError, match="vehicle_params"):
        pfjax.scenarios("line", 2, model="std", vehicle_params="robot")
