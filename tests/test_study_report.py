"""The study report: a tiny real study (2 controllers, 1 path, 40 runs each, a 3-amplitude margin
sweep) run with ``report=True``; the page must be one self-contained, well-formed HTML file whose
numbers are those of ``summary.json``, with every figure also on disk as PNG and SVG."""

from __future__ import annotations

import base64
import json
import os
import warnings
from html.parser import HTMLParser
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import pandas as pd
import pytest
from units_check import numbers_without_units

from pfjax.montecarlo.config import load_study
from pfjax.montecarlo.study import RUN_FIGURES, WORKER_SUMMARY_FIGURES, run
from pfjax.montecarlo.summary import summarize
from pfjax.report import figure_worker
from pfjax.report.figure_set import report_figures
from pfjax.report.study_format import fmt_ci, fmt_gains, fmt_margin, fmt_num, fmt_pct
from pfjax.report.study_report import write_report

# 30 runs in chunks of 30, and the sweep's 3 amplitudes x 10 runs per axis are 30 too: one array shape,
# so one compilation per controller.
CONFIG = {
    "name": "tiny_report",
    "n_runs": 30,
    "seed": 7,
    "chunk_size": 30,
    "sim": {"horizon": 4.0, "steady_window": 1.0},
    "success": {"from_s": 2.0},
    "slip": {
        "beta_r_deg": {"dist": "uniform", "low": -10, "high": 10},
        "beta_f_deg": {"dist": "uniform", "low": -10, "high": 10},
    },
    "initial": {"lateral_offset": {"dist": "uniform", "low": -0.2, "high": 0.2}},
    "margin": {"n_per_amplitude": 10, "amplitudes_deg": [0, 10, 20]},
    "paths": [{"kind": "line"}],
    "controllers": [{"name": "lmi", "type": "lmi"}, {"name": "stanley", "type": "stanley"}],
}
FIGURES = ("headline", "margin_curves", "dist_iae", "dist_late_max_abs_d", "slip_map", "success_by_param")
VOID = {"meta", "img", "br", "hr", "link", "input", "col", "area", "base", "source", "wbr"}


class _Page(HTMLParser):
    """Collects text, image sources and external references, and checks that tags balance."""

    def __init__(self):
        super().__init__(convert_charrefs=True)
        self.stack, self.errors, self.imgs, self.external, self.text = [], [], [], [], []
        self.tables, self._cell = [], None

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if tag == "img":
            self.imgs.append(a.get("src", ""))
        for key in ("src", "href"):
            v = a.get(key) or ""
            if v and not v.startswith(("data:", "#")):
                self.external.append((tag, key, v))
        if tag == "link":
            self.external.append((tag, "link", a.get("href")))
        if tag == "table":
            self.tables.append([])
        elif tag == "tr" and self.tables:
            self.tables[-1].append([])
        elif tag in ("td", "th"):
            self._cell = []
        if tag not in VOID:
            self.stack.append(tag)

    def handle_endtag(self, tag):
        if tag in VOID:
            return
        if tag in ("td", "th") and self._cell is not None and self.tables and self.tables[-1]:
            self.tables[-1][-1].append("".join(self._cell).strip())
            self._cell = None
        if not self.stack or self.stack[-1] != tag:
            self.errors.append(f"</{tag}> closes <{self.stack[-1] if self.stack else None}>")
        else:
            self.stack.pop()

    def handle_data(self, data):
        if self.stack and self.stack[-1] not in ("style", "script"):
            self.text.append(data)
        if self._cell is not None:
            self._cell.append(data)


def _parse(html: str) -> _Page:
    p = _Page()
    p.feed(html)
    p.close()
    return p


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    """The tiny study with its report, its run figures drawn by the figure worker process."""
    spec, _ = load_study(data=CONFIG)
    out = tmp_path_factory.mktemp("report") / "out"
    before = os.environ.get(figure_worker.ENV)
    os.environ[figure_worker.ENV] = "1"
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            run(spec, out, progress=False, report=True)
        assert not [w for w in caught if "figure worker" in str(w.message)]  # the worker drew, no fallback
    finally:
        if before is None:
            del os.environ[figure_worker.ENV]
        else:
            os.environ[figure_worker.ENV] = before
    summary = json.loads((out / "summary.json").read_text())
    return spec, out, summary


