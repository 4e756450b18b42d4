"""Plain-Python views of parking results (for the CLI, JSON outputs and reports)."""

from __future__ import annotations

import math

import numpy as np

from pfjax.parking.simulate import STATUS_NAMES, RunResult, SwitchCause

CAUSE_NAMES = {int(c): c.name.lower() for c in SwitchCause}


def switch_log(r: RunResult) -> list[dict]:
    """The logged switches of one run: [{t, x, y, theta_deg, cause}] in order."""
    n = min(int(r.n_switches), len(np.asarray(r.log_t)))
    t, pose, cause = np.asarray(r.log_t), np.asarray(r.log_pose), np.asarray(r.log_cause)
    return [
        {
            "t": float(t[i]),
            "x": float(pose[i, 0]),
            "y": float(pose[i, 1]),
            "theta_deg": math.degrees(float(pose[i, 2])),
            "cause": CAUSE_NAMES[int(cause[i])],
        }
        for i in range(n)
    ]


def run_summary(r: RunResult) -> dict:
    """converged, status, time_s, switches, switch_log, final {x, y, theta_deg}, error, distance_m."""
    status = STATUS_NAMES[int(r.status)]
    f = np.asarray(r.final)
    return {
        "converged": status == "converged",
        "status": status,
        "time_s": float(r.time),
        "switches": int(r.n_switches),
        "switch_log": switch_log(r),
        "final": {"x": float(f[0]), "y": float(f[1]), "theta_deg": math.degrees(float(f[2]))},
        "error": float(r.error),
        "distance_m": float(r.distance),
    }
