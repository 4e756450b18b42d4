"""docs/rare-events.md's "## Measured" section against the run it quotes,
results/rare_events/verification.json (studies/rare_events.py): every cell of its result tables,
formatted as the page formats it, and the numbers of its sentences and of its targets table
(:func:`claims`), each with the condition that keeps its wording true. The file is read, not
recomputed: no simulation."""

from __future__ import annotations

import json
import math
import re
import statistics
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "rare-events.md"
RESULT = ROOT / "results" / "rare_events" / "verification.json"
DIGITS = "0123456789"
WORDS = ("zero", "one", "two", "three", "four", "five", "six", "seven", "eight", "nine", "ten")


# --- the page's number formats ------------------------------------------------------------------


def g3(x: float) -> str:
    """Three significant digits, as the tables write them (``9.8e-05``, ``0.000148``)."""
    return f"{x:.3g}"


def unpad(s: str) -> str:
    """``6.5e-06`` as the sentences write it, ``6.5e-6``."""
    if "e" not in s:
        return s
    m, e = s.split("e")
    return f"{m}e{int(e)}"


def sci(x: float, decimals: int) -> str:
    """Scientific notation with ``decimals`` digits after the point (``sci(6.38e-6, 1) == "6.4e-6"``)."""
    return unpad(f"{x:.{decimals}e}")


def short(x: float) -> str:
    """Three significant digits, the exponent unpadded (``5.4e-6``)."""
    return unpad(g3(x))


def pct(r: float | None, decimals: int = 1) -> str:
    """A relative error or share in percent; ``—`` where it is unknown (null) or infinite."""
    return "—" if r is None or not math.isfinite(r) else f"{100 * r:.{decimals}f} %"


def count(n: float) -> str:
    return f"{round(n):,}"


def wall(s: float) -> str:
    return f"{s:.1f}"


def interval(ci: list[float], fmt=g3, sep: str = "–") -> str:
    return f"{fmt(ci[0])}{sep}{fmt(ci[1])}"


def joined(xs, fmt) -> str:
    return ", ".join(fmt(x) for x in xs)


def span(lo: float, hi: float, fmt, unit: str = "") -> str:
    """``lo–hi`` as ``fmt`` writes them, then ``unit``; one value where they read alike."""
    a, b = fmt(lo), fmt(hi)
    return (a if a == b else f"{a}–{b}") + unit


def integer(x: float) -> str:
    return f"{x:.0f}"


def pct_int(r: float) -> str:
    return f"{100 * r:.0f} %"


def thousands(n: float) -> str:
    return f"{round(n, -3):,.0f}"


def e7(n: float) -> str:
    return f"{n / 1e7:.0f}·10⁷"


def minutes(s: float) -> str:
    m, s = divmod(round(s), 60)
    return f"{m} min {s} s"


# --- the tables ---------------------------------------------------------------------------------


def estimate_cells(r: dict) -> list[str]:
    """An estimate's p, 95 % interval, relative error and rollouts."""
    return [g3(r["p_fail"]), interval(r["ci95"]), pct(r["rel_error"]), count(r["n_rollouts"])]


def spread(xs: list[float]) -> float:
    """The coefficient of variation of ``xs`` (sample standard deviation over the mean)."""
    return statistics.stdev(xs) / statistics.fmean(xs)


