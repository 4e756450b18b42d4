"""The kinematic-vs-dynamic study's config, arms and summary: the dynamic arms' actuator and speed
loop settable, arm names unique, the path curvature from the registry, the verdicts' "survives" and
the paired interval (Tango's score interval) against an independent computation."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from pfjax import paths
from pfjax.config import ConfigError
from pfjax.dynamic_study.arms import ROBOT_WHEELBASE, arms, car_study, check
from pfjax.dynamic_study.config import load
from pfjax.dynamic_study.report import slip_tables
from pfjax.dynamic_study.summary import compare, path_curvatures, slip_summary, survives
from pfjax.jsonio import dumps
from pfjax.metrics.robustness import paired_interval
from pfjax.models import single_track as st
from pfjax.montecarlo.config import VehicleSpec
from pfjax.report.document import Document, to_markdown


def test_the_dynamic_arms_actuator_and_speed_loop_are_settable_and_reach_every_dynamic_arm():
    """study.vehicle.tau_delta_s and k_v set the dynamic arms' (robot and, Froude-scaled, car) and
    the designs' operating point; the kinematic arms do not take them."""
    config = load(quick=True, overrides=["study.vehicle.tau_delta_s=0.2", "study.vehicle.k_v=3.0"])
    check(config)  # every arm's study config valid
    a = arms(config)
    for name in ("dynamic", config.grip_arm):
        assert (a[name]["vehicle"]["tau_delta_s"], a[name]["vehicle"]["k_v"]) == (0.2, 3.0), name
    for name in ("kinematic_10deg", "kinematic_0deg", "car_kinematic_10deg"):
        assert not {"tau_delta_s", "k_v"} & set(a[name]["vehicle"]), name
    p = st.parameter_set(config.car.params)
    rs = math.sqrt((p.l_f + p.l_r) / ROBOT_WHEELBASE)
    car = a["car_dynamic"]["vehicle"]
    assert car["tau_delta_s"] == pytest.approx(0.2 * rs, rel=1e-15) and car["k_v"] == pytest.approx(3.0 / rs, rel=1e-15)
    assert config.dynamic_vehicle().tau_delta_s == 0.2  # what the designs' operating point reads


def test_the_car_takes_the_schemas_actuator_and_speed_loop_when_not_given():
    fields = VehicleSpec.model_fields
    spec = car_study(load(quick=True))
    p = st.parameter_set("vehicle2")
    rs = math.sqrt((p.l_f + p.l_r) / ROBOT_WHEELBASE)
    assert spec["vehicle"]["tau_delta_s"] == pytest.approx(fields["tau_delta_s"].default * rs, rel=1e-15)
    assert spec["vehicle"]["k_v"] == pytest.approx(fields["k_v"].default / rs, rel=1e-15)


@pytest.mark.slow
def test_the_designs_operating_point_takes_the_dynamic_arms_actuator():
    from pfjax.dynamic_study.designs import designs

    _, record = designs(load(quick=True, overrides=["study.vehicle.tau_delta_s=0.08"]))
    assert record["operating_point"]["tau_delta_s"] == 0.08


@pytest.mark.parametrize(
    "setting, message",
    [
        # the kinematic model's keys: study.vehicle is the dynamic arms' vehicle
        (
            "study.vehicle.L=0.3",
            r'^study\.vehicle\.L: not with model = "st" .*\(study\.vehicle is the dynamic arms\' vehicle\)$',
        ),
        ("study.vehicle.convention='lenain'", r"^study\.vehicle\.convention: .*dynamic arms' vehicle\)$"),
        ("study.vehicle.tau_delta_s=0", r"^study\.vehicle\.tau_delta_s: must be "),
        ("study.vehicle.k_v=-1", r"^study\.vehicle\.k_v: must be "),
        ("study.vehicle.k_vv=1", r"^study\.vehicle\.k_vv: unknown key \(did you mean 'study\.vehicle\.k_v'\?\)$"),
    ],
)
def test_the_study_vehicle_is_validated_as_the_dynamic_arms_one_line_naming_the_key(setting, message):
    with pytest.raises(ConfigError, match=message) as e:
        load(quick=True, overrides=[setting])
    assert len(str(e.value).splitlines()) == 1


def test_an_actuator_too_fast_for_the_step_is_refused_naming_the_arm():
    config = load(quick=True, overrides=["study.vehicle.tau_delta_s=0.0001"])
    with pytest.raises(ConfigError, match=r"^study\.sim\.dt: .* needs dt <= .*\(arm dynamic\)$"):
        check(config)


@pytest.mark.parametrize(
    "ranges, named",
    [("[1.0, 1.0000001, 10, 10]", "kinematic_10deg, kinematic_1deg"), ("[5, 5.0]", "kinematic_5deg")],
)
def test_slip_ranges_that_name_the_same_arm_are_refused(ranges, named):
    with pytest.raises(ConfigError, match=r"^slip_ranges_deg: ") as e:
        load(overrides=[f"slip_ranges_deg={ranges}"])
    assert named in str(e.value) and len(str(e.value).splitlines()) == 1
    config = load(quick=True, overrides=["slip_ranges_deg=[1.0, 1.00001, 10]"])  # distinct to 6 digits
    assert [k for k in arms(config) if k.startswith("kinematic_")] == [
        "kinematic_1deg", "kinematic_1.00001deg", "kinematic_10deg",
    ]  # fmt: skip


