"""The kinematic-vs-dynamic study's report (markdown) from its summary
(``studies/kinematic_vs_dynamic_summary.py``)."""

from __future__ import annotations


def _pct(r: dict) -> str:
    return f"{100 * r['rate']:.1f} % [{100 * r['ci95'][0]:.1f}, {100 * r['ci95'][1]:.1f}]"


def _q(d: dict) -> str:
    return f"{d['q50']:.2f} / {d['q95']:.2f} / {d['max']:.2f}"


def slip_tables(s: dict) -> list[str]:
    head = "| max abs beta_r q50 / q95 / max | max abs beta_f q50 / q95 / max | mean abs beta_f q50 / q95 |"
    row = lambda b: (
        f"| {_q(b['max_abs_beta_r_deg'])} | {_q(b['max_abs_beta_f_deg'])} | "
        f"{b['mean_abs_beta_f_deg']['q50']:.2f} / {b['mean_abs_beta_f_deg']['q95']:.2f} |"
    )
    lines = ["| mu | runs " + head, "|---|---|---|---|---|"]
    lines += [f"| {b['mu'][0]:.2f}-{b['mu'][1]:.2f} | {b['n']} " + row(b) for b in s["by_mu"]]
    lines += ["", "| speed m/s | runs " + head, "|---|---|---|---|---|"]
    lines += [f"| {b['speed'][0]:.2f}-{b['speed'][1]:.2f} | {b['n']} " + row(b) for b in s["by_speed"]]
    lines += ["", "| path (max curvature at robot scale, 1/m) | runs " + head, "|---|---|---|---|---|"]
    lines += [f"| {b['path']} ({b['max_curvature_robot']}) | {b['n']} " + row(b) for b in s["by_path"]]
    fr = s["fraction_max_beyond_declared"]
    lines += [
        "",
        f"Runs whose largest slip exceeds the declared +-{s['declared_range_deg']:g} deg: rear "
        f"{100 * fr['max_abs_beta_r_deg']:.1f} %, front {100 * fr['max_abs_beta_f_deg']:.1f} %.",
    ]
    return lines


def comparison(c: dict, length_unit: float, unit: str) -> list[str]:
    """The verdict table and the per-arm tables of one :func:`compare` result."""
    dyn, ref = c["dynamic_arm"], c["reference_arm"]
    ctrl = c["controllers"]
    lines = [
        f"| controller | {dyn} | {ref} | paired difference | verdict kinematic -> dynamic | survives | equivalent kinematic arm |",
        "|---|---|---|---|---|---|---|",
    ]
    for name, x in ctrl.items():
        p = x["paired_dynamic_minus_kinematic"]
        lines.append(
            f"| {name} | {_pct(x['success'][dyn])} | {_pct(x['success'][ref])} | "
            f"{100 * p['diff']:+.1f} pp [{100 * p['ci95'][0]:+.1f}, {100 * p['ci95'][1]:+.1f}] | "
            f"{x['verdict_kinematic']} -> {x['verdict_dynamic']} | {'yes' if x['verdict_survives'] else 'no'} | "
            f"{x['equivalent_kinematic_arm']} (gap {100 * x['equivalent_gap']:.1f} pp) |"
        )
    first = next(iter(ctrl.values()))
    paths_ = list(first["success_by_path"][dyn])
    lines += ["", f"Success by path ({dyn} / {ref}):", "", "| controller | " + " | ".join(paths_) + " |"]
    lines.append("|---|" + "---|" * len(paths_))
    for name, x in ctrl.items():
        bp = x["success_by_path"]
        cells = [f"{100 * bp[dyn][p]['rate']:.1f} / {100 * bp[ref][p]['rate']:.1f} %" for p in paths_]
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    mus = first["success_by_mu_dynamic"]
    lines += ["", f"Success in {dyn} by friction:", ""]
    lines.append("| controller | " + " | ".join(f"mu {b['mu'][0]:.2f}-{b['mu'][1]:.2f}" for b in mus) + " |")
    lines.append("|---|" + "---|" * len(mus))
    for name, x in ctrl.items():
        lines.append(f"| {name} | " + " | ".join(_pct(b) for b in x["success_by_mu_dynamic"]) + " |")
    arms_ = [a for a in first["success"] if a != dyn]
    lines += ["", "Success in the other arms:", "", "| controller | " + " | ".join(arms_) + " |"]
    lines.append("|---|" + "---|" * len(arms_))
    for name, x in ctrl.items():
        lines.append(f"| {name} | " + " | ".join(_pct(x["success"][a]) for a in arms_) + " |")
    all_arms = [dyn, *arms_]
    lines += ["", f"Late max |d| ({unit}), 95th percentile / worst run:", ""]
    lines += ["| controller | " + " | ".join(all_arms) + " |", "|---|" + "---|" * len(all_arms)]
    for name, x in ctrl.items():
        cells = [
            f"{x['late_max_abs_d_q95'][a] / length_unit:.1f} / {x['worst_late_max_abs_d'][a] / length_unit:.1f}"
            for a in all_arms
        ]
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return lines


