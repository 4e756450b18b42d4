"""Verdicts on the claims of the path-following source (Fakharian et al.; model documentation:
``docs/reproductions/path-following.md``): one row per claim, path and criterion, from the paper reproduction's runs.

The inputs are plain dicts and frames the study computes (``studies/paper_reproduction.py``):

* ``rows``: one dict per (path, controller) with the run's metrics (``status``, ``settling_time``
  s, ``steady_abs_d`` m and ``steady_abs_theta_e_rad`` rad over the final window, ``final_delta`` and
  ``final_theta_e`` rad, ``max_abs_delta_cmd`` the peak commanded steering before saturation and
  ``max_abs_delta`` the peak applied steering, rad, ``steer_energy`` ∫δ² dt of the applied
  steering in rad²·s, ``sat_fraction`` the fraction of the run with the command beyond the limit);
* ``stab``: the stability analysis (fractions over the slip grid, the source linearisation's
  eigenvalue maxima over the open square (−90°, 90°)², the paper case's equilibrium);
* ``pi_df``: the 24 readings of Table 3 with their filter columns (``c_*``) and ``filters``, the
  number of readings passing each filter and the sensitivity of the choice to the thresholds;
* ``sine``: where the sine test's error peaks; ``long_pi``: the PI's line test at a long horizon;
  ``ga``: the Table 2 crossover readings.
"""

from __future__ import annotations

from pfjax.paths import source_tests
from pfjax.reproduce.analysis_claims import hurwitz, table2, table3
from pfjax.reproduce.run_claims import (  # noqa: F401  (re-exported: the verdict table's inputs and labels)
    CONTROLLERS,
    LABEL,
    Add,
    Inputs,
    converge,
    effort,
    faster,
    line_mixed_error,
    line_pi_error,
    line_steering,
    line_yaw,
    more_accurate,
    sine_peaks,
    steering_limit,
    yaw_error,
)
from pfjax.reproduce.verdict import Verdict

#: every claim, in the order of the verdict table
CLAIMS = (
    converge,
    steering_limit,
    faster,
    more_accurate,
    yaw_error,
    effort,
    line_mixed_error,
    line_pi_error,
    line_steering,
    line_yaw,
    sine_peaks,
    hurwitz,
    table3,
    table2,
)


def verdicts(cfg: dict, rows: list[dict], stab: dict, pi_df, sine: dict, long_pi: dict, ga: dict) -> list[Verdict]:
    """Every verdict row of the reproduction (module docstring), claim by claim (:data:`CLAIMS`)."""
    inp = Inputs(
        R={(r["path"], r["controller"]): r for r in rows},
        paths=source_tests(),
        dmax_deg=cfg["model"]["delta_max_deg"],
        band=cfg["sim"]["settle_band"],
        window=cfg["sim"]["steady_window"],
        horizon=cfg["sim"]["horizon"],
        src=cfg["source"],
        stab=stab,
        pi_df=pi_df,
        sine=sine,
        long_pi=long_pi,
        ga=ga,
    )
    out: list[Verdict] = []

    def add(*a, **k) -> None:
        out.append(Verdict(*a, **k).check())

    for claim in CLAIMS:
        claim(inp, add)
    return out
