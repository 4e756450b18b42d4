"""Write a benchmark result: ``bench.json`` (strict JSON, with the config, its hash, the seed, the
pfjax version and the ``units`` the command adds: :func:`result_units`), ``bench.parquet`` (one row
per implementation, dtype and batch size, each column with its unit: :data:`COLUMNS`),
``figures/throughput.png|svg`` (rollout-steps/s against batch size) and ``report.md``.
Written through :class:`pfjax.outputs.OutputDir`: assembled beside the target and moved into place
when complete, never over anything pfjax did not write.

The unit tables (:func:`summary_units`, :func:`result_units`) are in the form
:func:`pfjax.cli.records.units` reads: a dotted key's unit, or ``"<parent>.*"`` the units of
``<parent>``'s numbers by name."""

from __future__ import annotations

import math
from dataclasses import asdict

import pfjax
from pfjax.bench.problem import K_UNITS, RATE  # RATE: the unit of a rate (also report.RATE)
from pfjax.bench.run import disagreeing, disagreement
from pfjax.jsonio import dumps
from pfjax.outputs import OutputDir
from pfjax.provenance import config_hash, parquet_metadata
from pfjax.report.markdown import table
from pfjax.tables import write_parquet

#: ``bench.parquet``'s columns (``bench.json``'s rows): unit and description (unit "": text).
COLUMNS: dict[str, tuple[str, str]] = {
    "impl": ("", "implementation: pfjax, jax_minimal, numba, numpy or scipy"),
    "dtype": ("", "floating-point precision"),
    "batch": ("runs", "runs in the batch (scipy: runs integrated one at a time)"),
    "seconds": ("s", "best wall-clock time of a call"),
    "compile_s": ("s", "first call's time less the best call's: compilation"),
    "msteps_per_s": (RATE, "million rollout-steps (runs x RK4 steps) per second"),
    "failed_runs": ("runs", "runs whose status is not ok (pfjax's rows; null where not counted)"),
    "config_sha256": ("", "SHA-256 of the benchmark's config"),
    "pfjax_version": ("", "pfjax version"),
}


def summary_units(summary: dict, prefix: str = "") -> dict:
    """The unit of each number of a benchmark ``summary`` (keys under ``prefix``): rates, ratios,
    seconds, memory, the agreement's IAE differences, the gradient (:data:`GRADIENT`), the goals
    (each in its own ``unit``) and the vehicle models' costs."""
    ratios = [
        *(f"ratio_vs_{impl}_{p}" for impl in ("numba", "numpy") for p in ("f32", "f64")),
        "ratio_vs_scipy_f64",
        "fraction_of_minimal_f32",
        "fraction_of_minimal_f64",
        "grad_over_forward",
        "grad_over_forward_reverse",
        *(f"model_cost_ratio_{m}_{p}" for m in ("st", "std") for p in ("f32", "f64")),
    ]
    rates = [
        *(f"{impl}msteps_per_s_{p}" for impl in ("", "numba_", "numpy_", "minimal_") for p in ("f32", "f64")),
        "scipy_msteps_per_s_f64",
    ]
    table: dict = {
        **dict.fromkeys(rates, RATE),
        **dict.fromkeys(ratios, "1"),
        "compile_s_f32": "s",
        "compile_s_f64": "s",
        "peak_rss_mib": "MiB",
        "batch": "runs (the largest batch: the headline rates')",
        "failed_runs": "runs (not status ok, over every row)",
        "seed": "1 (the random seed)",
        "fraction_of_minimal_by_batch.*": {"f32": "1", "f64": "1", "batch": "runs"},
        "gradient.*": {
            **dict.fromkeys(("forward_s", "grad_s", "grad_compile_s", "reverse_s", "reverse_compile_s"), "s"),
            "modes_max_rel_diff": "1",
            "grad_block": "runs",
            "grad_blocks": "1",
            "reverse_segment": "samples",
            "grad": GRADIENT,
            "grad_reverse": GRADIENT,
        },
        "goals.*": {"target": "the goal's unit (its 'unit')", "value": "the goal's unit (its 'unit')", "batch": "runs"},
        "models.*": {"runs": "runs", "steps": "steps per run"},
    }
    for name in summary.get("agreement") or {}:
        table[f"agreement.{name}.*"] = {"max_abs_diff": "m s", "tolerance": "m s"}
    for dtype in ("float32", "float64"):
        row = (summary.get("models") or {}).get(dtype) or {}
        table[f"models.{dtype}.*"] = {k: "1" for k in row if k.startswith("ratio_")}
        for model in (k for k in row if not k.startswith("ratio_")):
            table[f"models.{dtype}.{model}.*"] = {"wall_s": "s", "ns_per_rollout_step": "ns"}
    return {prefix + k: v for k, v in table.items()}


