"""The kinematic-vs-dynamic study's report: :func:`report` builds a
:class:`pfjax.report.document.Document` from the summary (:mod:`pfjax.dynamic_study.summary`), written
as ``report.md`` and ``report.html`` by :func:`pfjax.report.document.write`. Nothing is computed
here: every number is the summary's."""

from __future__ import annotations

from pfjax.report.document import Block, Document, Heading, Paragraph, Table


def percent(r: dict) -> str:
    return f"{100 * r['rate']:.1f} % [{100 * r['ci95'][0]:.1f}, {100 * r['ci95'][1]:.1f}]"


def _num(x, digits: int = 2, scale: float = 1.0) -> str:
    """``x / scale`` to ``digits`` decimals; a missing number (None, NaN) as a dash."""
    return "-" if x is None or x != x else f"{x / scale:.{digits}f}"


def _q(d: dict) -> str:
    return f"{_num(d['q50'])} / {_num(d['q95'])} / {_num(d['max'])}"


_SLIP_HEAD = [
    "runs ok / failed",
    "max abs beta_r q50 / q95 / max",
    "max abs beta_f q50 / q95 / max",
    "mean abs beta_f q50 / q95",
]


def _slip_row(label: str, b: dict) -> list[str]:
    mean_f = b["mean_abs_beta_f_deg"]
    return [
        label,
        f"{b['n']} / {b['n_failed']}",
        _q(b["max_abs_beta_r_deg"]),
        _q(b["max_abs_beta_f_deg"]),
        f"{_num(mean_f['q50'])} / {_num(mean_f['q95'])}",
    ]


def slip_tables(s: dict) -> list[Block]:
    """The slip the dynamic arm produced (deg) by friction, speed and path, over its runs with status
    ok (the failed runs counted, not in the statistics)."""
    fr = s["fraction_max_beyond_declared"]
    return [
        Paragraph(
            f"Over the {s['n']} runs that ran the whole horizon (status ok); the {s['n_failed']} failed runs are "
            "left out (their slip describes them only up to the failure).",
            style="note",
        ),
        Table(["mu", *_SLIP_HEAD], [_slip_row(f"{b['mu'][0]:.2f}-{b['mu'][1]:.2f}", b) for b in s["by_mu"]]),
        Table(
            ["speed m/s", *_SLIP_HEAD],
            [_slip_row(f"{b['speed'][0]:.2f}-{b['speed'][1]:.2f}", b) for b in s["by_speed"]],
        ),
        Table(
            ["path (max curvature at robot scale, 1/m)", *_SLIP_HEAD],
            [_slip_row(f"{b['path']} ({_num(b['max_curvature_robot'], 3)})", b) for b in s["by_path"]],
        ),
        Paragraph(
            f"Runs (status ok) whose largest slip exceeds the declared +-{s['declared_range_deg']:g} deg: rear "
            f"{_num(fr['max_abs_beta_r_deg'], 1, 0.01)} %, front {_num(fr['max_abs_beta_f_deg'], 1, 0.01)} %."
        ),
    ]


def _verdicts(c: dict) -> Table:
    dyn, ref = c["dynamic_arm"], c["reference_arm"]
    rows = []
    for name, x in c["controllers"].items():
        p = x["paired_dynamic_minus_kinematic"]
        rows.append(
            [
                name,
                percent(x["success"][dyn]),
                percent(x["success"][ref]),
                f"{100 * p['diff']:+.1f} pp [{100 * p['ci95'][0]:+.1f}, {100 * p['ci95'][1]:+.1f}]",
                f"{x['verdict_kinematic']} -> {x['verdict_dynamic']}",
                x["verdict_survives"],
                f"{x['equivalent_kinematic_arm']} (gap {100 * x['equivalent_gap']:.1f} pp)"
                if x["equivalent_kinematic_arm"] is not None
                else f"none (closest {x['closest_kinematic_arm']}, gap {100 * x['equivalent_gap']:.1f} pp)",
            ]
        )
    head = ["controller", dyn, ref, "paired difference", "verdict kinematic -> dynamic", "survives"]
    return Table([*head, "equivalent kinematic arm"], rows)


def comparison(c: dict, length_unit: float, unit: str) -> list[Block]:
    """The verdict table and the per-arm tables of one :func:`pfjax.dynamic_study.summary.compare` result."""
    dyn, ref = c["dynamic_arm"], c["reference_arm"]
    ctrl = c["controllers"]
    first = next(iter(ctrl.values()))
    paths_ = list(first["success_by_path"][dyn])
    mus = first["success_by_mu_dynamic"]
    arms_ = [a for a in first["success"] if a != dyn]
    all_arms = [dyn, *arms_]
    by_path = [
        [
            name,
            *(
                f"{100 * x['success_by_path'][dyn][p]['rate']:.1f} / {100 * x['success_by_path'][ref][p]['rate']:.1f} %"
                for p in paths_
            ),
        ]
        for name, x in ctrl.items()
    ]
    late = [
        [
            name,
            *(
                f"{_num(x['late_max_abs_d_q95'][a], 1, length_unit)} / {_num(x['worst_late_max_abs_d'][a], 1, length_unit)}"
                f" ({x['n_ok'][a]})"
                for a in all_arms
            ),
        ]
        for name, x in ctrl.items()
    ]
    return [
        _verdicts(c),
        Table(["controller", *paths_], by_path, caption=f"Success by path ({dyn} / {ref})"),
        Table(
            ["controller", *(f"mu {b['mu'][0]:.2f}-{b['mu'][1]:.2f}" for b in mus)],
            [[name, *(percent(b) for b in x["success_by_mu_dynamic"])] for name, x in ctrl.items()],
            caption=f"Success in {dyn} by friction",
        ),
        Table(
            ["controller", *arms_],
            [[name, *(percent(x["success"][a]) for a in arms_)] for name, x in ctrl.items()],
            caption="Success in the other arms",
        ),
        Table(
            ["controller", *all_arms],
            late,
            caption=f"Late max |d| ({unit}) over the runs with status ok: 95th percentile / worst run (their number)",
        ),
    ]