def _toml(v) -> str:
    """A TOML inline value."""
    if isinstance(v, dict):
        return "{" + ", ".join(f"{k} = {_toml(x)}" for k, x in v.items()) + "}"
    if isinstance(v, list):
        return "[" + ", ".join(map(_toml, v)) + "]"
    return json.dumps(v)


def _config_sets() -> list[str]:
    """CONFIG as ``--set`` values of the command line."""
    return [f"{k}={_toml(v)}" for k, v in CONFIG.items()]


def _in_process(spec, out, summary, dest):
    """The figures the worker drew, drawn again in this process into ``dest``."""
    runs = pd.read_parquet(out / "runs.parquet")
    return report_figures(dest, spec, summary, runs, names=RUN_FIGURES + WORKER_SUMMARY_FIGURES)


def test_figures_from_the_worker_equal_those_drawn_in_process(study, tmp_path):
    spec, out, summary = study
    here = _in_process(spec, out, summary, tmp_path)
    assert set(here) == set(RUN_FIGURES + WORKER_SUMMARY_FIGURES)
    for name in here:  # same code, same data: the same bytes
        assert (tmp_path / "figures" / f"{name}.png").read_bytes() == (out / "figures" / f"{name}.png").read_bytes(), (
            name
        )


def test_cli_study_starts_the_worker_before_its_imports_and_draws_the_same_report(study, tmp_path, monkeypatch, capsys):
    """``pfjax study`` starts the figure worker itself and hands it to the study: the same figures."""
    from pfjax import cli

    spec, out, _ = study
    cfg = tmp_path / "tiny.toml"
    cfg.write_text('name = "x"\n')
    monkeypatch.setenv(figure_worker.ENV, "1")
    started = []
    monkeypatch.setattr(
        figure_worker.FigureWorker,
        "__init__",
        lambda self, _init=figure_worker.FigureWorker.__init__, **kw: (started.append(1), _init(self, **kw))[1],
    )

    sets = _config_sets()
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        assert (
            cli.main(
                ["study", str(cfg), "--out", str(tmp_path / "cli"), "--quiet"] + sum((["--set", a] for a in sets), [])
            )
            == 0
        )
    assert started == [1]  # one worker, started by the CLI
    for name in FIGURES:
        assert (tmp_path / "cli" / "figures" / f"{name}.png").read_bytes() == (
            out / "figures" / f"{name}.png"
        ).read_bytes(), name


def test_worst_case_figure_from_the_worker_equals_the_one_drawn_here(study, tmp_path):
    """The worker draws the worst-case figure from the trajectories it is sent (no run table)."""
    import numpy as np

    spec, out, summary = study
    summary = json.loads(json.dumps(summary))
    t = np.linspace(0.0, 4.0, 801)
    trajs = {}
    for i, name in enumerate(summary["controllers"]):
        summary["controllers"][name]["worst_case"] = {
            "path": "line",
            "objective": "iae",
            "falsifier": 1.0 + i,
            "falsifier_status": "ok",
            "random": 0.5,
            "ratio": 2.0 + 2 * i,
            "n_rollouts": 6,
            "history": [0.2, 0.7, 1.0 + i],
            "history_rollouts": [2, 4, 6],
            "history_random": [0.1, 0.4, 0.5],
            "history_random_rollouts": [2, 4, 6],
        }
        trajs[name] = {
            "t": t,
            "x": t,
            "y": 0.1 * np.sin(t),
            "d": 0.05 * np.sin(2 * t + i),
            "beta_r": 0.1 * np.sin(t),
            "beta_f": -0.1 * np.cos(t),
            "path_x": t,
            "path_y": 0 * t,
        }
    with figure_worker.FigureWorker() as w, warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)  # no fallback: the worker drew it
        got = w.submit(
            tmp_path / "w",
            spec,
            summary,
            tmp_path / "no-runs-needed.parquet",
            ["worst_cases"],
            worst_trajectories=trajs,
        ).result()
    here = report_figures(tmp_path / "h", spec, summary, None, trajs, names=["worst_cases"])
    assert list(got) == list(here) == ["worst_cases"]
    assert (tmp_path / "w" / "figures" / "worst_cases.png").read_bytes() == (
        tmp_path / "h" / "figures" / "worst_cases.png"
    ).read_bytes()