#: The unit of the gradient of the batch-mean IAE (m s) with respect to K, per entry of K.
GRADIENT = "m s per unit of K's entry: " + ", ".join(f"m s / ({u})" for u in K_UNITS)

#: The units of :func:`pfjax.bench.run.machine`'s numbers, under ``machine.`` (every output that
#: records the machine carries them).
LOAD = "runnable processes (1-minute load average)"
MACHINE_UNITS = {
    "machine.block_bytes.*": {"float32": "B", "float64": "B"},
    "machine.compiler_options.*": {"xla_cpu_prefer_vector_width": "bits"},
    "machine.cpus": "CPUs",
    "machine.gpu_block_bytes": "B",
    "machine.load_average_1m": LOAD,
    "machine.load_average_1m_start": LOAD,
}

#: The units of :class:`pfjax.bench.run.BenchConfig`'s numbers, by field.
CONFIG_UNITS = {
    **dict.fromkeys(("sizes", "ref_size", "ref_numpy", "scipy_runs", "grad_size", "model_runs"), "runs"),
    "horizon": "s",
    "model_horizon": "s",
    "repeats": "timed calls after the first",
    "grad_rounds": "rounds",
    "seed": "1 (the random seed)",
}


def result_units(result: dict) -> dict:
    """The unit of each number of ``bench.json`` (:func:`summary_units` under ``summary.``, the rows
    by :data:`COLUMNS`, the config by :data:`CONFIG_UNITS`, the problem, the step count, the seed
    and the machine by :data:`MACHINE_UNITS`)."""
    return {
        **summary_units(result["summary"], "summary."),
        "rows.*": {name: unit for name, (unit, _) in COLUMNS.items() if unit},
        "config.*": CONFIG_UNITS,
        "problem.*": {"dt": "s", "newton_iters": "Newton steps per closest-point search"},
        "n_steps": "RK4 steps per run",
        "seed": CONFIG_UNITS["seed"],
        **MACHINE_UNITS,
    }


def provenance(result: dict) -> dict:
    """What a benchmark's outputs record of where they come from: ``config_sha256`` (of
    ``result["config"]``), ``seed`` and ``pfjax_version``."""
    return dict(
        config_sha256=config_hash(result["config"]), seed=result["config"]["seed"], pfjax_version=pfjax.__version__
    )


_STYLE = {
    ("pfjax", "float32"): ("C0", "-", "o"),
    ("pfjax", "float64"): ("C0", "--", "s"),
    ("numba", "float32"): ("C1", "-", "^"),
    ("numba", "float64"): ("C1", "--", "v"),
    ("numpy", "float32"): ("C2", "-", "D"),
    ("numpy", "float64"): ("C2", "--", "d"),
    ("scipy", "float64"): ("C3", "--", "x"),
    ("jax_minimal", "float32"): ("C4", "-", "*"),
    ("jax_minimal", "float64"): ("C4", "--", "P"),
}


