"""Parking by switching travel direction and gain (docs/reproductions/parking.md).

The entry points (:mod:`pfjax.parking.api`, cheap to import): :func:`run`, one run with its log of
direction switches (``pfjax parking``), :func:`search`, the GA or grid search of the garage's
switching parameters (``pfjax parking-search``), and :func:`run_study`, the whole study
(``python studies/parking.py``; config schema :class:`pfjax.parking.study_config.ParkingStudy`). The modules: :mod:`~pfjax.parking.model`,
:mod:`~pfjax.parking.geometry`, :mod:`~pfjax.parking.maps`, :mod:`~pfjax.parking.schedules`,
:mod:`~pfjax.parking.simulate`, :mod:`~pfjax.parking.switch_search`, :mod:`~pfjax.parking.summary`, ...
"""

from pathlib import Path

from pfjax.parking.api import run, search

__all__ = ["run", "run_study", "search"]


def run_study(config=None, out: str | Path | None = None, **options) -> tuple[Path, dict]:
    """The parking study into ``out``: :func:`pfjax.parking.study.run` (imported on first call, so
    ``import pfjax.parking`` stays cheap). Returns ``(folder, summary)``."""
    from pfjax.parking.study import run as run_whole_study

    return run_whole_study(config, out, **options)
