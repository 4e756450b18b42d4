"""The parking simulator's loop bound, shared by the entry points' checks
(:mod:`pfjax.parking.api`, :mod:`pfjax.parking.study_config`) and the simulator's default
(:class:`pfjax.parking.runs.ParkingConfig`). Imports nothing, so the entry points stay cheap."""

#: Most scanner periods one run may take (``t_max / scan_period``); the simulator's loop allows one
#: more (:func:`pfjax.parking.runs.periods_needed`), so no accepted run ends before ``t_max``.
MAX_PERIODS = 20000