def throughput_figure(rows, machine: dict):
    """Million rollout-steps per second against batch size, log-log, one line per implementation and dtype."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.0, 4.4), constrained_layout=True)
    for (impl, dtype), (color, ls, marker) in _STYLE.items():
        pts = sorted((r["batch"], r["msteps_per_s"]) for r in rows if r["impl"] == impl and r["dtype"] == dtype)
        if not pts:
            continue
        b, m = zip(*pts)
        if impl == "scipy":  # one run at a time: a rate independent of the batch, drawn as a level
            ax.axhline(m[0], ls=ls, color=color, lw=1.2, label=f"scipy solve_ivp {dtype} (one run at a time)")
        elif len(b) == 1:  # a reference measured at one batch size: a marker with its value
            ax.plot(b, m, ls="none", marker=marker, ms=8, color=color, label=f"{impl} {dtype}")
            ax.annotate(
                f"{m[0]:.3g}",
                (b[0], m[0]),
                textcoords="offset points",
                fontsize=7,
                color=color,
                xytext=(8 if impl in ("numpy", "jax_minimal") else -30, 3 if dtype == "float32" else -9),
            )
        else:
            ax.plot(b, m, ls=ls, marker=marker, color=color, label=f"{impl} {dtype}")
            ax.annotate(
                f"{m[-1]:.3g}", (b[-1], m[-1]), textcoords="offset points", xytext=(6, 4), fontsize=7, color=color
            )
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.margins(x=0.12)
    ax.set_xlabel("batch size (runs)")
    ax.set_ylabel("million rollout-steps / s")
    ax.set_title(
        f"slip model, sine path, RK4 5 ms, metrics on — {machine['cpus']} CPUs, "
        f"{len(machine['devices'])} JAX device(s)",
        fontsize=9,
    )
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8, ncol=2)
    return fig


def _models(b: dict) -> list[str]:
    """The vehicle-model comparison (:mod:`pfjax.bench.models`): ns per rollout-step and the ratio to
    the kinematic model, per precision."""
    if not b:
        return []
    names = [m for m in b["float32"] if not m.startswith("ratio_")]
    rows = [
        [
            m,
            *(f"{b[d][m]['ns_per_rollout_step']:.1f}" for d in ("float32", "float64")),
            *("" if m == "kinematic" else f"{b[d][f'ratio_{m}_over_kinematic']:.2f}x" for d in ("float32", "float64")),
        ]
        for m in names
    ]
    std = "; STD: vehicle 2 at 10 m/s, 2 ms step" if "std" in names else ""  # the models that ran
    return [
        f"Vehicle models in the same loop ({b['runs']} runs of {b['steps']} steps, {b['controller']} on the "
        f"{b['path']} path, metrics on{std}):",
        "",
        table(
            ["model", "ns/rollout-step f32", "ns/rollout-step f64", "over kinematic f32", "over kinematic f64"], rows
        ),
        "",
    ]


def _goals(goals: list[dict]) -> list[str]:
    """The goals table (:mod:`pfjax.bench.goals`): target, measured value, met."""
    from pfjax.bench.problem import HORIZON

    if not goals:
        return []

    def number(x: float, name: str) -> str:
        if name.startswith("fraction_"):
            return f"{100 * x:.1f} %"
        return f"{x:.3g}" + ("x" if name.startswith(("numba_", "gradient_")) else "")

    def unmeasured(g: dict) -> str:
        why = g.get("not_measured") or ""
        return f"not measured ({why})" if why.startswith("reference ") else "not measured"

    rows = []
    for g in goals:
        rows.append(
            [
                f"{g['text']} (B = {g['batch']:,})",
                ("≥ " if g["at_least"] else "≤ ") + number(g["target"], g["goal"]),
                unmeasured(g) if g["value"] is None else number(g["value"], g["goal"]),
                "–" if g["met"] is None else ("yes" if g["met"] else "no"),
            ]
        )
    met = sum(g["met"] is True for g in goals)
    measured = sum(g["met"] is not None for g in goals)
    return [
        "Goals on this machine (docs/performance.md, Scale targets): "
        + (f"{met} of the {measured} measured met" if measured else "none measured")
        + (
            f"; {len(goals) - measured} not measured in this run (a goal is measured at its batch size "
            f"with the benchmark's {HORIZON:g} s horizon, against a reference that agrees with pfjax)"
            if measured < len(goals)
            else ""
        )
        + ".",
        "",
        table(["goal", "target", "measured", "met"], rows),
        "",
    ]


def _finite(x) -> bool:
    return x is not None and math.isfinite(x)


def _percent(x) -> str:
    """A fraction in percent, ``–`` where it is not reported (null: its reference disagrees)."""
    return f"{100 * x:.0f} %" if _finite(x) else "–"


def _numba_clause(s: dict) -> str:
    """The headline's ratios over Numba (``–`` in a precision where Numba disagrees with pfjax),
    or that Numba did not run (its ratios null)."""
    bad = [name for name in disagreeing(s) if name.startswith("numba_")]
    r32, r64 = s.get("ratio_vs_numba_f32"), s.get("ratio_vs_numba_f64")
    if bad:
        ratios = " / ".join(f"{r:.3g}x" if _finite(r) else "–" for r in (r32, r64))
        return f"; {ratios} Numba ({', '.join(bad)} disagrees with pfjax: not reported)."
    if not (_finite(r32) and _finite(r64)):
        return "; Numba not run."
    return f"; {r32:.3g}x / {r64:.3g}x Numba."


def _disagreement(s: dict) -> list[str]:
    """The paragraph naming the references that disagree with pfjax, and by how much (none where
    every reference agrees)."""
    text = disagreement(s)
    if not text:
        return []
    return [
        f"**Disagreement**: these references disagree with pfjax on the per-run IAE: {text}. pfjax's "
        "fractions of them and ratios over them are not reported (null in bench.json), and the goals read "
        "against them are not measured.",
        "",
    ]


def _minimal_sentence(s: dict) -> str:
    """pfjax's throughput as a fraction of the minimal implementation's, at the largest batch and
    every other; ``–`` in a precision where the minimal implementation disagrees with pfjax."""
    what = (
        "a minimal JAX implementation of the same problem (`jax_minimal`: IAE only, the same elementary functions, "
        "devices, blocks and compiler options, the problem's own shortcuts (a projection written for y = sin x, "
        "the heading's sine and cosine reused across steps), no metrics, statuses or general interfaces), "
        "measured in the same process"
    )
    at = f"{_percent(s['fraction_of_minimal_f32'])} (float32) and {_percent(s['fraction_of_minimal_f64'])} (float64)"
    bad = [name for name in disagreeing(s) if name.startswith("jax_minimal_")]
    if bad:
        head = (
            f"pfjax's throughput as a fraction of that of {what}, not reported where it disagrees with pfjax "
            f"({', '.join(bad)}): at B = {s['batch']} runs {at}"
        )
    else:
        head = f"pfjax at B = {s['batch']} runs at {at} of the throughput of {what}"
    return head + "".join(
        f"; at B = {f['batch']}: {_percent(f['f32'])} / {_percent(f['f64'])}"
        for f in s.get("fraction_of_minimal_by_batch", [])
        if f["batch"] != s["batch"]
    )


def _kinds(m: dict) -> str:
    """`` (NVIDIA H200)``: the devices' kinds, where recorded."""
    return f" ({', '.join(m['device_kinds'])})" if m.get("device_kinds") else ""