def expected_tables(res: dict) -> list[list[list[str]]]:
    """The result tables of the Measured section, in the page's order: header row, then rows."""
    known = [
        ["target", "slip std [deg]", "reference p", "method", "estimate", "95 % interval", "rel. error"]
        + ["rollouts", "holds reference", "wall [s]"]
    ]
    for label, e in res["known"].items():
        for m in ("is", "subset", "mc"):
            if m in e:
                r = e[m]
                known.append(
                    [label, f"{e['std_deg']:g}", g3(e["reference"]), m, *estimate_cells(r)]
                    + ["yes" if r["holds_reference"] else "no", wall(r["wall_s"])]
                )
    starts = [["starts", "rollouts", "estimates", "rel. error", "hold reference", "wall [s]"]]
    for how in res["config"]["sizes"]["starts"]:
        s = res["starts"][how]
        holds = f"{sum(s['holds_reference'])}/{len(s['holds_reference'])}"
        starts.append(
            [how, joined(s["n_rollouts"], count), joined(s["p_fail"], g3), joined(s["rel_error"], pct)]
            + [holds, joined(s["wall_s"], wall)]
        )
    coverage = [
        ["method", "repeats", "intervals holding p", "mean estimate / p", "mean rel. error (observed spread)"]
        + ["mean rollouts"]
    ]
    for m, c in res["coverage"].items():
        ratios = [e / c["reference"] for e in c["estimates"]]
        se = statistics.stdev(ratios) / math.sqrt(len(ratios))
        coverage.append(
            [m, str(c["repeats"]), f"{sum(c['holds_reference'])} ({pct(c['coverage'], 0)})"]
            + [f"{c['mean_estimate_over_reference']:.3f} ± {se:.3f}"]
            + [f"{pct(c['mean_rel_error'])} (observed {pct(spread(c['estimates']))})", count(c["mean_rollouts"])]
        )
    paths = [s["path"] for s in next(iter(res["study"].values()))["path"]["is"]["strata"]]
    study_header = ["controller", "method", "p_fail", "95 % interval", "rel. error", "rollouts", "wall [s]"]
    study_header.append(f"per path ({' / '.join(paths)})")
    study = {}
    for failure in ("path", "band"):
        study[failure] = [study_header]
        for name, entry in res["study"].items():
            for m, r in entry[failure].items():
                assert [s["path"] for s in r["strata"]] == paths
                per_path = " / ".join(g3(s["p_fail"]) for s in r["strata"])
                study[failure].append([name, m, *estimate_cells(r), wall(r["wall_s"]), per_path])
    sine = [["method", "p_fail", "95 % interval", "rel. error", "rollouts", "wall [s]"]]
    sine += [[m, *estimate_cells(r), wall(r["wall_s"])] for m, r in res["sine_check"].items()]
    return [known, starts, coverage, study["path"], study["band"], sine]


# --- the sentences ------------------------------------------------------------------------------


def names(items: list[str]) -> str:
    """Controller names as the page lists them: ```a``, ``b`` and ``c```."""
    quoted = [f"`{n}`" for n in items]
    return ", ".join(quoted[:-1]) + " and " + quoted[-1] if len(quoted) > 1 else "".join(quoted)


