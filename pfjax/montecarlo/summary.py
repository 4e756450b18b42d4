"""A study's ``summary.json``: robustness quantities per controller, from the run table and the margin sweep.

Per controller (all paths pooled, and per path): success rate with its 95 % Clopper-Pearson
interval, quantiles of every metric, status counts, the probabilistic statement the sample
supports, the slip margin per axis (rear, front, joint), and which sampled parameters drive
failure. The top-level keys: ``study``, ``n_runs_total``, ``seed``, ``config_sha256`` and
``controllers`` (each with ``success_rate``, ``success_ci95``, ``iae_mean``, ``iae_p95``,
``steady_abs_d_p95``, ``slip_margin_deg`` and ``slip_margin_fails_at_deg``: the joint-axis margin,
or null with the smallest amplitude tested in ``slip_margin_fails_at_deg`` when the controller
already fails there; both null when the sweep has no joint axis, whose margins are in ``slip_margin``).
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

import pfjax
from pfjax.metrics.margins import slip_margin
from pfjax.metrics.robustness import (
    failure_drivers,
    hoeffding_n,
    metric_quantiles,
    success_summary,
    supported_statement,
    zero_failure_n,
)
from pfjax.metrics.running import METRIC_NAMES
from pfjax.montecarlo.config import StudySpec, study_hash
from pfjax.montecarlo.sampling import column_names
from pfjax.provenance import STAMP_UNITS, cpu_settings, machine
from pfjax.sim.dynamic import SLIP_METRIC_NAMES
from pfjax.tables import COLUMNS

QUANTILE_METRICS = [m for m in METRIC_NAMES if m != "success"]

#: The keys :func:`summarize` always writes, at the top and in each controller's block (what a
#: report of a finished study reads: :func:`missing_key`).
SUMMARY_KEYS = ("study", "n_runs_total", "seed", "config_sha256", "dtype", "config", "controllers", "units")
CONTROLLER_KEYS = (
    *("n", "k", "success_rate", "success_ci95", "iae_mean", "iae_p95", "steady_abs_d_p95", "status_counts"),
    *("quantiles", "gains", "per_path", "statement", "slip_margin", "failure_drivers", "success_by_param"),
)

#: ``summary.json``'s units by field name (a field has one meaning wherever it occurs; "1":
#: dimensionless). :func:`summary_units` adds the units that depend on the study: the metrics'
#: (``quantiles``), the sampled parameters' (``success_by_param``) and the worst-case objective's.
UNITS: dict[str, object] = {
    **dict.fromkeys(("n_runs_total", "n_runs_per_controller_and_path", "n_margin_runs", "n"), "runs"),
    "k": "runs (successful)",
    "k_fail": "runs (failed)",
    "status_counts": "runs",
    "n_finite": "runs (with a finite value)",
    "n_per_controller": "runs",
    "chunks": "chunks of runs",
    **dict.fromkeys(("run", "run_indices"), "run index (the random stream of the run)"),
    **STAMP_UNITS,
    "wall_s": "s",
    "timings_s": "s (wall clock per phase)",
    "success_rate": "1",
    "success_ci95": "1 (95 % Clopper-Pearson interval of the success rate)",
    "iae_mean": "m s (over runs with status ok)",
    "iae_p95": "m s (over runs with status ok)",
    "steady_abs_d_p95": "m (over runs with status ok)",
    **dict.fromkeys(("delta", "confidence", "hoeffding_eps", "hoeffding_lower", "zero_failure_eps", "cp_lower"), "1"),
    **dict.fromkeys(("margin", "margin_lo", "margin_hi", "resolution", "amplitude"), "deg"),
    **dict.fromkeys(("slip_margin_deg", "slip_margin_fails_at_deg", "worst_slip_peak_deg", "theta_e0_deg"), "deg"),
    "eps": "1 (a margin's tolerance on the success rate)",
    "rate": "1 (success rate at the amplitude)",
    "lo": "1 in a margin table (95 % interval of rate); in success_by_param, the parameter's unit (below)",
    "hi": "1 in a margin table (95 % interval of rate); in success_by_param, the parameter's unit (below)",
    **dict.fromkeys(("rho_failure", "rho_metric"), "1 (Spearman rank correlation)"),
    **dict.fromkeys(("p_failure", "p_metric"), "1 (p-value)"),
    "effect_size": "1 (standard deviations of the parameter)",
    **dict.fromkeys(("hoeffding", "zero_failure"), "runs"),
    "max_abs_diff_iae": "m s",
    "max_rel_diff_iae": "1",
    "max_abs_diff_late_max_abs_d": "m",
    **dict.fromkeys(("status_agreement", "success_agreement"), "1 (fraction of the runs checked)"),
    "d0": "m",
    "ratio": "1",
    "n_rollouts": "rollouts (simulated runs)",
    "n_gradients": "gradient evaluations",
    **dict.fromkeys(("history_rollouts", "history_random_rollouts"), "rollouts (simulated runs)"),
    "p_fail_ci95": "probability (95 % interval of p_fail)",
    "plain_fail": "probability (share of the study's runs failing by the rare-event event)",
    "plain_fail_ci95": "probability (Clopper-Pearson 95 % interval of plain_fail)",
}


def summary_units(spec: StudySpec, params: list[str]) -> dict:
    """:data:`UNITS` with the study's own: ``quantiles`` (each metric's unit, which its ``mean``,
    ``std`` and quantiles take), ``success_by_param`` (each sampled parameter's unit, which its
    bins' ``lo`` and ``hi`` take), the worst-case search's ``falsifier``, ``random``,
    ``history`` and ``history_random`` (the objective's unit) and, with rare-event estimates,
    their block's (:func:`pfjax.rare.study.units`), and ``gains``: each controller's gains' units
    by its name (:func:`pfjax.controllers.gain_units`: a gain's name has other units in other
    controllers)."""
    from pfjax import controllers as C

    units = {name: COLUMNS[name][0] for name in COLUMNS if COLUMNS[name][0]}
    objective = spec.falsifier.objective
    rare = {}
    if spec.rare_event.enabled:  # the estimates' (p_fail, rel_error, ...), as pfjax rare-event gives them
        from pfjax.rare.study import units as rare_units

        rare = rare_units(spec)
    return {
        **rare,
        **UNITS,
        "quantiles": {m: units[m] for m in QUANTILE_METRICS + list(SLIP_METRIC_NAMES) if m in units},
        "success_by_param": {p: units[p] for p in params if p in units},
        "gains": {c.name: C.gain_units(C.resolve(c.type, "type")[0]) for c in spec.controllers},
        **dict.fromkeys(("falsifier", "random", "history", "history_random"), f"{units[objective]} ({objective})"),
    }


def run_statistics(df: pd.DataFrame) -> dict:
    """A controller's statistics over its rows of a run table (``success``, ``status`` and the
    metrics' columns): ``n``, ``k``, ``success_rate``, ``success_ci95``, ``iae_mean``, ``iae_p95``,
    ``steady_abs_d_p95``, ``status_counts`` and ``quantiles``. Success over every run; the metrics' statistics (``iae_mean``, ``iae_p95``, ``quantiles``) over
    the runs that ran the whole horizon (status ``ok``): a failed run's metrics describe it only up
    to its failure (a run that diverges at once has an IAE of about 0), so the failures are counted
    by ``status_counts`` and the success rate, not averaged into the metrics."""
    s = success_summary(df["success"].to_numpy())
    q = metric_quantiles(df[df["status"] == "ok"], QUANTILE_METRICS + [m for m in SLIP_METRIC_NAMES if m in df])
    return {
        **s,
        "iae_mean": q["iae"]["mean"],
        "iae_p95": q["iae"]["q95"],
        "steady_abs_d_p95": q["steady_abs_d"]["q95"],
        "status_counts": {k: int(v) for k, v in df["status"].value_counts().items()},
        "quantiles": q,
    }


def success_by_param(df: pd.DataFrame, param: str, max_bins: int = 8) -> list[dict]:
    """Success rate (with its Clopper-Pearson 95 % interval) per bin of a sampled parameter:
    one bin per value for parameters with few distinct values, else equal-count quantile bins."""
    x = df[param].to_numpy()
    ok = np.isfinite(x)
    x, success = x[ok], df["success"].to_numpy()[ok]
    values = np.unique(x)
    if len(values) <= max_bins:
        groups = [(v, v, x == v) for v in values]
    else:
        edges = np.unique(np.quantile(x, np.linspace(0, 1, max_bins + 1)))
        idx = np.clip(np.searchsorted(edges, x, side="right") - 1, 0, len(edges) - 2)
        groups = [(edges[i], edges[i + 1], idx == i) for i in range(len(edges) - 1)]
    out = []
    for lo, hi, m in groups:
        s = success_summary(success[m])
        out.append(
            {
                "lo": float(lo),
                "hi": float(hi),
                "n": s["n"],
                "success_rate": s["success_rate"],
                "success_ci95": s["success_ci95"],
            }
        )
    return out


def margins(counts: pd.DataFrame | None, controller: str, eps: float) -> dict:
    """Slip margins of ``controller`` per axis, from the sweep's success counts
    (:func:`pfjax.montecarlo.runner.margin_sweep`: columns controller, axis, amplitude_deg, k, n)."""
    if counts is None or counts.empty:
        return {}
    out = {}
    for axis, g in counts[counts.controller == controller].groupby("axis", sort=False):
        agg = g.groupby("amplitude_deg")[["k", "n"]].sum().sort_index()
        # with each reading's fails_at_smallest: "fails even at the smallest slip" (e.g. a path it
        # cannot follow within the band at all) is said, not reported as a bare 0
        out[axis] = slip_margin(agg.index.to_numpy(), agg["k"].to_numpy(), agg["n"].to_numpy(), eps=eps)
    return out


#: run-table columns the summary does not read (the streamed reader skips them)
_UNUSED = ("controller", "run", "status_code", "fail_time")


def _controller_rows(runs, name: str) -> pd.DataFrame:
    """One controller's rows: a slice of a DataFrame, or read from a ``runs.parquet`` path (only
    that controller's rows and the columns the summary uses are read, and the Arrow buffers are
    handed back as soon as pandas owns the data, so memory holds one controller's runs, not the study's)."""
    if isinstance(runs, pd.DataFrame):
        return runs[runs.controller == name]
    import pyarrow as pa
    import pyarrow.parquet as pq

    columns = [c for c in pq.read_schema(runs).names if c not in _UNUSED]
    table = pq.read_table(runs, columns=columns, filters=[("controller", "==", name)])
    df = table.to_pandas(self_destruct=True, split_blocks=True)
    del table
    pa.default_memory_pool().release_unused()
    return df


def driver_table(df: pd.DataFrame, params: list[str]) -> pd.DataFrame:
    """:func:`~pfjax.metrics.robustness.failure_drivers` of one controller's runs: ``rho_failure``
    and the effect size over every run, ``rho_metric`` (IAE) over the runs with status ``ok``, as
    every metric statistic: a failed run's IAE stops at its failure, and one that fails at once has
    an IAE of 0, which would rank it as the best run."""
    return failure_drivers(df.assign(iae=df["iae"].where(df["status"] == "ok")), params, metric="iae")


def missing_key(summary) -> str | None:
    """The first of :data:`SUMMARY_KEYS`, or ``controllers.<name>.<key>`` of :data:`CONTROLLER_KEYS`,
    that ``summary`` (a parsed ``summary.json``) lacks; ``""`` if it is not a JSON object, None if
    none is missing."""
    if not isinstance(summary, dict):
        return ""
    top = [k for k in SUMMARY_KEYS if k not in summary]
    if top or not isinstance(summary["controllers"], dict):
        return top[0] if top else "controllers"
    for name, block in summary["controllers"].items():
        if not isinstance(block, dict):
            return f"controllers.{name}"
        keys = [k for k in CONTROLLER_KEYS if k not in block]
        if keys:
            return f"controllers.{name}.{keys[0]}"
    return None


def summarize(spec: StudySpec, runs, sweep: pd.DataFrame | None, *, gains: dict, wall_s: float) -> dict:
    """The summary (module docstring). ``runs``: the run table as a DataFrame, or the path of
    ``runs.parquet``, read one controller at a time (large studies: peak memory is one
    controller's rows). ``sweep``: the slip-margin sweep's success counts
    (:func:`pfjax.montecarlo.runner.margin_sweep`), or None."""
    import pyarrow.parquet as pq

    n_total = len(runs) if isinstance(runs, pd.DataFrame) else pq.ParquetFile(runs).metadata.num_rows
    controllers, params = {}, None
    for name in [c.name for c in spec.controllers]:
        df = _controller_rows(runs, name)
        if params is None:  # every controller runs the same sampled scenarios (common random numbers)
            params = [c for c in column_names(spec) if df[c].nunique(dropna=True) > 1]
        block = run_statistics(df)
        block["gains"] = gains.get(name, {})
        block["per_path"] = {
            p: {k: v for k, v in run_statistics(g).items() if k != "quantiles"}
            for p, g in df.groupby("path", sort=False)
        }
        block["statement"] = supported_statement(len(df), int((~df["success"]).sum()))
        mg = margins(sweep, name, spec.margin.eps)
        block["slip_margin"] = mg
        joint = mg.get("joint")  # the headline margin is the joint axis's (null if not swept)
        # a controller that fails at the smallest amplitude has no margin: say so, not a bare 0
        fails = joint is not None and joint["fails_at_smallest"]
        block["slip_margin_deg"] = None if joint is None or fails else joint["margin"]
        block["slip_margin_fails_at_deg"] = joint["table"][0]["amplitude"] if fails and joint is not None else None
        block["slip_margin_censored"] = None if joint is None else joint["censored"]
        drivers = driver_table(df, params) if params else pd.DataFrame()
        block["failure_drivers"] = drivers.replace({np.nan: None}).to_dict("records")  # every parameter, ranked
        block["success_by_param"] = {p: success_by_param(df, p) for p in params}
        controllers[name] = block
        del df  # before the next controller's rows are read
    return {
        "study": spec.name,
        "n_runs_total": int(n_total),
        "n_runs_per_controller_and_path": spec.n_runs,
        "n_margin_runs": 0 if sweep is None else int(sweep["n"].sum()),
        "seed": spec.seed,
        "config_sha256": study_hash(spec),
        "pfjax_version": pfjax.__version__,
        "dtype": spec.dtype,
        "machine": machine(),
        "cpu_settings": cpu_settings(),
        "wall_s": wall_s,
        "config": spec.model_dump(mode="json"),
        "paths": [p.label for p in spec.paths],
        "controllers": controllers,
        "units": summary_units(spec, params or []),
        "sample_size": {
            "note": "runs needed for P(success) within eps of the estimate (Hoeffding) or for zero failures to bound P(failure) <= eps (worst case), at confidence 1 - delta = 0.95",
            **{
                f"eps={e:g}": {"hoeffding": hoeffding_n(e, 0.05), "zero_failure": zero_failure_n(e, 0.05)}
                for e in (0.05, 0.01, 0.001)
            },
        },
    }


def headline(summary: dict) -> pd.DataFrame:
    """One row per controller: the numbers a reader compares first."""
    rows = []
    for name, c in summary["controllers"].items():
        lo, hi = c["success_ci95"]
        rows.append(
            {
                "controller": name,
                "runs": c["n"],
                "success_rate": c["success_rate"],
                "ci95_lo": lo,
                "ci95_hi": hi,
                "iae_mean": c["iae_mean"],
                "iae_p95": c["iae_p95"],
                "steady_abs_d_p95_mm": 1000 * c["steady_abs_d_p95"]
                if c["steady_abs_d_p95"] is not None and math.isfinite(c["steady_abs_d_p95"])
                else math.nan,
                "slip_margin_deg": c["slip_margin_deg"],
                "slip_margin_fails_at_deg": c.get("slip_margin_fails_at_deg"),
            }
        )
    return pd.DataFrame(rows)
