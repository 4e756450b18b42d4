"""Summary of the kinematic-vs-dynamic study's runs (:mod:`pfjax.dynamic_study.runs`): slip
distributions of the dynamic arms, success rates with 95 % Clopper-Pearson intervals, paired
differences with 95 % Tango score intervals, verdicts and equivalent kinematic slip ranges per controller and scale.

Success counts every run; the slip statistics and the late max |d| statistics are over the runs
that ran the whole horizon (status ``ok``), as :func:`pfjax.montecarlo.summary.run_statistics`
takes a study's metrics: a failed run's slip and errors describe it only up to its failure (a run
that fails at its first sample has none), so the failures are counted, not averaged in."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from pfjax.dynamic_study.config import KinematicVsDynamic, kinematic_arm
from pfjax.metrics.robustness import clopper_pearson, paired_interval
from pfjax.provenance import STAMP_UNITS

#: A verdict's line: a controller is robust in an arm if its success rate is at least this.
ROBUST = 0.95
SLIP_COLS = ["max_abs_beta_r_deg", "max_abs_beta_f_deg", "mean_abs_beta_r_deg", "mean_abs_beta_f_deg"]
#: The design norms' channels (:mod:`pfjax.synthesis.dynamic_plant`); the norms are numbers of these
#: channels in SI units (the channels' units differ, so a norm has no one unit).
_INPUTS = "w = [w_r rad, w_f rad, kappa 1/m]"
_Z_INF = "z_inf = [d m, theta_e rad(, int d m s)]"
#: ``summary.json``'s units, by field name (a field has one meaning wherever it occurs).
UNITS = {
    "mu": "1 (friction coefficient; a bin's [lo, hi])",
    "speed": "m/s (a bin's [lo, hi])",
    **{c: "deg (q50, q95, max: quantiles over runs)" for c in SLIP_COLS},
    "declared_range_deg": "deg",
    "fraction_max_beyond_declared": "1",
    "max_curvature_robot": "1/m (the robot-scale path)",
    "robust_line": "1 (success rate)",
    "rate": "1 (success rate)",
    "ci95": "1 (95 % interval of a rate, Clopper-Pearson, or of a paired difference of success rates, Tango's score)",
    "only_dynamic": "runs (a success in the dynamic arm only)",
    "only_kinematic": "runs (a success in the reference kinematic arm only)",
    "diff": "1 (difference of success rates)",
    "equivalent_gap": "1 (difference of success rates)",
    "k": "runs",
    "n": "runs (in the slip tables: those with status ok)",
    "n_failed": "runs (failed, left out of the slip statistics)",
    "n_ok": "runs (status ok: the late max |d| statistics' runs)",
    "failure_status_dynamic": "runs",
    "late_max_abs_d_q95": "m (over runs with status ok)",
    "worst_late_max_abs_d": "m (over runs with status ok)",
    "operating_point": "v m/s, mu 1, tau_delta_s s",
    **dict.fromkeys(("K", "K0"), "rad/m, rad/rad (state feedback); rad/m, rad/rad, rad/(m s) (integral)"),
    "hinf_norm": f"H-infinity norm from {_INPUTS} to {_Z_INF} (channels in these SI units: no one unit), "
    "the largest over the design's plants",
    "h2_norm": f"H2 norm from {_INPUTS} to [{_Z_INF}; delta_c rad] (channels in these SI units: no one unit), "
    "the largest over the design's plants",
    "criterion": "1 (alpha hinf_norm^2 + beta h2_norm^2, alpha and beta dimensionless, at K)",
    "criterion0": "1 (the criterion at K0, the kinematic gain; null: K0 does not stabilise every plant)",
    "evaluations": "criterion evaluations (of the gain search)",
    "max_pole_real": "1/s",
    "ns_per_rollout_step": "ns",
    "ratio_st_over_kinematic": "1 (ratio of ns_per_rollout_step)",
    "ratio_std_over_kinematic": "1 (ratio of ns_per_rollout_step)",
    "runs": "runs (per timed batch)",
    "steps": "steps (per timed run)",
    "wall_s": "s",
    "load_average": "processes (1, 5, 15 min)",
    **STAMP_UNITS,
}


def path_curvatures(config: KinematicVsDynamic) -> dict[str, float]:
    """Path label -> the robot-scale path's largest |curvature| (1/m) over the support of its
    distributions (:func:`pfjax.montecarlo.checks.path_max_curvature`: the registry's bound for a
    fixed path; NaN for a random path), for the slip-by-path tables."""
    from pfjax.montecarlo.checks import path_max_curvature
    from pfjax.montecarlo.config import PathSpec

    specs = [PathSpec.model_validate(q) for q in config.study["paths"]]
    return {p.label: path_max_curvature(p) for p in specs}


def _rate(success: np.ndarray) -> dict:
    k, n = int(np.sum(success)), len(success)
    lo, hi = clopper_pearson(k, n)
    return {"rate": k / n, "ci95": [lo, hi], "k": k, "n": n}


def _paired(a: np.ndarray, b: np.ndarray) -> dict:
    """The mean of the paired differences ``a - b`` of success indicators, with its 95 % Tango score
    interval (:func:`paired_interval`)."""
    a, b = a.astype(bool), b.astype(bool)
    n, only_a, only_b = len(a), int(np.sum(a & ~b)), int(np.sum(~a & b))
    return {
        "diff": (only_a - only_b) / n if n else math.nan,
        "ci95": list(paired_interval(only_a, only_b, n)),
        "n": n,
        "only_dynamic": only_a,
        "only_kinematic": only_b,
    }


def _side(r: dict) -> str:
    """``robust`` (interval above the line), ``fragile`` (below) or ``undecided`` (straddles it)."""
    lo, hi = r["ci95"]
    return "robust" if lo >= ROBUST else "fragile" if hi < ROBUST else "undecided"


def survives(kinematic: str, dynamic: str) -> str:
    """Whether the kinematic verdict survives on the dynamic arm: ``undecided`` where either verdict
    is (there is no claim to keep, or no evidence to keep or drop it), else ``yes`` if the two agree
    and ``no`` if they differ."""
    if "undecided" in (kinematic, dynamic):
        return "undecided"
    return "yes" if kinematic == dynamic else "no"


def _q(s: pd.Series) -> dict:
    return {"q50": float(s.quantile(0.5)), "q95": float(s.quantile(0.95)), "max": float(s.max())}


def bins(values: pd.Series, n: int) -> list[tuple[float, float, pd.Series]]:
    """``n`` equal bins over the range of ``values``, each ``(lo, hi, mask of its rows)``: half-open
    ``[lo, hi)``, the last closed, so that every finite value lies in exactly one bin; a range of zero
    width is one bin ``[lo, lo]``; empty bins are left out."""
    ok = values.notna()
    if not ok.any():
        return []
    lo, hi = float(values[ok].min()), float(values[ok].max())
    if not lo < hi:
        return [(lo, hi, ok)]
    edges = np.linspace(lo, hi, n + 1)
    index = np.clip(np.searchsorted(edges, values.to_numpy(), side="right") - 1, 0, n - 1)
    out = []
    for i in range(n):
        mask = ok & (index == i)
        if mask.any():
            out.append((float(edges[i]), float(edges[i + 1]), mask))
    return out


def _slip_stats(part: pd.DataFrame) -> dict:
    """``n`` (the runs with status ok), ``n_failed`` and the slip quantiles over the ok runs of ``part``."""
    ok = part[part.status == "ok"]
    return {"n": len(ok), "n_failed": len(part) - len(ok), **{c: _q(ok[c]) for c in SLIP_COLS}}


def _binned(dyn: pd.DataFrame, col: str, n: int) -> list[dict]:
    """:func:`_slip_stats` in :func:`bins` over the range of every run of ``dyn``."""
    return [{col: [lo, hi], **_slip_stats(dyn[mask])} for lo, hi, mask in bins(dyn[col], n)]


def slip_summary(dyn: pd.DataFrame, declared: float, curvature: dict[str, float] | None = None) -> dict:
    """The slip the dynamic arm ``dyn`` produced, over its runs with status ``ok`` (module
    docstring; ``n``: their number, ``n_failed``: the runs left out, in all and in each part): by
    friction and speed (bins over the range of every run) and by path (with its robot-scale largest
    curvature, 1/m, from ``curvature``: :func:`path_curvatures`; NaN where it has none); quantiles NaN in a part without an
    ok run."""
    ok = dyn[dyn.status == "ok"]
    by_path = [
        {"path": p, "max_curvature_robot": (curvature or {}).get(p, math.nan), **_slip_stats(part)}
        for p, part in dyn.groupby("path")
    ]
    return {
        "n": len(ok),
        "n_failed": len(dyn) - len(ok),
        "by_mu": _binned(dyn, "mu", 7),
        "by_speed": _binned(dyn, "speed", 3),
        "by_path": by_path,
        "all": {c: _q(ok[c]) for c in SLIP_COLS},
        "declared_range_deg": declared,
        "fraction_max_beyond_declared": {
            c: float(np.mean(ok[c] > declared)) if len(ok) else math.nan
            for c in ("max_abs_beta_r_deg", "max_abs_beta_f_deg")
        },
    }


def compare(runs: pd.DataFrame, dyn_arm: str, ref_arm: str, kin_prefix: str, extra_arms=()) -> dict:
    """Per controller of ``dyn_arm``: success in it, in ``ref_arm`` and in every arm starting with
    ``kin_prefix``; the paired difference ``dyn_arm - ref_arm``; the verdicts; the equivalent
    kinematic arm; success by path and friction; the late max |d| over the runs with status ``ok``
    (``n_ok`` per arm; NaN where none is); the failure statuses. ``verdict_survives`` is ``yes``,
    ``no`` or ``undecided`` (:func:`survives`). The equivalent kinematic arm is
    the one whose success rate is closest to the dynamic arm's (``closest_kinematic_arm``, the gap
    ``equivalent_gap``) if the dynamic rate lies in its 95 % interval, else None."""
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
        closest = min(kin_arms, key=lambda a: abs(kin_arms[a]["rate"] - rates[dyn_arm]["rate"]))
        gap = abs(kin_arms[closest]["rate"] - rates[dyn_arm]["rate"])
        # equivalent only if the dynamic rate lies in that arm's 95 % interval, not merely nearest
        lo, hi = kin_arms[closest]["ci95"]
        equivalent = closest if lo <= rates[dyn_arm]["rate"] <= hi else None
        dm = d.reset_index()
        ok = mine[mine.status == "ok"]
        late = {arm: ok[ok.arm == arm].late_max_abs_d for arm in arms_}  # over the runs with status ok
        out[name] = {
            "success": rates,
            "success_by_path": {
                arm: {p: _rate(part.success.to_numpy()) for p, part in mine[mine.arm == arm].groupby("path")}
                for arm in (dyn_arm, ref_arm)
            },
            "success_by_mu_dynamic": [
                {"mu": [lo, hi], **_rate(dm[mask].success.to_numpy())} for lo, hi, mask in bins(dm.mu, 3)
            ],
            "paired_dynamic_minus_kinematic": _paired(d.success.to_numpy(), k.success.to_numpy()),
            "verdict_kinematic": _side(rates[ref_arm]),
            "verdict_dynamic": _side(rates[dyn_arm]),
            "verdict_survives": survives(_side(rates[ref_arm]), _side(rates[dyn_arm])),
            "equivalent_kinematic_arm": equivalent,
            "closest_kinematic_arm": closest,
            "equivalent_gap": gap,
            "failure_status_dynamic": {str(s): int(v) for s, v in d.status.value_counts().items()},
            "n_ok": {arm: len(late[arm]) for arm in arms_},
            "late_max_abs_d_q95": {arm: float(late[arm].quantile(0.95)) for arm in arms_},
            "worst_late_max_abs_d": {arm: float(late[arm].max()) for arm in arms_},
        }
    return {"dynamic_arm": dyn_arm, "reference_arm": ref_arm, "controllers": out}


def summarise(config: KinematicVsDynamic, runs: pd.DataFrame) -> dict:
    """The study's summary: one comparison per scale (robot, designs, car) and the slip tables."""
    a_max = max(config.slip_ranges_deg)
    arms_ = set(runs.arm)
    curvature = path_curvatures(config)
    out = {
        "robust_line": ROBUST,
        "slip": slip_summary(runs[runs.arm == "dynamic"], a_max, curvature),
        "robot": compare(runs, "dynamic", kinematic_arm(a_max), "kinematic_", extra_arms=(config.grip_arm,)),
    }
    if "designs_dynamic" in arms_:
        ref = kinematic_arm(a_max, "designs_kinematic_")
        out["designs_comparison"] = compare(runs, "designs_dynamic", ref, "designs_kinematic_")
    if "car_dynamic" in arms_:
        out["car_slip"] = slip_summary(runs[runs.arm == "car_dynamic"], a_max, curvature)
        out["car"] = compare(runs, "car_dynamic", kinematic_arm(a_max, "car_kinematic_"), "car_kinematic_")
    return out
