"""Monte Carlo studies and rare-event estimates through the public API."""

from __future__ import annotations

import re
from typing import Any, NamedTuple

from pfjax import errors
from pfjax.errors import arguments_checked


class StudyResult(NamedTuple):
    """A study's outputs (:func:`run_study`, :func:`load_study`).

    Attributes:
        out: the output directory (a :class:`pathlib.Path`).
        summary: ``summary.json`` as a dict: per controller its success rate and interval, metric
            statistics, slip margins and failure drivers, with the provenance (``config_sha256``,
            ``seed``, pfjax's version) and the unit of every number.
        runs: ``runs.parquet`` as a pandas DataFrame, one row per run (path, controller, run index,
            sampled values, metrics, ``success``, ``status``, ``fail_time``); the unit of every column
            is in :data:`pfjax.tables.COLUMNS` and in the file's column metadata.
        margin: ``margin.parquet`` as a pandas DataFrame, one row per run of the slip-margin sweep
            (None without a margin sweep).
        headline: a pandas DataFrame, one row per controller, all paths pooled: ``runs``,
            ``success_rate`` with its 95 % Clopper-Pearson interval ``ci95_lo``, ``ci95_hi``,
            ``iae_mean`` and ``iae_p95`` (m s), ``steady_abs_d_p95_mm`` (mm) over the runs with status
            ``ok``, the joint-axis ``slip_margin_deg`` (deg; None or NaN where the controller
            already fails at the sweep's smallest amplitude, and without a sweep) and
            ``slip_margin_fails_at_deg`` (deg: that smallest amplitude where the controller fails
            at it; None or NaN otherwise), as ``pfjax study --json`` gives them.
    """

    out: Any  # pathlib.Path of the output directory
    summary: dict  # summary.json
    runs: Any  # pandas DataFrame: runs.parquet
    margin: Any  # pandas DataFrame: margin.parquet (None without a margin sweep)
    headline: Any  # pandas DataFrame: one row per controller (success rate, interval, margin)


@arguments_checked
def load_study(out) -> StudyResult:
    """Read a finished study's outputs from its directory ``out``, as ``pfjax report`` reads them.

    Args:
        out: the study's output directory (a str or path-like).

    Returns:
        the directory, ``summary.json``, the run table, the margin table (None without a margin
        sweep) and the headline table.

    Raises:
        pfjax.errors.InputError: naming ``out``: not a str or path-like; no output of ``pfjax study``
            there (its ``.pfjax-output.json``); ``summary.json``, ``runs.parquet`` or
            ``margin.parquet`` missing, changed since the study wrote it, or unreadable. These are
            ``pfjax report``'s refusals: the tables returned are the study's own.
    """
    return read_result(out)


def read_result(out, name: str = "out", reader: str = "pfjax.load_study reads") -> StudyResult:
    """:func:`load_study`, its refusals naming the caller's argument ``name`` and the caller as
    ``reader`` (:func:`pfjax.replay` reads a study directory so too)."""
    from pfjax.montecarlo.study import read_study
    from pfjax.montecarlo.summary import headline

    out = _out_dir(out, name)
    summary, runs, margin = read_study(out, name, reader)
    try:
        rows = headline(summary)
    except (KeyError, TypeError, ValueError):  # a summary.json without a controller's numbers
        raise errors.InputError(
            f"{name}: {out / 'summary.json'} is not a study summary; re-run the study", name
        ) from None
    return StudyResult(out, summary, runs, margin, rows)


def _out_dir(out, name: str = "out"):
    """``out`` (a str or path-like) as a Path; :class:`~pfjax.errors.InputError` naming ``name``
    otherwise (which directories pfjax writes is :mod:`pfjax.outputs`' rule)."""
    import os
    from pathlib import Path

    if not isinstance(out, (str, os.PathLike)):
        raise errors.InputError(f"{name}: expected a directory path, got {out!r}", name)
    if str(out).strip() == "":  # Path("") would be the current directory
        raise errors.InputError(f"{name}: '' names no directory; give a directory name such as results/my_study", name)
    return Path(out)


