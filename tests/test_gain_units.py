"""The gains' units: one per scalar gain in the controller registry (``register(units=...)``), what
every output records beside the gains, and what the car arms' Froude scaling reads.

The units are checked by dimensional analysis run on the simulator: a kinematic run scaled by
``S`` (lengths x S, times and speeds x sqrt(S)) with every gain scaled by ``S^e``, ``e`` from its
unit (:func:`pfjax.dynamic_study.arms.froude_exponent`), must follow the robot's run scaled (the
lateral error x S at every step, the same steering). A wrong unit breaks that.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

import pfjax
from pfjax import controllers as C
from pfjax.cli import main
from pfjax.dynamic_study.arms import froude_exponent, scaled_gains
from pfjax.errors import InputError
from pfjax.sim import SimConfig

BUILT_IN = [n for n, e in C.REGISTRY.items() if e.module.startswith("pfjax.")]


def test_every_gain_of_pfjax_controllers_has_a_unit():
    for name in BUILT_IN:
        units = C.gain_units(C.entry(name))
        assert list(units) == list(C.flat_gains(C.entry(name))), name  # every scalar gain, in order
        assert C.UNSTATED not in units.values(), (name, units)
        assert all(froude_exponent(u) is not None for u in units.values()), (name, units)
    # the same name, other units: why units are kept per controller
    assert C.gain_units(C.entry("state_feedback"))["k_d"] == "rad/m"
    assert C.gain_units(C.entry("rear_wheel"))["k_d"] == "1/m^2"


@pytest.mark.parametrize(
    "unit, exponent",
    [("rad/m", -1.0), ("rad/(m s)", -1.5), ("rad/rad", 0.0), ("1/s", -0.5), ("m/s", 0.5), ("s", 0.5), ("m", 1.0)]
    + [("1/m", -1.0), ("1/m^2", -2.0), ("1", 0.0), ("m^2 s", 2.5)],
)
def test_froude_exponent_of_a_unit(unit, exponent):
    assert froude_exponent(unit) == exponent


@pytest.mark.parametrize("unit", [C.UNSTATED, "kg/s", "m^x", "rad/(m N)", "m^nan", "m^inf", "1/s^"])
def test_froude_exponent_of_a_unit_in_other_terms_is_none(unit):
    assert froude_exponent(unit) is None


S = 4.0  # a power of two: the scaled run is the robot's numbers times powers of two
#: one gain per controller whose exponent is off by 1/2 in the check that the test can fail
WRONG = {"integral": "k_i", "state_feedback": "k_d", "pi": "ki_theta"}
WRONG |= {"stanley": "k_soft", "pure_pursuit": "ld_gain", "rear_wheel": "k_d"}


def _scaled_run(name: str, s: float, wrong: str | None = None):
    """A line run at scale ``s`` (Froude: lengths x s, speed, step and horizon x sqrt(s)) with the
    controller's default gains scaled by their units (``wrong``: that gain's exponent + 1/2)."""
    e = C.entry(name)
    units = C.gain_units(e)
    gains = {k: v * s ** (froude_exponent(units[k]) + 0.5 * (k == wrong)) for k, v in C.flat_gains(e).items()}
    r = math.sqrt(s)
    sc = pfjax.scenarios(
        "line", 1, beta_r_deg=3.0, beta_f_deg=-2.0, lateral_offset=0.1 * s, heading_error_deg=8.0,
        speed=1.0 * r, L=0.2 * s, horizon=6.0 * r,
    )  # fmt: skip
    out = pfjax.simulate(sc, name, gains, SimConfig(dt=0.005 * r, horizon=6.0 * r, d_fail=10.0 * s), trajectories=True)
    assert out.table.status[0] == "ok"
    return np.asarray(out.result.trajectory.d)[0], np.asarray(out.result.trajectory.delta)[0]


@pytest.mark.parametrize("name", sorted(WRONG))
def test_the_units_make_every_controller_froude_similar(name):
    """The car-scale run with the gains scaled by their units is the robot's run scaled: the lateral
    error x S and the same steering at every step, to float32 rounding (1e-5 of the largest |d|;
    with S = 4 it is exact in exact arithmetic). One gain scaled by a wrong exponent departs from
    it by more than 1e-3 of the largest |d| (the test can fail)."""
    assert set(WRONG) == set(BUILT_IN) - {"linear"}
    d, delta = _scaled_run(name, 1.0)
    d_car, delta_car = _scaled_run(name, S)
    scale = np.max(np.abs(d))
    assert np.max(np.abs(d_car / S - d)) <= 1e-5 * scale
    assert np.max(np.abs(delta_car - delta)) <= 1e-5
    d_wrong, _ = _scaled_run(name, S, WRONG[name])
    assert np.max(np.abs(d_wrong / S - d)) > 1e-3 * scale


def test_scaled_gains_of_a_study_controller():
    pi = scaled_gains({"name": "p", "type": "pi", "gains": {"kp_d": 2.0}}, 4.0, "study.controllers[0]")
    assert pi["gains"]["kp_d"] == 0.5 and pi["gains"]["ki_d"] == C.PAPER_PI["ki_d"] / 8.0
    assert pi["gains"]["kp_theta"] == C.PAPER_PI["kp_theta"]  # rad/rad: unchanged
    sf = scaled_gains({"name": "k", "type": "state_feedback", "K": [-2.0, -1.0]}, 4.0, "k")
    assert "K" not in sf and sf["gains"] == {"k_d": -0.5, "k_theta": -1.0, "feedforward": 0.0}
    design = {"name": "m", "type": "lmi"}
    assert scaled_gains(design, 4.0, "k") is design  # made at the car's speed and wheelbase
    over = scaled_gains({"name": "m", "type": "lmi", "gains": {"k_d": -3.0}}, 4.0, "k")
    assert over["gains"] == {"k_d": -0.75}  # a gain given over a design: in the robot's units, scaled
    fixed = scaled_gains({"name": "p", "type": "paper_k"}, 4.0, "k")  # the source's fixed gain: scaled
    assert fixed["type"] == "paper_k" and fixed["gains"]["k_d"] == C.PAPER_K[0] / 4.0
    assert fixed["gains"]["k_theta"] == C.PAPER_K[1]


def test_register_checks_units_and_records_a_missing_one_as_unstated():
    e = C.entry("stanley")
    try:
        refused = (
            ({"kk": "1/s"}, r"^units\.kk: unknown gain"),
            ({"k": ""}, r"^units\.k: expected a unit"),
            ({"k": "furlong/fortnight"}, r"^units\.k: expected a product of m, s, rad and 1 with powers"),
            ({"k": "deg/s"}, r"^units\.k: expected a product of m, s, rad and 1"),
        )
        for units, say in refused:
            with pytest.raises(InputError, match=say):
                C.register(e.controller, e.make_params.factory, name="plug_units", units=units)
        plug = C.register(e.controller, e.make_params.factory, name="plug_units", units={"k": "1/s"})
        assert C.gain_units(plug) == {"k": "1/s", "k_soft": C.UNSTATED}
        with pytest.raises(InputError, match=r"^study\.controllers\[2\]\.type: the car arms scale plug_units's gains"):
            scaled_gains({"name": "x", "type": "plug_units"}, 4.0, "study.controllers[2]")
    finally:
        C.REGISTRY.pop("plug_units", None)


def test_simulate_json_gives_each_gain_its_controllers_unit(capsys):
    base = ["simulate", "--path", "line", "--horizon", "1", "--json"]
    for controller, gains in (("rear-wheel", {"k_theta": "1/m", "k_d": "1/m^2"}), ("paper-k", {"k_d": "rad/m"})):
        assert main([*base, "--controller", controller]) == 0
        units = json.loads(capsys.readouterr().out)["units"]
        for k, u in gains.items():
            assert units[f"gains.{k}"] == u and units[f"arguments.gains.{k}"] == u


def test_tuning_study_units_name_each_controllers_gains():
    from pfjax.tuning.study import summary_units
    from pfjax.tuning.study_config import TuningStudy

    cfg = TuningStudy().model_dump(mode="json")
    units = summary_units(cfg)
    assert units["gains"]["rear_wheel"]["k_d"] == "1/m^2" and units["gains"]["pi"]["kp_d"] == "rad/m"
    assert units["descent_gains"] == {"pi": C.gain_units(C.entry("pi"))}


@pytest.mark.parametrize(
    "unit", ["/", "m/", "1/", "(m", "()", "m)/s)", "m^1_000", "m^1e308", "a/b/c", "m^", "deg/s", "m^\u0663"]
)
def test_a_malformed_unit_is_not_read(unit):
    """The unit grammar reads only a product of m, s, rad and 1 with plain powers, over one such
    product, each side non-empty and parenthesised as a whole at most: anything else is None, and
    register refuses it."""
    from pfjax.tables import unit_powers

    assert unit_powers(unit) is None
    e = C.entry("pi")
    try:
        with pytest.raises(InputError, match=r"^units\.kp_d: expected a product of m, s, rad and 1"):
            C.register(e.controller, e.make_params.factory, name="plug_bad_unit", units={"kp_d": unit})
    finally:
        C.REGISTRY.pop("plug_bad_unit", None)
