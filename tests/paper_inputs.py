"""Made-up runs of the paper reproduction's three controllers on the source's three paths, for the
verdict tests: every number plausible, none from a simulation."""

from __future__ import annotations

import math

#: One run's metrics as ``path_following.verdicts`` reads them.
RUN = dict(
    status="ok",
    settling_time=1.0,
    max_abs_delta_cmd=0.3,
    sat_fraction=0.0,
    steady_abs_d=0.002,
    steady_abs_theta_e_rad=0.087,
    max_abs_delta=0.3,
    steer_energy=0.5,
    final_delta=math.radians(10.0),
    final_theta_e=math.radians(-5.0),
)


def run_rows(**mixed) -> list[dict]:
    """:data:`RUN` for every path and controller, the mixed design's metrics replaced by ``mixed``."""
    return [
        {"path": p, "controller": c, **RUN, **(mixed if c == "mixed" else {})}
        for p in ("line", "parabola", "sine")
        for c in ("mixed", "paper-k", "pi")
    ]