def claims(res: dict) -> list[tuple[str, bool]]:
    """``(text, holds)``: each sentence fragment of the section that quotes the run (whitespace
    collapsed), and whether the wording around it is true of the file."""
    known, starts, cov, study, sine = res["known"], res["starts"], res["coverage"], res["study"], res["sine_check"]
    sizes = res["config"]["sizes"]
    out: list[tuple[str, bool]] = []

    # the run and the machine
    out.append((f"({minutes(res['wall_s'])} in all", True))
    out.append((f"`{res['machine']}`", True))
    cpu = res["cpu_settings"]
    out.append(
        (f"with AVX-512 ({cpu['vector_width']}-bit vectors", cpu["vector_width"] == 512 and cpu["source"] == "rules")
    )

    # the known case
    ests = [e[m] for e in known.values() for m in ("is", "subset", "mc") if m in e]
    out.append(("Every interval holds its reference.", all(r["holds_reference"] for r in ests)))
    small = [known["1e-6"]["is"], known["1e-8"]["is"]]
    out.append(
        (
            f"reaches 1e-6 and 1e-8 with a {span(*sorted(r['rel_error'] * 100 for r in small), integer, ' %')} relative error "
            f"from {count(small[0]['n_rollouts'])} rollouts",
            small[0]["n_rollouts"] == small[1]["n_rollouts"],
        )
    )
    out.append(
        (f"subset simulation needs {count(known['1e-6']['subset']['n_rollouts'])} and "
         f"{count(known['1e-8']['subset']['n_rollouts'])} (", True)
    )  # fmt: skip

    # where the proposal starts
    f, e, n = (starts[k] for k in ("falsifier", "explore", "none"))
    save_e = [1 - a / b for a, b in zip(f["n_rollouts"], e["n_rollouts"])]
    save_n = [1 - a / b for a, b in zip(f["n_rollouts"], n["n_rollouts"])]
    out.append((f"`p = {sci(starts['reference'], 1)}`, seeds 0–{sizes['start_seeds'] - 1}", True))
    out.append(
        (
            f"save {span(100 * min(save_e), 100 * max(save_e), integer, ' %')} of the rollouts against `explore` and "
            f"{span(100 * min(save_n), 100 * max(save_n), integer, ' %')} against `N(0, I)`",
            True,
        )
    )
    out.append(
        (
            "in wall time they gain nothing on this 2-D case (the first estimate includes compiling",
            sum(f["wall_s"]) > max(sum(e["wall_s"]), sum(n["wall_s"])) and max(f["wall_s"]) == f["wall_s"][0],
        )
    )

    # coverage
    seed, reps = res["config"]["coverage_seed"], cov["is"]["repeats"]
    out.append((f"`p = {sci(cov['is']['reference'], 1)}` (the same case, seeds {seed}–{seed + reps - 1})", True))
    for m, label in (("is", "Importance sampling"), ("subset", "Subset simulation")):
        c = cov[m]
        out.append((f"{label}: {sum(c['holds_reference'])} of {c['repeats']} ({pct(c['coverage'], 0)})", True))
    c = cov["is"]
    out.append(
        ("its estimated relative error matching the repeats' spread", abs(c["mean_rel_error"] / spread(c["estimates"]) - 1) < 0.1)
    )  # fmt: skip
    c, runs = cov["subset"], cov["subset"]["runs"]
    lo, obs, hi = runs["delta_uncorrelated_rms"], runs["observed_cov"], runs["delta_correlated_rms"]
    out.append((f"The {runs['n_runs']} independent runs inside its repeats", runs["n_runs"] == len(runs["p"])))
    out.append(
        (
            f"their estimates spread by {pct(obs)} (coefficient of variation) against {pct(lo)} from each run's "
            f"`√Σ δ_j²` and {pct(hi)} from Au and Beck's",
            abs(obs - spread(runs["p"])) < 1e-12,
        )
    )
    out.append(("the levels are correlated, mildly", lo < obs < hi and obs - lo < hi - obs))
    out.append(
        (f"it holds `p` in {sum(c['holds_reference'])} of {c['repeats']} repeats, from {count(c['mean_rollouts'])} "
         "rollouts on average", True)
    )  # fmt: skip
    unbiased = all(
        abs(x["mean_estimate_over_reference"] - 1)
        < 2 * statistics.stdev(x["estimates"]) / x["reference"] / math.sqrt(x["repeats"])
        for x in cov.values()
    )
    out.append(("Both estimators are unbiased within the repeats' spread.", unbiased))

    # the certification study
    path = {name: entry["path"] for name, entry in study.items()}
    band = {name: entry["band"] for name, entry in study.items()}
    mc = band["mixed-lmi"]["mc"]
    out.append(
        (f"({count(sizes['mc_study'])} runs per controller, {count(mc['strata'][0]['n_rollouts'])} per path)",
         mc["n_rollouts"] == sizes["mc_study"])
    )  # fmt: skip
    out.append(
        (
            f"`mixed-lmi` {sci(path['mixed-lmi']['is']['p_fail'], 1)} (importance sampling) and "
            f"{sci(path['mixed-lmi']['subset']['p_fail'], 1)} (subset)",
            True,
        )
    )
    for name in ("integral-lmi", "polytopic-integral", "stanley", "pi-table3"):
        out.append(
            (f"`{name}` {sci(path[name]['is']['p_fail'], 1)} and {sci(path[name]['subset']['p_fail'], 1)}", True)
        )
    is_, ss = [p["is"] for p in path.values()], [p["subset"] for p in path.values()]
    is_n = {r["n_rollouts"] for r in is_}
    out.append(
        (
            f"importance sampling from {count(min(is_n))} rollouts "
            f"({span(min(r['rel_error'] for r in is_) * 100, max(r['rel_error'] for r in is_) * 100, integer, ' %')}), subset "
            f"simulation from {span(min(r['n_rollouts'] for r in ss), max(r['n_rollouts'] for r in ss), thousands)} "
            f"({span(min(r['rel_error'] for r in ss) * 100, max(r['rel_error'] for r in ss) * 100, integer, ' %')})",
            len(is_n) == 1,
        )
    )
    ps = [r["p_fail"] for r in is_ + ss]
    out.append((f"would need 100 / p, {span(100 / max(ps), 100 / min(ps), e7)} runs per controller, for 10 %", True))
    top = [fp for p in path.values() for fp in p["is"]["failure_points"][:3]]
    slips = [abs(fp[k]) for fp in top for k in ("slip.beta_r_deg", "slip.beta_f_deg")]
    us = [abs(d["u"]) for fp in top for d in fp["drivers"] if d["key"].startswith("slip.")]
    one_sign = all(fp["slip.beta_r_deg"] * fp["slip.beta_f_deg"] > 0 for fp in top)
    out.append(
        (
            f"both slips of one sign at {span(min(slips), max(slips), integer, '°')} "
            f"({span(min(us), max(us), integer)} standard deviations)",
            one_sign,
        )
    )
    points = path["pi-table3"]["is"]["failure_points"]
    fp = points[0]
    stratum = next(s for s in path["pi-table3"]["is"]["strata"] if s["path"] == fp["path"])
    out.append(
        (
            f"`pi-table3`'s heaviest mode, on the {fp['path']} ({pct(fp['weight'] / stratum['weight'], 0)} of that "
            f"path's proposal), at `β_f = {fp['slip.beta_f_deg']:.1f}°`, `β_r = {fp['slip.beta_r_deg']:.1f}°`",
            fp["weight"] == max(q["weight"] for q in points),
        )
    )

    # pi-table3 on the sine
    strata = {(name, s["path"]): s for name, p in path.items() for s in p["is"]["strata"]}
    sine_is = strata[("pi-table3", "sine")]
    sine_ss = path["pi-table3"]["subset"]["strata"][2]
    overlap = all(
        p["is"]["ci95"][0] <= p["subset"]["ci95"][1] and p["subset"]["ci95"][0] <= p["is"]["ci95"][1]
        for p in path.values()
    )
    out.append((f"intervals overlap for all {WORDS[len(path)]} controllers", overlap))
    out.append(
        (
            f"importance sampling gives {sci(sine_is['p_fail'], 1)} in the study against "
            f"{sci(sine_ss['p_fail'], 1)} by subset simulation",
            sine_ss["path"] == "sine",
        )
    )
    smc, sis, sss = sine["mc"], sine["is"], sine["subset"]
    out.append(
        (
            f"On the sine alone, 10⁶ plain runs give {sci(smc['p_fail'], 1)} "
            f"({interval(smc['ci95'], lambda x: sci(x, 1), ' to ')}): subset simulation agrees "
            f"({sci(sss['p_fail'], 2)})",
            smc["n_rollouts"] == 10**6 and sss["ci95"][0] <= smc["p_fail"] <= sss["ci95"][1],
        )
    )
    out.append(
        (
            f"importance sampling with another seed gives {sci(sis['p_fail'], 2)} "
            f"({interval(sis['ci95'], lambda x: sci(x, 2), ' to ')}), inside the plain interval",
            smc["ci95"][0] <= sis["p_fail"] <= smc["ci95"][1],
        )
    )

    # the reliability check
    flagged = sorted(k for k, s in strata.items() if s["check"]["status"] == "disagree")
    higher = all(strata[k]["p_fail"] > strata[k]["check"]["other"]["p_fail"] for k in flagged)
    out.append((f"flags {WORDS[len(flagged)]} {'stratum' if len(flagged) == 1 else 'strata'}", True))

    def versus(k, fmt):
        s = strata[k]
        return f"{fmt(s['p_fail'])} against {fmt(s['check']['other']['p_fail'])}, `z = {s['check']['z']:.2f}`"

    for k in flagged:  # each flagged stratum named, with both estimates and z
        out.append((f"`{k[0]}` on the {k[1]} ({versus(k, lambda x: sci(x, 1))})", True))
    where = "There" if len(flagged) == 1 else f"On all {WORDS[len(flagged)]}"
    out.append((f"{where} importance sampling is the higher", bool(flagged) and higher))
    out.append((f"{len(strata)} strata tested at the 5 % level", True))
    out.append(
        (
            f"importance sampling's {short(sine_is['p_fail'])} against subset simulation's "
            f"{short(sine_is['check']['other']['p_fail'])} on the same budget is `z = {sine_is['check']['z']:.2f}`",
            sine_is["check"]["status"] == "ok",
        )
    )
    share = {
        failure: max(s["check"]["max_weight_share"] for e in study.values() for s in e[failure]["is"]["strata"])
        for failure in ("path", "band")
    }
    out.append(
        (
            f"(largest share {pct(share['path'])} on the path, {pct(share['band'])} on the band)",
            max(share.values()) < 0.1,
        )
    )
    check = sis["strata"][0]["check"]
    out.append(
        (
            f"the check gives `z = {check['z']:.2f}` ({sci(sis['p_fail'], 2)} against "
            f"{sci(check['other']['p_fail'], 2)}) and does not flag",
            check["status"] == "ok",
        )
    )

    # the band
    inside = [n for n, b in band.items() if all(b[m]["ci95"][0] <= b["mc"]["p_fail"] <= b[m]["ci95"][1] for m in ("is", "subset"))]  # fmt: skip
    outside = [n for n in band if n not in inside]
    out.append((f"the plain estimate lies inside both intervals for {names(inside)}", bool(inside)))
    two = lambda x: sci(x, 2)
    above = [
        f"{two(b['mc']['p_fail'])} ({interval(b['mc']['ci95'], two, ' to ')}) against "
        f"{interval(b['is']['ci95'], two, ' to ')}"
        for b in (band[n] for n in outside)
    ]
    out.append(
        (
            f"for {names(outside)} it lies inside subset simulation's interval and just above importance "
            f"sampling's, which overlaps it: {'; '.join(above)}",
            bool(outside)
            and all(
                b["subset"]["ci95"][0] <= b["mc"]["p_fail"] <= b["subset"]["ci95"][1]
                and b["mc"]["ci95"][0] <= b["is"]["ci95"][1] < b["mc"]["p_fail"]
                for b in (band[n] for n in outside)
            ),
        )
    )
    line = [band["integral-lmi"][m]["strata"][0]["p_fail"] for m in ("is", "subset")]
    mc_line = band["integral-lmi"]["mc"]["strata"][0]
    bound = 1 - 0.025 ** (1 / mc_line["n_rollouts"])  # Clopper-Pearson's top for no failure
    out.append(
        (
            f"`integral-lmi` is at {span(min(line) * 1e7, max(line) * 1e7, integer)}e-7, where "
            f"{count(mc_line['n_rollouts'])} plain runs see nothing",
            mc_line["p_fail"] == 0,
        )
    )
    unknown = [n for n, b in band.items() if b["mc"]["rel_error"] is None]
    top_ok = all(band[n]["mc"]["ci95"][1] >= bound * band[n]["mc"]["strata"][0]["weight"] for n in unknown)
    out.append(
        (
            f"holds the line's exact bound, {sci(bound, 2)}, weighted by 1/3",
            unknown == ["integral-lmi", "polytopic-integral"] and top_ok,
        )
    )
    out.append(
        (
            f"({pct_int(band['mixed-lmi']['mc']['p_fail'])} and {pct_int(band['stanley']['mc']['p_fail'])})",
            True,
        )
    )
    reached = all(s["p_fail"] > 0 for p in path.values() for s in p["subset"]["strata"])
    out.append(("Subset simulation with the tie rules reaches every stratum", reached))

    # the targets table (the known case's budgets: 10⁵ rollouts at 1e-6, 2·10⁵ at 1e-8)
    for label, budget in (("1e-6", 10**5), ("1e-8", 2 * 10**5)):
        r, q = known[label]["is"], known[label]["subset"]
        met = r["n_rollouts"] <= budget < q["n_rollouts"] and r["rel_error"] <= 0.1
        out.append(
            (
                f"{sci(r['p_fail'], 2)}, {pct(r['rel_error'])}, {count(r['n_rollouts'])}"
                f"{' rollouts' if label == '1e-6' else ''} (importance sampling); {sci(q['p_fail'], 2)}, "
                f"{pct(q['rel_error'])}, {count(q['n_rollouts'])} (subset) | importance sampling yes; subset over "
                "the budget |",
                met,
            )
        )
    out.append(
        (
            "10⁴× at 1e-6 (10⁴ against 10⁸ for 10 %)",
            known["1e-6"]["is"]["n_rollouts"] == 10**4,
        )
    )
    out.append(
        (f"| reference inside the 95 % interval | {sum(r['holds_reference'] for r in ests)} of {len(ests)} |", True)
    )
    out.append(
        (
            f"{pct(cov['is']['coverage'], 0)} ({sum(cov['is']['holds_reference'])}/{cov['is']['repeats']}) importance "
            f"sampling; {pct(cov['subset']['coverage'], 0)} ({sum(cov['subset']['holds_reference'])}/"
            f"{cov['subset']['repeats']}) subset simulation",
            all(0.9 <= c["coverage"] <= 0.99 and c["repeats"] >= 50 for c in cov.values()),
        )
    )
    pi, il = path["pi-table3"]["is"], path["integral-lmi"]["is"]
    out.append(
        (
            f"the study's `pi-table3` ({sci(pi['p_fail'], 1)}, {pct(pi['rel_error'])}, {count(pi['n_rollouts'])} "
            f"rollouts of 20 s) and `integral-lmi` ({sci(il['p_fail'], 1)}, {pct(il['rel_error'])})",
            True,
        )
    )
    walls = [p["is"]["wall_s"] for p in path.values()]
    out.append((f"{span(min(walls), max(walls), wall)} s per importance-sampling estimate of leaving the path", True))
    every = [x for p in path.values() for x in (p["is"]["p_fail"], p["subset"]["p_fail"])]
    out.append(
        (
            f"leaving the path: {sci(min(every), 1)} to {sci(max(every), 1)} for all {WORDS[len(path)]} controllers "
            "(both estimators' intervals overlap)",
            overlap,
        )
    )
    return out