@arguments_checked
def run_study(
    config,
    out=None,
    *,
    overwrite: bool = False,
    fresh: bool = False,
    progress: bool | None = None,
    report: bool = True,
    **overrides,
) -> StudyResult:
    """Run a Monte Carlo study and return its outputs, as ``pfjax study`` does.

    The study computes in its config's ``dtype`` (default float32), whatever JAX is configured
    for (``float64`` enables ``jax_enable_x64`` for the study, ``float32`` turns it off for the
    study), so its numbers are ``pfjax study``'s.

    Args:
        config: a study TOML path, a config dict, or a :class:`pfjax.montecarlo.config.StudySpec`.
        out: output directory (default ``results/<name>``), written with pfjax's output rules
            (:mod:`pfjax.outputs`: another pfjax output is replaced only with ``overwrite``).
        overwrite: True: replace a pfjax output of another config or command in ``out``, or one
            whose files changed since pfjax wrote them (an edited report too); never files pfjax
            did not write there.
        fresh: True: discard the finished chunks of an interrupted run instead of resuming.
        progress: progress bars (None, the default: when stderr is a terminal).
        report: True: write the report (``report.md``, ``report.html`` and ``figures/``).
        overrides: config values by key, nested keys with ``__`` and list items by their index
            (``n_runs=1000``, ``sim__horizon=30``, ``controllers__0__gains__k_d=-2.5`` for
            ``controllers[0].gains.k_d``, ``paths=[{"kind": "line"}]``), as ``--set key=value``
            but with Python values (NumPy and JAX numbers and 1-D arrays too).

    Returns:
        the study's outputs, as :func:`load_study` reads them from ``out``.

    Warns:
        RuntimeWarning: each feasibility warning (a path sharper than the steering limit follows, a
            spline path shorter than a run travels; :func:`pfjax.montecarlo.checks.study_warnings`)
            that ``pfjax study`` prints on stderr, before the simulation starts; the study runs, and
            ``summary["warnings"]`` records them.

    Raises:
        pfjax.errors.InputError: before anything is written: a bad argument, named as here
            (``config``: no such file or not a path, dict or StudySpec; ``overwrite``, ``fresh``,
            ``report``: not True or False; ``progress``: not True, False or None); ``out`` when it
            is not a path or pfjax may not write there (:mod:`pfjax.outputs`: files pfjax did not
            write, another output without ``overwrite``; :class:`pfjax.outputs.OutputBusy` while
            another process writes there); a key of the config (``chunk_size``, ``max_rollouts``,
            ``controllers[i]``) for a study beyond the memory budget, a rare-event budget too small
            or a design that cannot be made. Its subclass :class:`pfjax.config.ConfigError` names
            the config key (an override by its dotted key) of a bad key or value.
        OSError: the file system refuses a write (what ``out`` held stays as it was).
    """
    import warnings

    from pfjax.montecarlo.checks import check_resources
    from pfjax.montecarlo.runner import study_output, study_target
    from pfjax.montecarlo.study import run

    overwrite = errors.boolean("overwrite", overwrite)
    fresh = errors.boolean("fresh", fresh)
    progress = errors.boolean("progress", progress, or_none=True)
    report = errors.boolean("report", report)
    if out is not None:
        import os

        from pfjax.outputs import target_path

        if isinstance(out, (str, os.PathLike)):  # judged as pfjax study --out is, by the same words
            target_path(os.fspath(out), "out")
        out = _out_dir(out)
    _misspelt(run_study, overrides)
    spec = _study_spec(config, {dotted(k): v for k, v in overrides.items()})
    out = study_target(spec, out)
    check_resources(spec, report=report, no_report="report=False")  # in pfjax study's order: before out
    # the output directory judged by pfjax.outputs as `pfjax study --out` is, its messages naming
    # this function's arguments (out, overwrite=True)
    output = study_output(spec, out, overwrite=overwrite, flag="out")
    # the feasibility warnings pfjax study prints on stderr, as Python warnings (also in summary.json)
    warn = lambda m: warnings.warn(m, RuntimeWarning, stacklevel=6)  # lambda, _run, run, run_study, its check
    run(spec, output, progress=progress, report=report, fresh=fresh, overwrite=overwrite, warn=warn)
    return load_study(out)


