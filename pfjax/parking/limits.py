"""The parking simulator's loop bound, shared by the entry points' checks
(:mod:`pfjax.parking.api`, :mod:`pfjax.parking.study_config`) and the simulator's default
(:class:`pfjax.parking.runs.ParkingConfig`), and the one check of it. Imports only
:mod:`pfjax.errors`, so the entry points stay cheap."""

from pfjax.errors import InputError, shown

#: Most scanner periods one run may take (``t_max / scan_period``); the simulator's loop allows one
#: more (:func:`pfjax.parking.runs.periods_needed`), so no accepted run ends before ``t_max``.
MAX_PERIODS = 20000
#: Longest scanner period, s.
MAX_SCAN_PERIOD = 10.0


def check_periods(key: str, t_max: float, scan_period: float, t_max_key: str = "t_max") -> None:
    """:class:`~pfjax.errors.InputError` naming the period (``key``, or ``scan_period`` where ``key``
    is ``t_max``) when one scanner period is longer than the run (``t_max_key``: the timeout's own
    key, in the message), and naming ``key`` when a run of ``t_max`` s at ``scan_period`` s would
    take more than :data:`MAX_PERIODS` scanner periods (the message shows both values: either may
    be the one to change)."""
    if scan_period > t_max:  # one period longer than the run: its RK4 steps would run past t_max
        period = "scan_period" if key == "t_max" else key  # the period's own key
        raise InputError(
            f"{period}: must be <= {t_max_key} (one scanner period within the run), got {shown(scan_period)} s > "
            f"{shown(t_max)} s",
            period,
        )
    if t_max / scan_period > MAX_PERIODS:
        raise InputError(
            f"{key}: {t_max_key} / scan period may be at most {MAX_PERIODS}, got {shown(t_max)} / {shown(scan_period)} = "
            f"{shown(t_max / scan_period)}",
            key,
        )
