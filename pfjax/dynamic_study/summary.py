"""Summary of the kinematic-vs-dynamic study's runs (:mod:`pfjax.dynamic_study.runs`): slip
distributions of the dynamic arms, success rates with 95 % Clopper-Pearson intervals, paired
differences, verdicts and equivalent kinematic slip ranges per controller and scale."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pandas as pd

from pfjax.dynamic_study.config import KinematicVsDynamic
from pfjax.metrics.robustness import clopper_pearson

#: A verdict's line: a controller is robust in an arm if its success rate is at least this.
ROBUST = 0.95
SLIP_COLS = ["max_abs_beta_r_deg", "max_abs_beta_f_deg", "mean_abs_beta_r_deg", "mean_abs_beta_f_deg"]
#: The source paths' largest curvature, 1/m (pfjax.paths registry), for the slip-by-curvature table.
PATH_CURVATURE = {"line": 0.0, "sine": 1.0, "parabola": 2.0}


def _rate(success: np.ndarray) -> dict:
    k, n = int(np.sum(success)), len(success)
    lo, hi = clopper_pearson(k, n)
    return {"rate": k / n, "ci95": [lo, hi], "k": k, "n": n}


def _paired(a: np.ndarray, b: np.ndarray) -> dict:
    """Mean of the paired differences ``a - b`` (success indicators) with its 95 % normal interval."""
    d = a.astype(float) - b.astype(float)
    se = float(np.std(d, ddof=1) / math.sqrt(len(d))) if len(d) > 1 else math.nan
    m = float(np.mean(d))
    return {"diff": m, "ci95": [m - 1.96 * se, m + 1.96 * se], "n": len(d)}


def _side(r: dict) -> str:
    """``robust`` (interval above the line), ``fragile`` (below) or ``undecided`` (straddles it)."""
    lo, hi = r["ci95"]
    return "robust" if lo >= ROBUST else "fragile" if hi < ROBUST else "undecided"


def _q(s: pd.Series) -> dict:
    return {"q50": float(s.quantile(0.5)), "q95": float(s.quantile(0.95)), "max": float(s.max())}


def _binned(dyn: pd.DataFrame, col: str, edges) -> list[dict]:
    out = []
    for lo, hi in itertools.pairwise(edges):
        part = dyn[(dyn[col] >= lo) & (dyn[col] <= hi)]
        if len(part):
            out.append({col: [float(lo), float(hi)], "n": len(part), **{c: _q(part[c]) for c in SLIP_COLS}})
    return out


def slip_summary(dyn: pd.DataFrame, declared: float, speed_scale: float = 1.0) -> dict:
    """The slip the dynamic arm ``dyn`` produced: by friction, speed and path (curvature)."""
    v_lo, v_hi = float(dyn.speed.min()), float(dyn.speed.max())
    by_path = [
        {"path": p, "max_curvature_robot": PATH_CURVATURE.get(p), "n": len(part), **{c: _q(part[c]) for c in SLIP_COLS}}
        for p, part in dyn.groupby("path")
    ]
    return {
        "by_mu": _binned(dyn, "mu", np.linspace(float(dyn.mu.min()), float(dyn.mu.max()), 8)),
        "by_speed": _binned(dyn, "speed", np.linspace(v_lo, v_hi, 4)),
        "by_path": by_path,
        "all": {c: _q(dyn[c]) for c in SLIP_COLS},
        "declared_range_deg": declared,
        "fraction_max_beyond_declared": {
            c: float(np.mean(dyn[c] > declared)) for c in ("max_abs_beta_r_deg", "max_abs_beta_f_deg")
        },
    }


def compare(runs: pd.DataFrame, dyn_arm: str, ref_arm: str, kin_prefix: str, extra_arms=()) -> dict:
    """Per controller of ``dyn_arm``: success in it, in ``ref_arm`` and in every arm starting with
    ``kin_prefix``; the paired difference ``dyn_arm - ref_arm``; the verdicts; the equivalent
    kinematic arm; success by path and friction; the late max |d|; the failure statuses."""
    key = ["path", "controller", "run"]
    arms_ = [dyn_arm, *extra_arms, *[a for a in dict.fromkeys(runs.arm) if a.startswith(kin_prefix)]]
    out = {}
    dyn_all = runs[runs.arm == dyn_arm]
    for name in dict.fromkeys(dyn_all.controller):
        mine = runs[(runs.controller == name) & runs.arm.isin(arms_)]
        rates = {arm: _rate(mine[mine.arm == arm].success.to_numpy()) for arm in arms_}
        d = mine[mine.arm == dyn_arm].set_index(key).sort_index()
        k = mine[mine.arm == ref_arm].set_index(key).sort_index()
        kin_arms = {a: r for a, r in rates.items() if a.startswith(kin_prefix)}
        equivalent = min(kin_arms, key=lambda a: abs(kin_arms[a]["rate"] - rates[dyn_arm]["rate"]))
        dm = d.reset_index()
        edges = np.linspace(float(dm.mu.min()), float(dm.mu.max()), 4)
        out[name] = {
            "success": rates,
            "success_by_path": {
                arm: {p: _rate(part.success.to_numpy()) for p, part in mine[mine.arm == arm].groupby("path")}
                for arm in (dyn_arm, ref_arm)
            },
            "success_by_mu_dynamic": [
                {"mu": [float(lo), float(hi)], **_rate(dm[(dm.mu >= lo) & (dm.mu <= hi)].success.to_numpy())}
                for lo, hi in itertools.pairwise(edges)
            ],
            "paired_dynamic_minus_kinematic": _paired(d.success.to_numpy(), k.success.to_numpy()),
            "verdict_kinematic": _side(rates[ref_arm]),
            "verdict_dynamic": _side(rates[dyn_arm]),
            "verdict_survives": _side(rates[ref_arm]) == _side(rates[dyn_arm]),
            "equivalent_kinematic_arm": equivalent,
            "equivalent_gap": abs(kin_arms[equivalent]["rate"] - rates[dyn_arm]["rate"]),
            "failure_status_dynamic": {str(s): int(v) for s, v in d.status.value_counts().items()},
            "late_max_abs_d_q95": {arm: float(mine[mine.arm == arm].late_max_abs_d.quantile(0.95)) for arm in arms_},
            "worst_late_max_abs_d": {arm: float(mine[mine.arm == arm].late_max_abs_d.max()) for arm in arms_},
        }
    return {"dynamic_arm": dyn_arm, "reference_arm": ref_arm, "controllers": out}


def summarise(config: KinematicVsDynamic, runs: pd.DataFrame) -> dict:
    """The study's summary: one comparison per scale (robot, designs, car) and the slip tables."""
    a_max = max(config.slip_ranges_deg)
    arms_ = set(runs.arm)
    grip = f"dynamic_mu{config.mu_grip:g}"
    out = {
        "robust_line": ROBUST,
        "slip": slip_summary(runs[runs.arm == "dynamic"], a_max),
        "robot": compare(runs, "dynamic", f"kinematic_{a_max:g}deg", "kinematic_", extra_arms=(grip,)),
    }
    if "designs_dynamic" in arms_:
        ref = f"designs_kinematic_{a_max:g}deg"
        out["designs_comparison"] = compare(runs, "designs_dynamic", ref, "designs_kinematic_")
    if "car_dynamic" in arms_:
        out["car_slip"] = slip_summary(runs[runs.arm == "car_dynamic"], a_max)
        out["car"] = compare(runs, "car_dynamic", f"car_kinematic_{a_max:g}deg", "car_kinematic_")
    return out