def _gpu_blocks(m: dict) -> str:
    """``; GPU blocks of 1000000 bytes per array``, where a GPU ran in blocks."""
    return f"; GPU blocks of {m['gpu_block_bytes']} bytes per array" if m.get("gpu_block_bytes") else ""


def markdown(result: dict) -> str:
    s, m = result["summary"], result["machine"]
    lines = [
        "# pfjax benchmark",
        "",
        f"Machine: {m['processor']}, {m.get('cpu_vendor') or 'vendor unknown'} {m.get('cpu_model') or 'CPU model unknown'}"
        f"{' (family ' + m['cpu_family'] + ', model ' + m['cpu_model_number'] + ')' if m.get('cpu_family') else ''}, {m['cpus']} CPUs, JAX {m['jax']} with {len(m['devices'])} device(s){_kinds(m)}; "
        f"1-min load average {m['load_average_1m_start']:.1f} at the start, {m['load_average_1m']:.1f} at the end. "
        f"AVX-512: {'yes' if m.get('avx512') else 'no'} (flags: {', '.join(m.get('cpu_flags') or []) or 'unknown'}); "
        f"simulator compiler options: {m.get('compiler_options') or 'XLA defaults'}"
        f"{_gpu_blocks(m)}.",
        "",
        *_disagreement(s),
        _minimal_sentence(s) + _numba_clause(s),
        "",
        table(
            ["implementation", "dtype", "batch", "M rollout-steps/s", "compile s"],
            [
                [r["impl"], r["dtype"], r["batch"], f"{r['msteps_per_s']:.3g}", f"{r['compile_s']:.2f}"]
                for r in result["rows"]
            ],
        ),
        "",
        table(
            ["agreement (max abs IAE difference vs pfjax, m s)", "value", "tolerance", "ok"],
            [
                [
                    k,
                    f"{a['max_abs_diff']:.2e}" if _finite(a["max_abs_diff"]) else "not finite",
                    f"{a['tolerance']:.0e}",
                    a["ok"],
                ]
                for k, a in s["agreement"].items()
            ],
        ),
    ]
    g = s["gradient"]
    lines += [
        "",
        f"Value and gradient of the batch-mean IAE w.r.t. K over the forward pass: {s['grad_over_forward']:.2f}x "
        f"({s['grad_mode']} mode, as the tuner takes it"
        + (
            f", in {g['grad_blocks']} blocks of {g['grad_block']} runs per device"
            if (g.get("grad_blocks") or 1) > 1
            else ""
        )
        + f"); reverse mode {s['grad_over_forward_reverse']:.2f}x ("
        + (
            f"in checkpointed segments of {g['reverse_segment']} steps; "
            if g.get("reverse_segment")
            else "every step checkpointed; "
        )
        + f"the two gradients differ by {g['modes_max_rel_diff']:.1e} relative). "
        f"Peak RSS {s['peak_rss_mib']:.0f} MiB.",
        "",
        *_models(s.get("models") or {}),
    ]
    lines += _goals(s.get("goals") or [])
    for note in s.get("notes", []):  # a reference that was skipped (Numba not installed)
        lines += [f"Note: {note} (the Numba reference was skipped; its rates and ratios are null).", ""]
    return "\n".join(lines)


