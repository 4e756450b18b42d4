"""Single scenarios: the source's tests from their start poses (docs/reproductions/path-following.md §6) and checked
builders (:func:`make_scenario` for the kinematic slip vehicle, :func:`make_dynamic_scenario` for the ST model).

| test     | path        | initial (x, y) | initial theta |
|----------|-------------|----------------|---------------|
| line     | y = x       | (1, 0)         | pi/2          |
| parabola | y = x^2     | (-2, 3)        | -pi/2         |
| sine     | y = sin x   | (0, -0.2)      | pi/4          |

Slip ``beta_r = beta_f = 5 deg`` in all tests (source). *Assumed*: steering limit 30 deg,
horizon 20 s, direction of travel increasing ``x``. The circle (radius 2 m, centre (0, 2),
start (0, -0.3), heading 0) is pfjax's own extra scenario, not the source's.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp

from pfjax import errors, paths
from pfjax.errors import InputError
from pfjax.models import DYNAMIC_MODELS, PARAMETER_SETS, check_setting
from pfjax.models import single_track as st
from pfjax.models.slip import CONVENTIONS, Pose, SlipParams
from pfjax.sim.dynamic import DynamicScenario
from pfjax.sim.simulate import Scenario
from pfjax.sim.slip_profiles import SlipProfile, constant_slip

PAPER_SLIP_DEG = 5.0
#: The source's three tests (:func:`pfjax.paths.source_tests`).
PAPER_TESTS = paths.source_tests()


def check_gains(gains, key: str = "gains") -> None:
    """:class:`~pfjax.errors.InputError` naming ``key.<field>`` unless every gain is a finite number
    within pfjax's magnitude bound (a controller's parameter NamedTuple, or any pytree of numbers)."""
    fields = gains._asdict().items() if hasattr(gains, "_asdict") else [("", gains)]
    for name, value in fields:
        for leaf in jax.tree_util.tree_leaves(value):
            errors.numbers(f"{key}.{name}" if name else key, leaf)


def make_scenario(
    path, pose0, gains, *, slip: SlipProfile | None = None, v=1.0, L=0.2, delta_max_deg=30.0, convention="source"
) -> Scenario:
    """One scenario from plain values, checked (:class:`~pfjax.errors.InputError` naming the
    argument: ``v`` and ``L`` > 0, ``0 < delta_max_deg < 90``, ``pose0`` three finite numbers, slip
    angles below 90 deg, gains finite).

    Args:
        path: a path shape (:mod:`pfjax.paths.shapes`).
        pose0: start pose ``(x, y, theta)``, m, m, rad.
        gains: the controller's parameter pytree.
        slip: slip profile (rad); default none.
        v: speed, m/s. L: wheelbase, m. delta_max_deg: steering limit, deg.
        convention: front-slip sign convention, ``"source"`` or ``"lenain"``.
    """
    if convention not in CONVENTIONS:
        raise InputError(f"convention: expected one of {sorted(CONVENTIONS)}, got {convention!r}")
    check_setting("v", "speed", v)  # the study config's rules of its [vehicle] keys, one home
    check_setting("L", "L", L)
    check_setting("delta_max_deg", "delta_max_deg", delta_max_deg)
    if not errors.is_traced(pose0) and (not hasattr(pose0, "__len__") or len(pose0) != 3):
        raise InputError(f"pose0: expected (x, y, theta), got {pose0!r}")
    for name, value in zip(("pose0[0]", "pose0[1]", "pose0[2]"), pose0):
        errors.numbers(name, value)
    if slip is not None:
        errors.numbers("slip.constant", slip.constant, below=math.pi / 2, unit=" rad")
    check_gains(gains)
    f = lambda a: jnp.asarray(a, dtype=float)
    return Scenario(
        pose0=Pose(*(f(a) for a in pose0)),
        slip=constant_slip(0.0, 0.0) if slip is None else slip,
        params=SlipParams(
            v=f(v),
            L=f(L),
            delta_max=f(math.radians(delta_max_deg)),
            convention=jnp.asarray(CONVENTIONS[convention], jnp.int32),
        ),
        path=path,
        gains=gains,
    )


def paper_scenario(
    test: str, gains, *, beta_r_deg=PAPER_SLIP_DEG, beta_f_deg=PAPER_SLIP_DEG, pose0=None, **kwargs
) -> Scenario:
    """The registered fixed path ``test`` (:data:`pfjax.paths.PATHS`: the source's "line",
    "parabola", "sine", pfjax's "circle", any registered path) from its start pose (or ``pose0``)
    with constant slip ``beta_r_deg``, ``beta_f_deg`` (deg, magnitude below 90); ``kwargs`` as
    :func:`make_scenario`."""
    e = paths.fixed_entry(test)
    errors.numbers("beta_r_deg", beta_r_deg, below=90, unit=" deg")
    errors.numbers("beta_f_deg", beta_f_deg, below=90, unit=" deg")
    assert e.build is not None  # a fixed path (fixed_entry)
    slip = constant_slip(math.radians(beta_r_deg), math.radians(beta_f_deg))
    return make_scenario(e.build(), e.start_pose if pose0 is None else pose0, gains, slip=slip, **kwargs)


def make_dynamic_scenario(
    path, pose0, gains, *, params="robot", mu=None, v=1.0, tau_delta=0.05, k_v=5.0, model="st"
) -> DynamicScenario:
    """One run of the dynamic vehicle (:mod:`pfjax.sim.dynamic`) from plain values, checked
    (:class:`~pfjax.errors.InputError` naming the argument).

    Args:
        path: a path shape (:mod:`pfjax.paths.shapes`).
        pose0: rear-axle start pose ``(x, y, theta)``, m, m, rad.
        gains: the controller's parameter pytree.
        params: the ST parameter set's name (:data:`pfjax.models.PARAMETER_SETS`: ``robot``,
            ``vehicle1``-``vehicle3``) or an :class:`~pfjax.models.single_track.STParams` (or, for the
            drift model, :class:`~pfjax.models.single_track.STDParams`).
        mu: friction coefficient in ``(0, 10]`` (default: the set's).
        v: reference speed, m/s. tau_delta: steering actuator time constant, s. k_v: speed loop gain, 1/s.
        model: ``"st"`` or ``"std"`` (the drift model; a named set then is one of CommonRoad's vehicles).
    """
    if model not in DYNAMIC_MODELS:
        raise InputError(f"model: expected {' or '.join(DYNAMIC_MODELS)}, got {model!r}", "model")
    if isinstance(params, str):
        if params not in PARAMETER_SETS:
            raise InputError(f"params: expected one of {', '.join(PARAMETER_SETS)}, got {params!r}", "params")
        params = st.model_parameter_set(model, params)
    elif not isinstance(params, (st.STParams, st.STDParams)):
        raise InputError(
            f"params: expected a parameter set's name, an STParams or an STDParams, got {type(params).__name__}",
            "params",
        )
    if mu is not None:
        errors.numbers("mu", mu, positive=True, high=10)
        params = st.with_mu(params, mu)
    check_setting("v", "speed", v)
    check_setting("tau_delta", "tau_delta_s", tau_delta)
    check_setting("k_v", "k_v", k_v)
    if not errors.is_traced(pose0) and (not hasattr(pose0, "__len__") or len(pose0) != 3):
        raise InputError(f"pose0: expected (x, y, theta), got {pose0!r}")
    for name, value in zip(("pose0[0]", "pose0[1]", "pose0[2]"), pose0):
        errors.numbers(name, value)
    check_gains(gains)
    f = lambda a: jnp.asarray(a, dtype=float)
    return DynamicScenario(
        pose0=Pose(*(f(a) for a in pose0)),
        vehicle=jax.tree_util.tree_map(f, params),
        v_ref=f(v),
        path=path,
        gains=gains,
        tau_delta=f(tau_delta),
        k_v=f(k_v),
    )