def design_tables(d: dict) -> list[Block]:
    """The designs' heading and gains table of a designs record (:func:`pfjax.dynamic_study.designs.designs`)."""
    op = d["operating_point"]
    rows = [
        [
            name,
            ", ".join(f"{k:.3f}" for k in g["K"]) if "K" in g else "none",
            f"no design: {g['failed']}"
            if "failed" in g
            else f"{g['criterion0']:.2f} -> {g['criterion']:.2f}"
            if "criterion" in g
            else "",
        ]
        for name, g in d["gains"].items()
    ]
    return [
        Heading(
            f"Designs on the kinematic and on the linearised dynamic model (v = {op['v']:g} m/s, mu = {op['mu']:g}, "
            f"tau_delta = {op['tau_delta_s']:g} s; polytopic: mu and speed ranges' corners)"
        ),
        Table(["design", "K", "criterion at the kinematic gain -> at the dynamic gain"], rows),
    ]


def _designs(s: dict) -> list[Block]:
    return [*design_tables(s["designs"]), *comparison(s["designs_comparison"], 1e-3, "mm")]


def _throughput(s: dict) -> list[Block]:
    b = s["throughput"]
    rows = []
    for dtype in ("float32", "float64"):
        r = b[dtype]
        rows.append(
            [
                dtype,
                f"{r['kinematic']['ns_per_rollout_step']:.0f}",
                f"{r['st']['ns_per_rollout_step']:.0f}",
                f"{r['std']['ns_per_rollout_step']:.0f}",
                f"{r['ratio_st_over_kinematic']:.2f}",
                f"{r['ratio_std_over_kinematic']:.2f}",
            ]
        )
    head = ["precision", "kinematic ns/rollout-step", "ST ns/rollout-step", "STD ns/rollout-step"]
    return [
        Heading(
            f"Throughput ({b['runs']} runs x {b['steps']} steps, {b['controller']} on {b['path']}, best of "
            f"{s['config']['bench_repeats']})"
        ),
        Table([*head, "ST / kinematic", "STD / kinematic"], rows),
    ]


def _wall(s: dict) -> Table:
    w = s["wall_s"]
    rows = [[arm, f"{t:.1f}"] for arm, t in w["arms"].items()]
    rows += [[k, f"{w[k]:.1f}"] for k in ("designs", "throughput") if k in w]
    return Table(["part", "wall s"], [*rows, ["total", f"{w['total']:.1f}"]], caption="Wall time")


def report(s: dict) -> Document:
    """The report of a study summary ``s`` (:func:`pfjax.dynamic_study.runs.run` writes it)."""
    cfg = s["config"]
    study = cfg["study"]
    blocks: list[Block] = [
        Paragraph(
            f"{study['n_runs']} runs per controller and path on {', '.join(p['kind'] for p in study['paths'])}; "
            f"speed {study['vehicle']['speed']}; dynamic arm: CommonRoad ST, robot parameter set, mu uniform on "
            f"[{cfg['mu_low']:g}, {cfg['mu_high']:g}]; kinematic arms: constant slip uniform on +-A per axle, A in "
            f"{cfg['slip_ranges_deg']} deg. Machine: {s['machine']}; wall {s['wall_s']['total']:.0f} s at a load "
            f"average of {', '.join(f'{x:.2f}' for x in s['load_average'])} (1, 5, 15 min)."
        ),
        Heading("Slip the dynamic model produces (deg), robot scale"),
        *slip_tables(s["slip"]),
        Heading("Success rates (95 % Clopper-Pearson intervals) and verdicts, robot scale"),
        Paragraph(
            f"Verdict: robust if the interval lies above {100 * s['robust_line']:.0f} %, fragile if below, "
            "undecided if it straddles; survives: undecided where either verdict is; paired difference: dynamic - "
            "kinematic, same runs (95 % Tango score interval).",
            style="note",
        ),
        *comparison(s["robot"], 1e-3, "mm"),
    ]
    if "designs_comparison" in s:
        blocks += _designs(s)
    if "car" in s:
        blocks += [
            Heading("Passenger-car scale (CommonRoad vehicle 2, paths scaled by the wheelbase ratio)"),
            *slip_tables(s["car_slip"]),
            *comparison(s["car"], 1e-2, "cm"),
        ]
    blocks += [*(_throughput(s) if s["throughput"] else []), _wall(s)]
    subtitle = f"pfjax {s['pfjax_version']} · config {s['config_sha256'][:12]}"
    return Document(f"Kinematic vs dynamic ({cfg['name']})", subtitle, blocks)


__all__ = ["comparison", "design_tables", "percent", "report", "slip_tables"]