# --- the check ----------------------------------------------------------------------------------


def measured(doc: str) -> str:
    """The "## Measured" section of ``doc`` (to the next second-level heading)."""
    start = doc.index("\n## Measured\n")
    end = doc.find("\n## ", start + 1)
    return doc[start : end if end >= 0 else len(doc)]


def tables(text: str) -> list[list[list[str]]]:
    """The markdown tables of ``text``: each a list of rows of stripped cells, the header first,
    the separator row left out."""
    out: list[list[list[str]]] = []
    rows = None
    for line in text.splitlines():
        if not line.startswith("|"):
            rows = None
            continue
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if all(c and set(c) <= set("-:") for c in cells):
            continue
        if rows is None:
            rows = []
            out.append(rows)
        rows.append(cells)
    return out


def mismatches(doc: str, res: dict) -> list[str]:
    """Every place where ``doc``'s Measured section does not quote ``res`` (the verification file)."""
    section = measured(doc)
    found, want = tables(section), expected_tables(res)
    out = []
    if len(found) != len(want) + 1:
        out.append(f"{len(found)} tables in the Measured section, expected {len(want)} and the targets")
    for f, w in zip(found, want):
        name = w[0][0]
        if len(f) != len(w):
            out.append(f"table '{name}': {len(f) - 1} rows, expected {len(w) - 1}")
        for i, (fr, wr) in enumerate(zip(f, w)):
            if len(fr) != len(wr):
                out.append(f"table '{name}' row {i}: {len(fr)} cells, expected {len(wr)}")
            for j, (a, b) in enumerate(zip(fr, wr)):
                if a != b:
                    out.append(f"table '{name}' row {i} ('{wr[0]}') column '{w[0][j]}': {a!r}, the file gives {b!r}")
    text = " ".join(section.split())
    for claim, holds in claims(res):
        if claim not in text:
            out.append(f"missing: {claim!r}")
        elif not holds:
            out.append(f"no longer true of the file: {claim!r}")
    return out


