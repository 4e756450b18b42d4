"""The slip vehicle's static settings (:class:`SimConfig`): step, horizon, controller sampling, projection
iterations, recording and the metrics' bands; hashable, so they are a jitted program's static argument."""

from __future__ import annotations

from dataclasses import dataclass

from pfjax import errors, resources
from pfjax.errors import InputError


@dataclass(frozen=True)
class SimConfig:
    """Static settings (they fix array shapes; hashable so they can be jit-static).

    Attributes:
        dt: integrator step, s (default 5 ms). The single-track models' step is checked against
            their tyre modes (:func:`pfjax.models.single_track.check_step`); the kinematic model's
            stiffness is the controller's, and is not checked: a heading gain ``k_theta`` (rad/rad)
            needs ``control_every dt v |k_theta| / L < 2`` with the command held over its period
            (an Euler step of the heading error), about 2.8 for a continuous controller (RK4), and
            a step beyond it shows as steering that chatters between its limits
            (``sat_fraction`` near 1), not as a failed status.
        horizon: simulated time, s (docs/reproductions/path-following.md §6: *assumed* 20 s), a whole
            number of steps ``dt`` (to a relative 1e-9, :func:`pfjax.resources.whole_steps`).
        control_every: controller sampling period in integrator steps (zero-order hold);
            ``None`` evaluates the controller continuously inside every RK4 stage.
        newton_iters: Newton steps of the warm-started projection per measurement.
        record: ``True`` returns full trajectories (memory O(horizon) per run);
            ``False`` only the running metrics (memory independent of the horizon).
        d_fail: |d| above which a run is flagged ``DIVERGED``, m.
        settle_band: band on |d| for the settling time, m.
        steady_window: final part of the run for the steady-state errors, s (the whole run when
            longer than ``horizon``; a study's ``[sim]`` refuses that).
        success_band: a run succeeds if it does not fail and |d| <= this from ``success_from`` on, m.
        success_from: start of the success window, s, at most ``horizon`` (``None``: the steady
            window's start).
    """

    dt: float = 0.005
    horizon: float = 20.0
    control_every: int | None = 1
    newton_iters: int = 3
    record: bool = True
    d_fail: float = 10.0
    settle_band: float = 0.05
    steady_window: float = 5.0
    success_band: float = 0.05
    success_from: float | None = None

    def __post_init__(self):
        """Checks every setting (:class:`~pfjax.errors.InputError` naming it)."""
        errors.number("dt", self.dt, positive=True, unit=" s")
        errors.number("horizon", self.horizon, positive=True, unit=" s")
        # a step that does not fit the horizon names the step when only the step was changed
        named = resources.check_fits(self.horizon, self.dt, (_DEFAULT_HORIZON, _DEFAULT_DT))
        resources.check_steps(self.horizon, self.dt)
        resources.whole_steps(self.horizon, self.dt, named)  # never rounded to whole steps
        if self.control_every is not None:
            errors.integer("control_every", self.control_every, low=1, high=resources.MAX_STEPS)
            if self.control_every > self.n_steps:  # one command for the whole run: a mistake, not a controller
                raise InputError(
                    f"control_every: the controller's sampling period ({self.control_every} steps of {self.dt:g} s) "
                    f"is longer than the horizon ({self.n_steps} steps)",
                    "control_every",
                )
        errors.integer("newton_iters", self.newton_iters, low=1, high=100)
        for name in ("d_fail", "settle_band", "steady_window", "success_band"):
            errors.number(name, getattr(self, name), positive=True)
        if self.success_from is not None:
            errors.number("success_from", self.success_from, nonnegative=True, unit=" s")
            if self.success_from > self.horizon:  # an empty success window would pass every run
                raise InputError(
                    f"success_from: must be <= horizon ({self.horizon:g} s), got {errors.shown(self.success_from)}",
                    "success_from",
                )

    @property
    def n_steps(self) -> int:
        """``horizon / dt``, a whole number (checked on construction)."""
        return int(round(self.horizon / self.dt))

    @property
    def success_start(self) -> float:
        return self.n_steps * self.dt - self.steady_window if self.success_from is None else self.success_from


def changed(base: SimConfig, changes: dict, key: str = "config") -> SimConfig:
    """``base`` with the fields in ``changes`` replaced (and checked as :class:`SimConfig` checks
    them); :class:`~pfjax.errors.InputError` naming ``<key>.<field>`` for an unknown or bad field,
    as a caller who passed ``changes`` as its argument ``key`` wrote it."""
    import dataclasses

    names = [f.name for f in dataclasses.fields(SimConfig)]
    unknown = [k for k in changes if k not in names]
    if unknown:
        raise InputError(f"{key}.{unknown[0]}: unknown setting; expected one of {', '.join(names)}", key)
    try:
        return dataclasses.replace(base, **changes)
    except InputError as e:
        raise (errors.renamed(e, e.key, f"{key}.{e.key}") if e.key in names else e) from None


_DEFAULT_DT = SimConfig.dt
_DEFAULT_HORIZON = SimConfig.horizon
