"""pfjax's public Python API: design, sample, simulate, summarise (re-exported by :mod:`pfjax`).

A user's script needs nothing else::

    import pfjax

    design = pfjax.design_mixed(v=1.0, L=0.2)                       # LMI state feedback
    runs = pfjax.scenarios("sine", n=1000, beta_r_deg=pfjax.uniform(-8, 8),
                           beta_f_deg=pfjax.uniform(-8, 8), key=0)   # 1,000 slipping runs
    sim = pfjax.simulate(runs, "state_feedback", gains=design)
    print(pfjax.success_rate(sim))

Every argument is checked as the command line checks it: a bad value raises
:class:`pfjax.InputError` (a ``ValueError``) whose message starts with the argument's name, and so
does a keyword a function does not take (:class:`pfjax.errors.ArgumentError`, also a
``TypeError``), with the closest name it takes.
Angles are in degrees where the name ends in ``_deg``, everything else in SI units.

The functions live in small modules by task (:mod:`pfjax.api.distributions`, :mod:`~pfjax.api.design`,
:mod:`~pfjax.api.runs`, :mod:`~pfjax.api.simulation`, :mod:`~pfjax.api.studies`,
:mod:`~pfjax.api.tuning`); this package re-exports them, and :mod:`pfjax` re-exports this package.
"""

from pfjax.api.design import design_mixed
from pfjax.api.distributions import choice, normal, truncnormal, uniform
from pfjax.api.runs import Scenarios, scenarios
from pfjax.api.simulation import Simulation, SuccessRate, replay, simulate, success_rate
from pfjax.api.studies import StudyResult, load_study, rare_event, run_study
from pfjax.api.tuning import falsify, tune

__all__ = [
    "Scenarios",
    "Simulation",
    "StudyResult",
    "SuccessRate",
    "choice",
    "design_mixed",
    "falsify",
    "load_study",
    "normal",
    "rare_event",
    "replay",
    "run_study",
    "scenarios",
    "simulate",
    "success_rate",
    "truncnormal",
    "tune",
    "uniform",
]