def report(s: dict) -> str:
    cfg = s["config"]
    study = cfg["study"]
    lines = [
        f"# Kinematic vs dynamic ({cfg['name']})",
        "",
        f"{study['n_runs']} runs per controller and path on {', '.join(p['kind'] for p in study['paths'])}; "
        f"speed {study['vehicle']['speed']}; dynamic arm: CommonRoad ST, robot parameter set, mu uniform on "
        f"[{cfg['mu_low']:g}, {cfg['mu_high']:g}]; kinematic arms: constant slip uniform on +-A per axle, A in "
        f"{cfg['slip_ranges_deg']} deg. Machine: {s['machine']}; wall {s['wall_s']['total']:.0f} s.",
        "",
        "## Slip the dynamic model produces (deg), robot scale",
        "",
        *slip_tables(s["slip"]),
        "",
        "## Success rates (95 % Clopper-Pearson intervals) and verdicts, robot scale",
        "",
        f"Verdict: robust if the interval lies above {100 * s['robust_line']:.0f} %, fragile if below, "
        "undecided if it straddles; paired difference: dynamic - kinematic, same runs (95 % normal interval).",
        "",
        *comparison(s["robot"], 1e-3, "mm"),
    ]
    if "designs_comparison" in s:
        op = s["designs"]["operating_point"]
        lines += [
            "",
            f"## Designs on the kinematic and on the linearised dynamic model (v = {op['v']:g} m/s, "
            f"mu = {op['mu']:g}, tau_delta = {op['tau_delta_s']:g} s; polytopic: mu and speed ranges' corners)",
            "",
            "| design | K | criterion at the kinematic gain -> at the dynamic gain |",
            "|---|---|---|",
        ]
        for name, g in s["designs"]["gains"].items():
            crit = f"{g['criterion0']:.2f} -> {g['criterion']:.2f}" if "criterion" in g else ""
            lines.append(f"| {name} | {', '.join(f'{k:.3f}' for k in g['K'])} | {crit} |")
        lines += ["", *comparison(s["designs_comparison"], 1e-3, "mm")]
    if "car" in s:
        lines += [
            "",
            "## Passenger-car scale (CommonRoad vehicle 2, paths scaled by the wheelbase ratio)",
            "",
            *slip_tables(s["car_slip"]),
            "",
            *comparison(s["car"], 1e-2, "cm"),
        ]
    b = s["throughput"]
    lines += [
        "",
        f"## Throughput ({b['runs']} runs x {b['steps']} steps, {b['controller']} on {b['path']}, best of "
        f"{cfg['bench_repeats']})",
        "",
        "| precision | kinematic ns/rollout-step | ST ns/rollout-step | STD ns/rollout-step | ST / kinematic | STD / kinematic |",
        "|---|---|---|---|---|---|",
    ]
    for dtype in ("float32", "float64"):
        r = b[dtype]
        lines.append(
            f"| {dtype} | {r['kinematic']['ns_per_rollout_step']:.0f} | {r['st']['ns_per_rollout_step']:.0f} | "
            f"{r['std']['ns_per_rollout_step']:.0f} | {r['ratio_st_over_kinematic']:.2f} | "
            f"{r['ratio_std_over_kinematic']:.2f} |"
        )
    return "\n".join(lines) + "\n"