def test_a_worst_case_search_without_its_figure_says_why(study):
    """The worst-case figure needs the search's trajectories, which ``pfjax report`` does not have:
    a report whose study ran with ``--no-report`` says why the figure is missing."""
    from pfjax.report.document import to_markdown
    from pfjax.report.study_document import study_document

    spec, out, summary = study
    summary = json.loads(json.dumps(summary))
    for name in summary["controllers"]:
        summary["controllers"][name]["worst_case"] = {
            "path": "line",
            "objective": "iae",
            "falsifier": 1.0,
            "falsifier_status": "ok",
            "random": 0.5,
            "random_status": "ok",
            "ratio": 2.0,
            "n_rollouts": 6,
            "worst_ic": {"d0": 0.1, "theta_e0_deg": 2.0},
            "worst_slip_peak_deg": [3.0, 4.0],
        }
    runs = pd.read_parquet(out / "runs.parquet")
    text = to_markdown(study_document(summary, runs, {}, [], {n: "#000000" for n in summary["controllers"]}))
    assert "## Worst cases found" in text and "No figure of the worst runs" in text


def test_figure_worker_that_cannot_start_or_dies_falls_back_to_this_process(study, tmp_path):
    spec, out, summary = study
    want = {n: (out / "figures" / f"{n}.png").read_bytes() for n in RUN_FIGURES}
    # a worker that cannot start: one warning, the figures drawn here
    with pytest.warns(RuntimeWarning, match="figure worker could not start"):
        w = figure_worker.FigureWorker(python=str(tmp_path / "no-such-python"))
    got = w.submit(tmp_path / "a", spec, summary, out / "runs.parquet", RUN_FIGURES).result()
    w.close()
    assert list(got) == RUN_FIGURES
    assert all((tmp_path / "a" / "figures" / f"{n}.png").read_bytes() == b for n, b in want.items())
    # a worker that dies before it answers: one warning naming its exit code, the figures drawn here
    w = figure_worker.FigureWorker()
    w._proc.kill()
    w._proc.wait()
    with pytest.warns(RuntimeWarning, match="figure worker exited with code -9"):
        got = w.submit(tmp_path / "b", spec, summary, out / "runs.parquet", RUN_FIGURES).result()
    w.close()
    assert list(got) == RUN_FIGURES
    assert all((tmp_path / "b" / "figures" / f"{n}.png").read_bytes() == b for n, b in want.items())


def test_figure_worker_reports_a_failed_request_and_the_figures_are_drawn_here(study, tmp_path):
    spec, out, summary = study
    with figure_worker.FigureWorker() as w:
        bad = w.submit(tmp_path / "c", spec, summary, tmp_path / "missing.parquet", RUN_FIGURES)
        good = w.submit(tmp_path / "d", spec, summary, out / "runs.parquet", ["dist_iae"])
        with pytest.warns(RuntimeWarning, match="figure worker failed: FileNotFoundError"):
            with pytest.raises(FileNotFoundError):  # drawn here: the same error, raised where it belongs
                bad.result()
        assert list(good.result()) == ["dist_iae"]  # the worker goes on with the next request
    assert (tmp_path / "d" / "figures" / "dist_iae.png").read_bytes() == (out / "figures" / "dist_iae.png").read_bytes()


def test_report_is_one_self_contained_wellformed_file(study):
    _, out, _ = study
    html = (out / "report.html").read_text(encoding="utf-8")
    page = _parse(html)
    assert page.errors == [] and page.stack == [], (page.errors, page.stack)
    assert html.lstrip().lower().startswith("<!doctype html>")
    assert page.external == []
    assert 'src="http' not in html and "url(" not in html and "@import" not in html
    assert len(page.imgs) == len(FIGURES)
    assert all(src.startswith("data:image/png;base64,") for src in page.imgs)
    # the embedded images are the figures written next to the page
    on_disk = {(out / "figures" / f"{n}.png").read_bytes() for n in FIGURES}
    assert {base64.b64decode(src.split(",", 1)[1]) for src in page.imgs} == on_disk