def output_dir(out, cfg, *, overwrite: bool = False) -> OutputDir:
    """The (unopened) :class:`~pfjax.outputs.OutputDir` of a benchmark of ``cfg`` (a
    :class:`~pfjax.bench.run.BenchConfig`): open it before running the benchmark, so a bad
    ``--out`` is refused before minutes of work."""
    return OutputDir(
        out, command="bench", config_sha256=config_hash(asdict(cfg)), overwrite=overwrite, extra={"seed": cfg.seed}
    )


def write(result: dict, output: OutputDir):
    """Write ``result`` into ``output`` (opened) and move it into place; returns the directory."""
    import pandas as pd

    from pfjax.report.figures import save

    result = dict(result, **provenance(result))
    tmp = output.staging
    (tmp / "figures").mkdir()
    (tmp / "bench.json").write_text(dumps(result) + "\n")
    df = pd.DataFrame(result["rows"])
    df.attrs = {}
    # a whole count, null in the rows that do not count failures (not a float with NaN)
    df["failed_runs"] = df["failed_runs"].astype("Int64")
    table = df.assign(config_sha256=result["config_sha256"], pfjax_version=pfjax.__version__)
    write_parquet(
        table,
        tmp / "bench.parquet",
        parquet_metadata(result["config"], result["seed"], config_sha256=result["config_sha256"]),
        units=COLUMNS,
    )
    fig = throughput_figure(result["rows"], result["machine"])
    save(fig, tmp / "figures", "throughput", dpi=150, tight=False)
    (tmp / "report.md").write_text(markdown(result))
    return output.commit()
