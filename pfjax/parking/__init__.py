"""Parking by switching travel direction and gain (docs/reproductions/parking.md).

The entry points (:mod:`pfjax.parking.api`, cheap to import): :func:`run`, one run with its log of
direction switches (``pfjax parking``), and :func:`search`, the GA or grid search of the garage's
switching parameters (``pfjax parking-search``). The modules: :mod:`~pfjax.parking.model`,
:mod:`~pfjax.parking.geometry`, :mod:`~pfjax.parking.maps`, :mod:`~pfjax.parking.schedules`,
:mod:`~pfjax.parking.simulate`, :mod:`~pfjax.parking.switch_search`, :mod:`~pfjax.parking.summary`, ...
"""

from pfjax.parking.api import run, search

__all__ = ["run", "search"]