def test_every_figure_is_written_as_png_and_svg(study):
    _, out, _ = study
    for name in FIGURES:
        png, svg = out / "figures" / f"{name}.png", out / "figures" / f"{name}.svg"
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", name
        assert "<svg" in svg.read_text(encoding="utf-8")[:2000], name


def _headline_numbers_in(text: str, summary: dict) -> None:
    """The summary's headline numbers, formatted as the report shows them, are all in ``text``."""
    assert summary["config_sha256"] in text
    assert f"{summary['n_runs_total']} simulated runs" in text
    assert f"seed {summary['seed']}" in text
    for name, c in summary["controllers"].items():
        assert name in text
        lo, hi = c["success_ci95"]
        rate = f"{100 * c['success_rate']:.2f} %"
        assert fmt_pct(c["success_rate"]) == rate and rate in text
        assert fmt_ci(c["success_ci95"]) == f"[{100 * lo:.2f}, {100 * hi:.2f}] %" and fmt_ci(c["success_ci95"]) in text
        assert f"{c['k']} / {c['n']}" in text
        assert f"{c['iae_mean']:.3g}" in text and f"{c['iae_p95']:.3g}" in text
        assert f"{1000 * c['steady_abs_d_p95']:.1f}" in text
        assert c["statement"]["text"] in text
        for axis, m in c["slip_margin"].items():
            shown = fmt_margin(m)
            assert shown.startswith(("≥ " if m["censored"] else "") + f"{m['margin']:g}°")
            assert shown in text
        for k, v in c["gains"].items():
            assert f"{k} = {v:.4g}" in text


def test_report_numbers_are_those_of_summary_json(study):
    spec, out, summary = study
    text = "".join(_parse((out / "report.html").read_text(encoding="utf-8")).text)
    _headline_numbers_in(text, summary)
    _headline_numbers_in((out / "report.md").read_text(encoding="utf-8"), summary)
    # failed runs are counted, never hidden: one status row per controller and path (plus the
    # controller's total over its paths), adding up to its runs
    tables = _parse((out / "report.html").read_text(encoding="utf-8")).tables
    status = next(t for t in tables if t[0][:5] == ["controller", "path", "runs", "success", "ok but outside the band"])
    runs = pd.read_parquet(out / "runs.parquet")
    n_paths = runs.path.nunique()
    for row in status[1:]:
        g = runs[runs.controller == row[0]]
        if row[1] != "all paths":
            g = g[g.path == row[1]]
        counts = dict(zip(status[0][5:], map(int, row[5:])))
        n = (
            summary["controllers"][row[0]]["n"]
            if row[1] == "all paths"
            else summary["controllers"][row[0]]["per_path"][row[1]]["n"]
        )
        assert int(row[2]) == len(g) == sum(counts.values()) == n
        assert int(row[3]) == int(g.success.sum())
        assert int(row[4]) == int(((g.status == "ok") & ~g.success).sum())
        assert counts == {
            f"status {k}": int((g.status == k).sum()) for k in [h.removeprefix("status ") for h in status[0][5:]]
        }
    assert len(status) - 1 == len(summary["controllers"]) * (n_paths + (n_paths > 1))
    assert [r[0] for r in status[1:] if r[1] == "all paths"] == (list(summary["controllers"]) if n_paths > 1 else [])
    for heading in (
        "Verdict",
        "Set-up",
        "Headline per controller",
        "Per path",
        "Run status",
        "Distributions",
        "Slip margins",
        "Robustness map (from simulation)",
        "Failure drivers",
        "Reproducibility",
    ):
        assert heading in text


def test_every_number_of_summary_json_has_a_unit(study):
    _, _, summary = study
    assert numbers_without_units(summary) == []
    units = summary["units"]
    assert units["iae_mean"].startswith("m s") and units["slip_margin_deg"] == "deg" and units["wall_s"] == "s"
    assert units["quantiles"]["steady_abs_d"] == "m" and units["quantiles"]["steer_energy"] == "rad^2 s"
    assert units["success_by_param"] == {"beta_r_deg": "deg", "beta_f_deg": "deg", "lateral_offset": "m"}