def test_the_slip_by_path_tables_take_the_curvature_from_the_path_registry():
    config = load(
        quick=True,
        overrides=["study.paths=[{kind='line'}, {kind='sine'}, {kind='circle', radius=2.5, name='ring'}]"],
    )
    curv = path_curvatures(config)
    assert curv == {"line": paths.PATHS["line"].max_curvature, "sine": paths.PATHS["sine"].max_curvature, "ring": 0.4}
    rows = [
        {"path": p, "status": "ok", "mu": 0.5, "speed": 1.0, **dict.fromkeys(("max_abs_beta_r_deg", "max_abs_beta_f_deg",
         "mean_abs_beta_r_deg", "mean_abs_beta_f_deg"), 1.0)}
        for p in ("line", "sine", "ring")
    ]  # fmt: skip
    s = slip_summary(pd.DataFrame(rows), 10.0, curv)
    assert {b["path"]: b["max_curvature_robot"] for b in s["by_path"]} == curv
    import json

    text = to_markdown(Document("t", "", slip_tables(json.loads(dumps(s)))))
    assert "| ring (0.400) |" in text and "| line (0.000) |" in text and "None" not in text


def _runs(arms_: dict[str, np.ndarray]) -> pd.DataFrame:
    """A hand-made runs table: one controller on one path, each arm's success indicators."""
    frames = []
    for arm, ok in arms_.items():
        n = len(ok)
        frames.append(
            pd.DataFrame(
                {
                    "arm": arm, "path": "line", "controller": "c", "run": np.arange(n), "success": ok,
                    "status": "ok", "mu": np.linspace(0.3, 1.0, n), "late_max_abs_d": 0.01,
                }
            )
        )  # fmt: skip
    return pd.concat(frames, ignore_index=True)


def test_undecided_verdicts_are_reported_as_undecided_not_as_surviving():
    assert survives("undecided", "undecided") == "undecided"
    assert survives("robust", "undecided") == survives("undecided", "fragile") == "undecided"
    assert survives("robust", "robust") == survives("fragile", "fragile") == "yes"
    assert survives("robust", "fragile") == "no"
    # 19 of 20 succeed in both: the interval [75.1, 99.9] % straddles the 95 % line
    ok = np.r_[np.ones(19, bool), False]
    c = compare(_runs({"dyn": ok, "kin_a": ok}), "dyn", "kin_a", "kin_")["controllers"]["c"]
    assert (c["verdict_kinematic"], c["verdict_dynamic"], c["verdict_survives"]) == ("undecided",) * 3


def test_identical_outcomes_give_a_paired_interval_with_a_width():
    ok = np.r_[np.ones(15, bool), np.zeros(5, bool)]
    p = compare(_runs({"dyn": ok, "kin_a": ok}), "dyn", "kin_a", "kin_")["controllers"]["c"][
        "paired_dynamic_minus_kinematic"
    ]
    z2 = 1.959963984540054**2
    assert p["diff"] == 0.0 and (p["only_dynamic"], p["only_kinematic"]) == (0, 0)
    assert p["ci95"] == pytest.approx([-z2 / (20 + z2), z2 / (20 + z2)], rel=1e-9)


def _tango_reference(b: int, c: int, n: int) -> tuple[float, float]:
    """Tango's interval computed independently: the restricted maximum likelihood of the discordant
    cells maximised numerically (scipy.optimize.minimize_scalar) and the score equation solved by
    scipy.optimize.brentq."""
    from scipy import optimize, stats

    z = stats.norm.ppf(0.975)

    def score(delta: float) -> float:
        # cells p12 = x + delta, p21 = x, concordant 1 - 2 x - delta; x in [max(0, -delta), (1 - delta) / 2]
        lo, hi = max(0.0, -delta), (1.0 - delta) / 2
        nll = lambda x: (
            -(
                (b * math.log(x + delta) if b else 0.0)
                + (c * math.log(x) if c else 0.0)
                + ((n - b - c) * math.log(1 - 2 * x - delta) if n - b - c else 0.0)
            )
        )
        eps = 1e-15
        x = optimize.minimize_scalar(nll, bounds=(lo + eps, hi - eps), method="bounded", options={"xatol": 1e-14}).x
        return (b - c - n * delta) / math.sqrt(n * (2 * x + delta * (1 - delta)))

    d = (b - c) / n
    lower = -1.0 if score(-1 + 1e-9) <= z else optimize.brentq(lambda t: score(t) - z, -1 + 1e-9, d - 1e-12)
    upper = 1.0 if score(1 - 1e-9) >= -z else optimize.brentq(lambda t: score(t) + z, d + 1e-12, 1 - 1e-9)
    return lower, upper


@pytest.mark.parametrize(
    "b, c, n", [(0, 0, 10), (0, 0, 200), (5, 2, 40), (3, 3, 12), (7, 0, 25), (0, 4, 9), (12, 30, 100), (1, 0, 1)]
)
def test_the_paired_interval_is_tangos_score_interval(b, c, n):
    got = paired_interval(b, c, n)
    want = _tango_reference(b, c, n)
    assert got == pytest.approx(want, abs=2e-6)
    assert got[0] < (b - c) / n < got[1] or (b - c) / n in (-1.0, 1.0)


def test_tangos_interval_matches_the_closed_forms_of_its_edge_cases():
    z2 = 1.959963984540054**2
    for n in (1, 10, 1200):
        assert paired_interval(0, 0, n) == pytest.approx((-z2 / (n + z2), z2 / (n + z2)), rel=1e-9)
        # every pair discordant one way: the lower end solves (1 - D) / (1 + D) = z^2 / n
        assert paired_interval(n, 0, n) == pytest.approx(((n - z2) / (n + z2), 1.0), rel=1e-9)
    assert all(math.isnan(x) for x in paired_interval(0, 0, 0))
