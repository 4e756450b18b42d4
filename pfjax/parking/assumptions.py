"""What the parking cases' outcomes depend on: the source's four cases under every combination of
the modelling assumptions the source leaves open (docs/reproductions/parking.md §3), in one batch.

The assumptions swept (each a :func:`pfjax.parking.simulate.run_params` argument):

* ``front`` — the rectangle's reach ahead of the wheel axle, m (the source gives only the
  rectangle's size; pfjax calibrates 0.1746 m from case A's first switch);
* ``zone`` — which part of the rectangle the scanner checks toward the travel direction:
  ``"middle"`` (the half beyond the geometric middle, pfjax's default reading), ``"axle"`` (the part
  ahead of / behind the wheel axle), ``"whole"`` (any contact with the rectangle reverses);
* ``scan_period`` — the scanner's sampling period, s (0.1 s in the source's hardware);
* ``decision_delay`` — the decision taken on the pose one scanner period old;
* ``lag`` — the experiment's yaw-rate PI loop (k_P 0.8, k_I 16) on, so the robot turns late;
* ``pause`` — seconds standing still at each reversal (the source's experiments stood still 1 s).

:func:`case_sweep` simulates cases A-D (docs/reproductions/parking.md §4) for every combination; :func:`sweep_summary` counts,
for each case, the combinations in which it parks, gets stuck or times out, and lists the
combinations that reproduce all four of the source's outcomes at once (A, C, D park; B stuck).
"""

from __future__ import annotations

import itertools

import numpy as np
import pandas as pd

from pfjax.parking.defaults import ASSUMPTION_GRID
from pfjax.parking.geometry import L2_LENGTH
from pfjax.parking.model import control_params
from pfjax.parking.schedules import CASES
from pfjax.parking.simulate import STATUS_NAMES, ParkingConfig, run_many, run_params, stack_params

#: The source's outcome per case (docs/reproductions/parking.md §4): what a combination must give to reproduce it.
SOURCE_OUTCOME = {"A": "converged", "B": "stuck", "C": "converged", "D": "converged"}
ZONES = {"middle": {}, "axle": {"split": 0.0}, "whole": {"zone": L2_LENGTH}}
#: The sweep's default combinations (:data:`pfjax.parking.defaults.ASSUMPTION_GRID`; its zones are :data:`ZONES`'s keys).
DEFAULT_GRID = {key: list(values) for key, values in ASSUMPTION_GRID.items()}
KEYS = tuple(DEFAULT_GRID)


def case_sweep(
    omap,
    grid: dict = DEFAULT_GRID,
    *,
    control_kw: dict | None = None,
    cfg: ParkingConfig = ParkingConfig(),
    chunk: int = 512,
    progress: bool = False,
) -> pd.DataFrame:
    """Cases A-D under every combination of ``grid`` (keys :data:`KEYS`): one row per run with the
    combination, ``case``, ``status``, ``switches``, ``time_s`` and ``min_leg_m`` (the shortest travel
    between two reversals, m; NaN without a reversal)."""
    combos = list(itertools.product(*(grid[k] for k in KEYS)))
    items, rows = [], []
    for combo in combos:
        a = dict(zip(KEYS, combo))
        for name, c in CASES.items():
            items.append(
                run_params(
                    c["x0"],
                    c["direction"],
                    c["schedule"],
                    front=a["front"],
                    scan_period=a["scan_period"],
                    decision_delay=a["decision_delay"],
                    pause=a["pause"],
                    control=control_params(lag=a["lag"], **(control_kw or {})),
                    **ZONES[a["zone"]],
                )
            )
            rows.append({**a, "case": name})
    r = run_many(stack_params(items), omap, cfg, chunk=chunk, progress=progress, desc="assumption sweep")
    df = pd.DataFrame(rows)
    df["status"] = [STATUS_NAMES[int(s)] for s in r.status]
    df["switches"] = r.n_switches.astype(int)
    df["time_s"] = r.time
    legs = []
    for i in range(len(df)):
        n = min(int(r.n_switches[i]), r.log_t.shape[1])
        t = np.concatenate([[0.0], r.log_t[i][:n]])
        moving = np.diff(t) - df["pause"].iloc[i] * (np.arange(n) > 0)  # standing time is no travel
        legs.append(max(float(np.min(moving) * items[i].control.speed), 0.0) if n else np.nan)
    df["min_leg_m"] = legs
    return df


def sweep_summary(df: pd.DataFrame) -> dict:
    """Per case the status counts over the combinations; per detection zone how often case B is
    stuck; the combinations that reproduce all four source outcomes (A, C, D park, B stuck)."""
    wide = df.pivot_table(index=list(KEYS), columns="case", values="status", aggfunc="first")
    match = np.all([wide[c] == s for c, s in SOURCE_OUTCOME.items()], axis=0)
    by_zone = {
        z: {c: df[(df.zone == z) & (df.case == c)].status.value_counts().to_dict() for c in CASES}
        for z in df.zone.unique()
    }
    return {
        "n_combinations": int(len(wide)),
        "status_counts": {c: df[df.case == c].status.value_counts().to_dict() for c in CASES},
        "by_zone": by_zone,
        "b_min_leg_m": float(df[df.case == "B"].min_leg_m.min()),
        "all_four_reproduced": [
            dict(zip(KEYS, (v.item() if hasattr(v, "item") else v for v in idx))) for idx in wide.index[match]
        ],
    }
