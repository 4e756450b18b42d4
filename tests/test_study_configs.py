"""Every shipped study config validates and runs end to end at a small size (with its report).

The worst-case search costs a gradient compilation per controller, so the shipped configs run here
without it, and one small study (one controller, the default study's falsifier settings) checks it
end to end: in the summary, the report and the figures."""

import json
import tomllib
from pathlib import Path

import matplotlib
import pandas as pd
import pytest
from units_check import numbers_without_units

from pfjax.montecarlo.config import load_study
from pfjax.montecarlo.study import run

matplotlib.use("Agg")
ROOT = Path(__file__).resolve().parents[1]
# Monte Carlo study configs (those with controllers and paths); the other TOML files configure study scripts
CONFIGS = sorted(
    p for p in (ROOT / "studies").glob("*.toml") if {"controllers", "paths"} <= set(tomllib.loads(p.read_text()))
)
SMALL = [
    "n_runs=6",
    "chunk_size=6",
    "sim.horizon=3.0",
    "sim.steady_window=1.0",
    "success.from_s=2.0",
    "margin.amplitudes_deg=[0.0, 10.0]",
    "margin.n_per_amplitude=3",
    "falsifier.n_restarts=2",
    "falsifier.steps=2",
    "f64_check_runs=0",
    "falsifier.enabled=false",
]  # the float64 check recompiles every simulator in float64: tested in test_determinism.py
#: a config's rare-event estimates (rare_events.toml) on a small budget: per stratum (path) 100 draws
#: for the starts, a cross-entropy level of 100 and 100 draws to estimate from; the estimators'
#: accuracy is tested in test_rare.py
RARE_BUDGET = 3 * 3 * 100
RARE_SMALL = [f"rare_event.max_rollouts={RARE_BUDGET}", "rare_event.n_per_level=100", "rare_event.batch=100"]


def test_configs_are_found():
    names = {p.stem for p in CONFIGS}
    assert {"robustness_default", "slip_frequency", "random_paths"} <= names


@pytest.mark.parametrize("path", [p for p in CONFIGS if p.stem != "paper_reproduction"], ids=lambda p: p.stem)
def test_study_config_runs_small(path, tmp_path):
    spec, _ = load_study(path)  # the file as shipped validates
    if path.stem == "robustness_default":
        assert spec.n_runs >= 10_000 and {p.kind for p in spec.paths} == {"line", "parabola", "sine"}
    small, _ = load_study(path, SMALL + (RARE_SMALL if spec.rare_event.enabled else []))
    summary = run(small, tmp_path / "out", progress=False, report=True)
    runs = pd.read_parquet(tmp_path / "out" / "runs.parquet")
    assert len(runs) == summary["n_runs_total"] == 6 * len(small.paths) * len(small.controllers)
    if spec.rare_event.enabled:  # every controller's estimate within the budget, in the summary
        for c in summary["controllers"].values():
            assert {"p_fail", "p_fail_ci95", "rel_error", "n_rollouts", "method"} <= set(c)
            assert c["method"] == spec.rare_event.method and 0 < c["n_rollouts"] <= RARE_BUDGET
    assert set(summary["controllers"]) == {c.name for c in small.controllers}
    on_disk = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert numbers_without_units(on_disk) == []  # the rare-event estimates' too (rare_events.toml)
    for c in on_disk["controllers"].values():
        assert {"success_rate", "success_ci95", "iae_mean", "iae_p95", "steady_abs_d_p95", "slip_margin_deg"} <= set(c)
    html = (tmp_path / "out" / "report.html").read_text()
    assert len(html) > 10_000
    assert all("worst_case" not in c for c in on_disk["controllers"].values())


def test_default_study_falsifier_small_end_to_end(tmp_path):
    """The default study's worst-case search (its settings as shipped, 2 restarts x 2 steps), one
    controller and the falsifier's path only: summary block, report section and figure."""
    data = tomllib.loads((ROOT / "studies" / "robustness_default.toml").read_text())
    assert data["falsifier"]["enabled"]
    data["controllers"] = [c for c in data["controllers"] if c["name"] == "pi-table3"]
    data["paths"] = [p for p in data["paths"] if p["kind"] == data["falsifier"]["path"]]
    sets = [s for s in SMALL if not s.startswith("falsifier.enabled")] + ["margin.enabled=false"]
    small, _ = load_study(overrides=sets, data=data)
    summary = run(small, tmp_path / "out", progress=False, report=True)
    on_disk = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert numbers_without_units(on_disk) == [] and on_disk["units"]["falsifier"] == "m s (iae)"
    wc = on_disk["controllers"]["pi-table3"]["worst_case"]
    assert wc == summary["controllers"]["pi-table3"]["worst_case"]
    assert wc["path"] == "sine" and wc["n_rollouts"] == 2 * 2 and wc["falsifier"] >= 0 and wc["random"] >= 0
    assert len(wc["history"]) == len(wc["history_rollouts"]) and max(wc["history"]) == pytest.approx(
        wc["falsifier"], rel=1e-6
    )
    html = (tmp_path / "out" / "report.html").read_text()
    assert "Worst cases found" in html and (tmp_path / "out" / "figures" / "worst_cases.png").is_file()


def test_random_paths_take_every_allowed_waypoint_count():
    """``n_waypoints`` up to the schema's 10,000: the waypoints stay distinct samples of the integrated
    path (the curvature integral takes 4 samples per interval past 1,000 intervals)."""
    import numpy as np

    from pfjax.montecarlo.config import PathSpec
    from pfjax.montecarlo.sampling import random_path

    key = np.array([0, 7], np.uint32)
    for n in (4, 41, 1001, 10_000):
        path = random_path(key, PathSpec(kind="random", n_waypoints=n), kappa_max=0.5)
        knots = np.asarray(path.knots)
        assert knots.shape == (n,) and np.all(np.diff(knots) > 0), n
        assert np.all(np.isfinite(np.asarray(path.coef_x))) and np.all(np.isfinite(np.asarray(path.coef_y)))