def test_report_shows_the_wall_time_of_summary_json(study):
    """The report (and ``pfjax report``, re-rendering it from summary.json) shows summary.json's
    ``wall_s``: everything but writing the report out."""
    _, out, summary = study
    shown = f"{fmt_num(summary['wall_s'], 4)} s (runs, sweep, summary, side jobs and figures"
    assert shown in (out / "report.md").read_text(encoding="utf-8")
    assert sum(v for k, v in summary["timings_s"].items() if k != "side_jobs") >= summary["wall_s"]


def test_report_without_margin_sweep(study, tmp_path):
    spec, out, summary = study
    runs = pd.read_parquet(out / "runs.parquet")
    s = summarize(spec, runs, None, gains={k: v["gains"] for k, v in summary["controllers"].items()}, wall_s=1.0)
    write_report(tmp_path, spec, s, runs)
    html = (tmp_path / "report.html").read_text(encoding="utf-8")
    page = _parse(html)
    assert page.errors == [] and page.external == []
    assert not (tmp_path / "figures" / "margin_curves.png").exists()
    assert "No slip-margin sweep" in "".join(page.text)
    assert len(page.imgs) == len(FIGURES) - 1
    md = (tmp_path / "report.md").read_text(encoding="utf-8")  # the same report in Markdown, figures linked
    assert "No slip-margin sweep" in md and "margin_curves.png" not in md
    assert md.count("](figures/") == len(FIGURES) - 1


def test_summary_from_the_file_equals_summary_from_the_table(study):
    """Large studies summarise ``runs.parquet`` one controller at a time (never loading it whole):
    the same numbers as from the whole table."""
    spec, out, summary = study
    gains = {k: v["gains"] for k, v in summary["controllers"].items()}
    sweep = None
    if (out / "margin.parquet").exists():
        sweep = (
            pd.read_parquet(out / "margin.parquet")
            .groupby(["controller", "axis", "amplitude_deg"], sort=False)["success"]
            .agg(k="sum", n="count")
            .reset_index()
        )
    from_table = summarize(spec, pd.read_parquet(out / "runs.parquet"), sweep, gains=gains, wall_s=1.0)
    from_file = summarize(spec, out / "runs.parquet", sweep, gains=gains, wall_s=1.0)
    from pfjax.jsonio import dumps  # strict JSON (NaN -> null), so NaN quantiles compare equal

    assert from_file["n_runs_total"] == from_table["n_runs_total"] == summary["n_runs_total"]
    assert dumps(from_file) == dumps(from_table)


def test_study_without_report_streams_and_gives_the_same_summary(study, tmp_path):
    """``report=False`` never loads the run table whole (summary per controller, float64 check on its
    sampled runs only): same summary, float64 check included, as the run with a report."""
    from pfjax.jsonio import dumps

    spec, out, summary = study
    assert summary["float64_check"]["checked"]
    s = run(spec, tmp_path / "noreport", progress=False, report=False)
    assert not (tmp_path / "noreport" / "report.html").exists()
    drop = lambda d: {k: v for k, v in d.items() if k not in ("wall_s", "timings_s")}
    assert dumps(drop(s)) == dumps(drop(json.loads(dumps(summary))))