@arguments_checked
def rare_event(
    config,
    *,
    controller: str | None = None,
    method: str | None = None,
    target_rel_error: float | None = None,
    max_rollouts: int | None = None,
    seed: int | None = None,
    progress: bool | None = None,
    **overrides,
) -> dict:
    """Each controller's probability of failure under a study's uncertain inputs, down to 1e-6 and
    below, with a 95 % interval (:mod:`pfjax.rare`), as ``pfjax rare-event`` does.

    A run fails where its status is a failure or the study's ``rare_event.metric`` reaches
    ``rare_event.threshold`` (``metric >= threshold``; default: ``late_max_abs_d`` against
    ``success.band``, m). The keyword
    arguments override the config's ``[rare_event]`` table. The runs are computed in the study's
    ``dtype``, whatever JAX is configured for, as :func:`run_study`'s.

    Args:
        config: a study TOML path, a config dict, or a :class:`pfjax.montecarlo.config.StudySpec`.
        controller: only this controller of the study (default: all).
        method: ``is`` (cross-entropy importance sampling), ``subset`` (subset simulation) or
            ``mc`` (plain Monte Carlo, exact binomial interval).
        target_rel_error: ``is``, ``subset``: stop once the relative error (coefficient of
            variation) is at most this; plain Monte Carlo (``mc``) runs all of ``max_rollouts`` (its
            strata's even shares).
        max_rollouts: rollouts per controller, split evenly over the strata (docs/rare-events.md, *The budget*:
            at least :func:`pfjax.rare.study.rollouts_needed` per stratum, checked before anything is simulated).
        seed: seed of the estimator's draws.
        progress: a progress bar on stderr (None, the default: when it is a terminal).
        overrides: config values by key, nested keys with ``__``, as :func:`run_study`.

    Returns:
        ``{"study", "pfjax_version", "config_sha256", "seed", "machine", "cpu_settings", "config",
        "units", "controllers": {name: {"p_fail", "ci95",
        "rel_error", "n_rollouts", "method", "wall_s", "status", "warning", "strata",
        "failure_points"}}}`` (:func:`pfjax.rare.study.estimate_controller`), with the provenance
        record (:func:`pfjax.provenance.stamp`; ``seed`` is the estimator's, ``rare_event.seed``,
        ``config`` the validated study): ``ci95`` ``[lo, hi]``,
        ``wall_s`` s; ``status`` the verdict of the importance-sampling checks
        (:mod:`pfjax.rare.check`): ``"ok"``, or the first flagged stratum's ``"disagree"``
        (``rare_event.check = "subset"`` and subset simulation's estimate beyond the 95 %
        intervals) or ``"concentrated"`` (one draw carries more than
        :data:`pfjax.rare.check.MAX_WEIGHT_SHARE` of the estimate), else ``"no_failures"`` where
        a stratum's estimate is 0 (no failing draw seen, by any method: ``p_fail`` is then bounded
        only by its interval); ``warning`` None, or each flagged stratum's path and what was
        found, joined by ``"; "``.

    Raises:
        pfjax.errors.InputError: before anything is simulated: a bad argument, named as here
            (``method``, ``target_rel_error``, ``max_rollouts``, ``seed``, ``controller``: not one
            of the study's; ``progress``: not True, False or None; ``config``: no such file or not
            a path, dict or StudySpec); ``max_rollouts`` (or, not given, ``rare_event.max_rollouts``)
            also when the budget leaves a stratum fewer rollouts than its method needs
            (:func:`pfjax.rare.study.check_budget`); ``controllers[i]``
            for a design that cannot be made. Its subclass :class:`pfjax.config.ConfigError` names
            the config key (an override by its dotted key) of a bad key or value.
    """
    from pfjax.config import field_limits
    from pfjax.montecarlo.analysis_config import RareEventSpec
    from pfjax.montecarlo.config import study_hash
    from pfjax.montecarlo.runner import controllers_of
    from pfjax.provenance import STAMP_UNITS, stamp
    from pfjax.rare import METHODS
    from pfjax.rare.study import check_budget, estimate_study
    from pfjax.rare.study import units as rare_units

    progress = errors.boolean("progress", progress, or_none=True)
    _misspelt(rare_event, overrides)
    values = {dotted(k): v for k, v in overrides.items()}
    if method is not None:
        if method not in METHODS:
            raise errors.InputError(f"method: expected one of {', '.join(METHODS)}, got {method!r}", "method")
        values["rare_event.method"] = method
    if target_rel_error is not None:  # the bounds of the config's rare_event table, by the argument's name
        values["rare_event.target_rel_error"] = errors.number("target_rel_error", target_rel_error, positive=True)
        top = field_limits(RareEventSpec, "target_rel_error")["le"]
        if target_rel_error > top:
            raise errors.InputError(
                f"target_rel_error: must be <= {top:g}, got {errors.shown(target_rel_error)}", "target_rel_error"
            )
    if max_rollouts is not None:
        lim = field_limits(RareEventSpec, "max_rollouts")
        values["rare_event.max_rollouts"] = errors.integer(
            "max_rollouts", max_rollouts, low=int(lim["ge"]), high=int(lim["le"])
        )
    if seed is not None:
        values["rare_event.seed"] = errors.seed("seed", seed)
    spec = _study_spec(config, values)
    names = [c.name for c in spec.controllers]
    if controller is not None and controller not in names:
        raise errors.InputError(
            f"controller: {controller!r} is not one of study {spec.name!r}'s controllers: {', '.join(names)}",
            "controller",
        )
    try:  # an unsupported study or too small a budget fails here, before anything is simulated
        check_budget(spec)
    except errors.InputError as e:
        if max_rollouts is None or e.key != "rare_event.max_rollouts":
            raise
        # the budget given here, not the config's: the error names the argument (--max-rollouts)
        raise errors.InputError(str(e).replace("rare_event.max_rollouts", "max_rollouts", 1), "max_rollouts") from None
    chosen = names if controller is None else [controller]
    controllers = controllers_of(spec, chosen)  # an LMI design is solved only if chosen
    config = spec.model_dump(mode="json")
    return {
        "study": spec.name,
        **stamp(config, spec.rare_event.seed),
        "config_sha256": study_hash(spec),
        "config": config,
        "units": {**STAMP_UNITS, "seed": "1 (the estimator's seed, rare_event.seed)", **rare_units(spec)},
        "controllers": estimate_study(spec, controllers, names=chosen, progress=progress),
    }