@pytest.fixture(scope="module")
def doc() -> str:
    return DOC.read_text()


@pytest.fixture(scope="module")
def res() -> dict:
    return json.loads(RESULT.read_text())


def test_measured_section_quotes_the_file(doc, res):
    assert mismatches(doc, res) == []


def bump(s: str) -> str:
    """``s`` with its last digit changed (one more, modulo 10)."""
    i = max(i for i, ch in enumerate(s) if ch in DIGITS)
    return s[:i] + str((int(s[i]) + 1) % 10) + s[i + 1 :]


def test_every_table_cell_is_checked(doc, res):
    """Changing any cell of a result table, in a copy of the page, is a mismatch."""
    section = measured(doc)
    lines = section.splitlines()
    missed = []
    for t, table in enumerate(tables(section)[: len(expected_tables(res))]):
        for row in table[1:]:
            line = "| " + " | ".join(row) + " |"
            k = lines.index(line)
            for j, cell in enumerate(row):
                cells = list(row)
                cells[j] = bump(cell) if any(ch in DIGITS for ch in cell) else cell + "x"
                altered = lines[:k] + ["| " + " | ".join(cells) + " |"] + lines[k + 1 :]
                if not mismatches(doc.replace(section, "\n".join(altered)), res):
                    missed.append((t, row[0], table[0][j]))
    assert missed == []


def test_every_claim_is_checked(doc, res):
    """Changing a digit of any quoted sentence (or, without a digit, removing it), in a copy of the
    page, is a mismatch: each claim appears where the page quotes it, once."""
    missed = []
    for claim, _ in claims(res):
        pattern = r"\s+".join(re.escape(word) for word in claim.split())
        m = re.search(pattern, doc)
        assert m, claim
        new = bump(m.group()) if any(ch in DIGITS for ch in claim) else ""
        if not mismatches(doc[: m.start()] + new + doc[m.end() :], res):
            missed.append(claim)
    assert missed == []


@pytest.mark.parametrize(
    ("old", "new"),
    [("| 1e-6 | 1.091 | 1e-06 | is | 9.6e-07 |", "| 1e-6 | 1.091 | 1e-06 | is | 9.7e-07 |"), ("in all", "in total")],
)
def test_an_altered_copy_fails(doc, res, old, new):
    assert old in doc
    assert mismatches(doc.replace(old, new, 1), res)