def test_worst_case_figure_asked_of_the_worker_by_the_last_search_equals_the_one_drawn_here(tmp_path, monkeypatch):
    """With a falsifier, the worker draws the worst-case figure (asked for by whichever thread ends
    the search): every figure of the report is the same as a study's without a worker."""
    data = {  # CONFIG's simulation (8 runs, padded to 32 as its 30): the fixture's compiled simulator
        **CONFIG,
        "n_runs": 8,
        "chunk_size": 8,
        "margin": {"enabled": False},
        "controllers": [{"name": "lmi", "type": "lmi"}],
        "falsifier": {"enabled": True, "path": "line", "n_restarts": 2, "steps": 2},
    }
    spec, _ = load_study(data=data)
    asked = []
    submit = figure_worker.FigureWorker.submit
    monkeypatch.setattr(
        figure_worker.FigureWorker, "submit", lambda self, *a, **k: (asked.append(list(a[4])), submit(self, *a, **k))[1]
    )
    monkeypatch.setenv(figure_worker.ENV, "1")
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)  # no fallback: the worker drew them
        run(spec, tmp_path / "worker", progress=False, report=True)
    assert ["worst_cases"] in asked
    monkeypatch.setenv(figure_worker.ENV, "0")
    run(spec, tmp_path / "here", progress=False, report=True)
    pngs = sorted(p.name for p in (tmp_path / "here" / "figures").glob("*.png"))
    assert "worst_cases.png" in pngs
    assert pngs == sorted(p.name for p in (tmp_path / "worker" / "figures").glob("*.png"))
    for name in pngs:
        assert (tmp_path / "worker" / "figures" / name).read_bytes() == (
            tmp_path / "here" / "figures" / name
        ).read_bytes(), name


def test_worst_figure_is_asked_for_once_when_the_searches_and_the_directory_are_there():
    """:class:`~pfjax.montecarlo.study.WorstFigure` submits one request, from the thread that
    completes it (the last search or the directory), with the controllers' blocks in their order."""
    import threading

    from pfjax.montecarlo.side_jobs import WorstFigure

    class Fake:
        def __init__(self):
            self.calls = []

        def submit(self, out, spec, summary, runs_path, names, trajs):
            self.calls.append((out, summary, runs_path, names, list(trajs), threading.current_thread().name))
            return type("R", (), {"result": lambda self: {"worst_cases": {"name": "worst_cases"}}})()

    for order in (["a", "dir", "b"], ["dir", "b", "a"], ["b", "a", "dir"]):
        w = WorstFigure(fake := Fake(), None, ["a", "b"])
        for step in order:
            if step == "dir":
                w.start(Path("/out"), Path("/out/runs.parquet"))
            else:  # a search ends in another thread
                t = threading.Thread(
                    target=w.found, args=(step, ({"falsifier": step}, {"t": step})), name=f"search-{step}"
                )
                t.start()
                t.join()
            assert len(fake.calls) == (step == order[-1])  # asked for only once everything is there
        out, summary, runs_path, names, trajs, thread = fake.calls[0]
        assert (out, runs_path, names, trajs) == (Path("/out"), Path("/out/runs.parquet"), ["worst_cases"], ["a", "b"])
        assert summary == {
            "controllers": {"a": {"worst_case": {"falsifier": "a"}}, "b": {"worst_case": {"falsifier": "b"}}}
        }
        assert thread == ("MainThread" if order[-1] == "dir" else f"search-{order[-1]}")
        assert w.result() == {"worst_cases": {"name": "worst_cases"}} and len(fake.calls) == 1
    assert WorstFigure(None, None, ["a"]).result() is None  # no worker: the study draws it


def test_figure_worker_answers_can_be_collected_in_any_order(study, tmp_path):
    """Results asked for out of order (a later request first) are each the worker's, not redrawn here."""
    spec, out, summary = study
    with figure_worker.FigureWorker() as w, warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        first = w.submit(tmp_path / "e", spec, summary, out / "runs.parquet", ["dist_iae"])
        second = w.submit(tmp_path / "f", spec, summary, out / "runs.parquet", ["headline"])
        assert list(second.result()) == ["headline"]
        assert first._answer is not None  # read on the way to the second's
        assert list(first.result()) == ["dist_iae"]
    for d, name in (("e", "dist_iae"), ("f", "headline")):
        assert (tmp_path / d / "figures" / f"{name}.png").read_bytes() == (out / "figures" / f"{name}.png").read_bytes()