def _misspelt(f, overrides: dict) -> None:
    """:class:`~pfjax.errors.ArgumentError` for an override that is no config key and is closest to
    one of ``f``'s own keyword arguments (``overwite=True``: a misspelt ``overwrite``, not a config
    value), naming it with that argument; the rest are left to the config's own check."""
    import difflib
    import inspect

    from pfjax.montecarlo.config import StudySpec

    keys = list(StudySpec.model_fields)
    takes = [n for n, p in inspect.signature(f).parameters.items() if p.kind is p.KEYWORD_ONLY]
    for k in overrides:
        top = re.split(r"__", k, maxsplit=1)[0]
        best = [] if top in keys else difflib.get_close_matches(top, [*takes, *keys], n=1)
        if best and best[0] in takes:
            raise errors.no_such_argument(f"pfjax.{f.__name__}", k, takes, best)


def dotted(key: str) -> str:
    """A keyword override's config key: ``__`` nests, an index between them is a list item
    (``controllers__0__gains__k_d`` -> ``controllers[0].gains.k_d``)."""
    return re.sub(r"__(\d+)(?=__|$)", r"[\1]", key).replace("__", ".")


def _study_spec(config, values: dict):
    """A validated study config from a TOML path, a dict or a StudySpec, with ``values`` overriding."""
    import os
    from pathlib import Path

    from pfjax.montecarlo.config import StudySpec
    from pfjax.montecarlo.config import load_study as load_config

    if isinstance(config, StudySpec):
        return load_config(data=config.model_dump(mode="json"), values=values)[0]
    if isinstance(config, dict):
        return load_config(data=config, values=values)[0]
    if isinstance(config, (str, os.PathLike)):  # a missing file or a directory: as pfjax study says it
        return load_config(Path(config), values=values)[0]
    raise errors.InputError(
        f"config: expected a TOML path, a dict or a StudySpec, got {type(config).__name__}", "config"
    )