def test_paired_comparison_is_mcnemars_exact_test_and_tangos_interval():
    """:func:`pfjax.report.study_verdict.paired` against ``scipy.stats.binomtest`` (the exact
    McNemar test: the runs where exactly one controller succeeds, at p = 1/2); its interval is
    Tango's score interval of the same counts (checked against an independent solution in
    ``tests/test_dynamic_study_audit.py``), with a width where the outcomes are identical."""

    import numpy as np
    from scipy import stats

    from pfjax.metrics.robustness import paired_interval
    from pfjax.report.study_verdict import paired

    rng = np.random.default_rng(5)
    for n, p_a, p_b in [(2000, 0.6, 0.55), (300, 0.5, 0.5), (40, 0.9, 0.2), (12, 1.0, 1.0), (7, 0.0, 1.0)]:
        ok_a, ok_b = rng.random(n) < p_a, rng.random(n) < p_b
        runs = pd.DataFrame(
            {
                "controller": ["a"] * n + ["b"] * n,
                "path": "line",
                "run": np.r_[np.arange(n), rng.permutation(n)],  # rows of b in another order
                "success": np.r_[ok_a, np.zeros(n, bool)],
            }
        )
        runs.loc[runs.controller == "b", "success"] = ok_b[runs.loc[runs.controller == "b", "run"].to_numpy()]
        got = paired(runs, "a", "b")
        b, c = int((ok_a & ~ok_b).sum()), int((~ok_a & ok_b).sum())
        assert (got["n"], got["only_a"], got["only_b"]) == (n, b, c)
        want_p = stats.binomtest(b, b + c, 0.5).pvalue if b + c else 1.0
        assert got["p"] == pytest.approx(want_p, rel=1e-10)
        assert got["diff"] == (b - c) / n
        assert got["ci"] == paired_interval(b, c, n) and got["ci"][0] <= got["diff"] <= got["ci"][1]
        z2 = stats.norm.ppf(0.975) ** 2
        if b == c == 0:  # identical outcomes (n = 12 at 1.0 and 1.0): +-z^2 / (n + z^2), not a zero width
            assert got["ci"] == pytest.approx((-z2 / (n + z2), z2 / (n + z2)), rel=1e-9)


def test_a_study_with_its_report_does_not_import_scipy_stats(tmp_path):
    """The summary's intervals and rank correlations and the report's paired tests come from
    ``scipy.special``: ``scipy.stats`` would add about 0.5 s of imports to every study."""
    import subprocess
    import sys

    cfg = tmp_path / "s.toml"
    cfg.write_text('name = "imports"\n')
    out = tmp_path / "o"
    cmd = [sys.executable, "-X", "importtime", "-m", "pfjax.cli", "study", str(cfg), "--out", str(out), "--quiet"]
    # the module's study (two controllers, a margin sweep) on this process's one device: the
    # simulators the `study` fixture compiled, loaded from the persistent cache
    cmd += sum((["--set", a] for a in _config_sets()), [])
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=600, env={**os.environ, "PFJAX_HOST_DEVICES": "1"})
    assert r.returncode == 0, r.stderr[-3000:]
    assert (out / "report.html").is_file()
    imported = {line.rsplit("|", 1)[-1].strip() for line in r.stderr.splitlines() if line.startswith("import time:")}
    # (an import through scipy's lazy attributes lists only scipy.stats' submodules)
    assert "scipy.special" in imported and not [m for m in imported if m.split(".")[:2] == ["scipy", "stats"]]


def test_gains_are_shown_by_scalar_name_to_four_significant_digits():
    from pfjax import controllers as C

    flat = C.flat_gains(C.entry("state_feedback"), C.state_feedback_params(C.PAPER_K))
    assert fmt_gains(flat) == "k_d = -2.738, k_theta = -2.077, feedforward = 0"
    assert fmt_gains({}) == "—" and fmt_gains({}, "defaults") == "defaults"


def test_run_counts_are_what_the_study_ran(study):
    """pfjax.montecarlo.checks.run_counts (the plan, before running) against the summary's counts
    of what ran: the study's runs and the margin sweep's."""
    from pfjax.montecarlo.checks import run_counts

    spec, _, s = study
    n = run_counts(spec)
    assert n["study"] == s["n_runs_total"] and n["margin"] == s["n_margin_runs"] > 0
    assert n["per_controller"] * len(spec.controllers) == n["study"]
    assert (
        run_counts(spec.model_copy(update={"margin": spec.margin.model_copy(update={"enabled": False})}))["margin"] == 0
    )
