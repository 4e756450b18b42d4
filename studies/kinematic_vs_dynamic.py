#!/usr/bin/env python
"""Kinematic vs dynamic: does the robustness verdict of the kinematic slip studies survive a vehicle
whose slip comes from tyre forces (CommonRoad's single-track model, :mod:`pfjax.sim.dynamic`)?

    python studies/kinematic_vs_dynamic.py [--config studies/kinematic_vs_dynamic.toml] [--set key=value ...]
                                           [--out DIR] [--quick]

Arms, all on the same runs (run ``i`` of a path starts from the same pose, speed and friction in
every arm of its scale: common random numbers, so differences between arms are paired):

* robot scale (the robot parameter set, speed and friction ``mu`` sampled): the dynamic arm, the
  same vehicle on a high-friction surface (``mu_grip``), and kinematic arms with constant slip
  uniform on ``+-A`` per axle for each ``A`` of ``slip_ranges_deg``;
* designs: the mixed H2/H-inf, integral and polytopic gains designed on the kinematic model and
  redesigned on the dynamic model's linearised lateral-yaw dynamics (:mod:`pfjax.synthesis.dynamic_plant`),
  on the dynamic arm and the kinematic +-A_max arm;
* passenger-car scale: CommonRoad's vehicle 2 on the source's paths scaled by the wheelbase ratio
  ``S = l_car / 0.2 m``, with Froude scaling of speed and time (``x sqrt(S)``), dynamic and kinematic.

Writes to ``results/kinematic_vs_dynamic/`` (or ``--out``): ``runs.parquet`` (one row per arm, path,
controller and run), ``summary.json`` and ``report.md`` (:mod:`kinematic_vs_dynamic_report`).
"""

from __future__ import annotations

import argparse
import copy
import math
import sys
import tempfile
import time
from pathlib import Path

import jax

import pfjax  # before JAX: one CPU device per core (pfjax.default_host_devices)
import pfjax.cache

pfjax.cache.enable()

import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from kinematic_vs_dynamic_report import report  # noqa: E402
from kinematic_vs_dynamic_summary import summarise  # noqa: E402

from pfjax import controllers as C  # noqa: E402
from pfjax import paths  # noqa: E402
from pfjax.config import ConfigError, load, parse_override  # noqa: E402
from pfjax.errors import command_main  # noqa: E402
from pfjax.jsonio import dumps  # noqa: E402
from pfjax.models import single_track as st  # noqa: E402
from pfjax.outputs import OutputDir, check_name  # noqa: E402
from pfjax.provenance import config_hash, machine  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_TOML = Path(__file__).with_suffix(".toml")
ROBOT_WHEELBASE = 0.2  # m, the source robot's (the kinematic studies' L)
DEFAULTS = {
    "name": "kinematic_vs_dynamic",
    "mu_low": 0.3,  # the dynamic arms' friction: uniform on [mu_low, mu_high]
    "mu_high": 1.0,
    "mu_grip": 3.0,  # a high-friction arm (the same vehicle, little slip)
    "slip_ranges_deg": [10.0, 7.5, 5.0, 3.0, 2.0, 1.0, 0.0],  # kinematic arms: constant slip uniform on +-A
    "bench_runs": 256,  # runs per batch of the throughput comparison
    "bench_repeats": 7,  # timed repeats, interleaved (the best of each is reported)
    "designs": {"enabled": True, "alpha": 10.0, "beta": 1.0, "polytope_slip_deg": 10.0},
    "car": {"enabled": True, "params": "vehicle2", "n_runs": 200, "dt": 0.01},
    "study": {
        "n_runs": 400,
        "seed": 2026,
        "chunk_size": 400,
        "dtype": "float32",
        "f64_check_runs": 0,
        "sim": {"dt": 0.005, "horizon": 20.0, "steady_window": 5.0},
        "success": {"band": 0.05, "from_s": 15.0},
        "vehicle": {"speed": {"dist": "uniform", "low": 0.7, "high": 1.3}},
        "initial": {
            "start_along_m": {"dist": "uniform", "low": 0.0, "high": 2.0},
            "lateral_offset": {"dist": "uniform", "low": -0.5, "high": 0.5},
            "heading_error_deg": {"dist": "uniform", "low": -30.0, "high": 30.0},
        },
        "margin": {"enabled": False},
        "paths": [{"kind": "line"}, {"kind": "parabola"}, {"kind": "sine"}],
        "controllers": [
            {"name": "mixed-lmi", "type": "lmi", "alpha": 10.0, "beta": 1.0},
            {"name": "pi-table3", "type": "pi"},
            {"name": "stanley", "type": "stanley"},
        ],
    },
}
QUICK = ["study.n_runs=16", "study.chunk_size=16", "study.sim.horizon=4.0", "study.sim.steady_window=2.0", "study.success.from_s=2.0",
         "slip_ranges_deg=[10.0, 0.0]", "bench_runs=32", "bench_repeats=1", "car.n_runs=8"]  # fmt: skip
#: Froude scaling exponents of the controllers' gains (the gain's unit in m and s -> S^exponent).
GAIN_SCALING = {"kp_d": -1.0, "ki_d": -1.5, "ki_theta": -0.5, "k_aw": -0.5, "k": -0.5, "k_soft": 0.5}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", help="a TOML file of keys of DEFAULTS (studies/kinematic_vs_dynamic.toml)")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    ap.add_argument("--out")
    ap.add_argument("--quick", action="store_true", help="a small sample and short runs (for tests)")
    ap.add_argument("--overwrite", action="store_true", help="replace a pfjax output of another config in --out")
    args = ap.parse_args(argv)
    return command_main("kinematic_vs_dynamic", lambda: run(args))


def load_config(args) -> dict:
    """DEFAULTS <- --config <- --set; ConfigError naming the key (the arms' study configs are
    validated by pfjax's study schema when they run)."""
    defaults = copy.deepcopy(DEFAULTS)
    defaults["slip_ranges_deg"] = []  # any length
    cfg = load(defaults, args.config)
    if not cfg["slip_ranges_deg"]:
        cfg["slip_ranges_deg"] = list(DEFAULTS["slip_ranges_deg"])
    for text in (QUICK if args.quick else []) + args.set:
        if "slip_ranges_deg" in parse_override(text):
            cfg["slip_ranges_deg"] = []
        cfg = load(cfg, None, [text])
    if not 0 < cfg["mu_low"] < cfg["mu_high"] <= 10:
        raise ConfigError(f"mu_low, mu_high: need 0 < mu_low < mu_high <= 10, got {cfg['mu_low']}, {cfg['mu_high']}")
    ranges = cfg["slip_ranges_deg"]
    if not ranges or not all(isinstance(a, (int, float)) and 0 <= a < 90 for a in ranges):
        raise ConfigError(f"slip_ranges_deg: expected a non-empty list of angles in [0, 90) deg, got {ranges!r}")
    if not 0 < cfg["mu_grip"] <= 10:
        raise ConfigError(f"mu_grip: expected a friction coefficient in (0, 10], got {cfg['mu_grip']!r}")
    for k, v in (("bench_runs", cfg["bench_runs"]), ("bench_repeats", cfg["bench_repeats"]), ("car.n_runs", cfg["car"]["n_runs"])):  # fmt: skip
        if not (isinstance(v, int) and v >= 1):
            raise ConfigError(f"{k}: expected an integer >= 1, got {v!r}")
    if cfg["car"]["params"] not in st.COMMONROAD_VEHICLES:
        raise ConfigError(
            f"car.params: expected one of {', '.join(st.COMMONROAD_VEHICLES)}, got {cfg['car']['params']!r}"
        )
    return cfg


def _dynamic(spec: dict, cfg: dict, mu=None) -> dict:
    out = copy.deepcopy(spec)
    out["vehicle"] = {**out.get("vehicle", {}), "model": "st"}
    out["vehicle"]["mu"] = mu if mu is not None else {"dist": "uniform", "low": cfg["mu_low"], "high": cfg["mu_high"]}
    return out


def _kinematic(spec: dict, a: float) -> dict:
    out = copy.deepcopy(spec)
    for key in ("tau_delta_s", "k_v"):  # the dynamic vehicle's actuator and speed loop
        out.get("vehicle", {}).pop(key, None)
    slip = {"dist": "uniform", "low": -a, "high": a} if a > 0 else 0.0
    out["slip"] = {"kind": "constant", "beta_r_deg": slip, "beta_f_deg": slip}
    return out


def arms(cfg: dict, designed: list[dict] | None = None) -> dict[str, dict]:
    """Arm name -> its study config (pfjax's study schema)."""
    base = {**copy.deepcopy(cfg["study"]), "name": cfg["name"]}
    a_max = max(cfg["slip_ranges_deg"])
    out = {"dynamic": _dynamic(base, cfg), f"dynamic_mu{cfg['mu_grip']:g}": _dynamic(base, cfg, cfg["mu_grip"])}
    for a in cfg["slip_ranges_deg"]:
        out[f"kinematic_{a:g}deg"] = _kinematic(base, a)
    if designed:
        with_designs = {**base, "controllers": designed}
        out["designs_dynamic"] = _dynamic(with_designs, cfg)
        out[f"designs_kinematic_{a_max:g}deg"] = _kinematic(with_designs, a_max)
    if cfg["car"]["enabled"]:
        car = car_study(cfg)
        out["car_dynamic"] = _dynamic(car, cfg)
        out["car_dynamic"]["vehicle"].update(params=cfg["car"]["params"])
        for key in ("L", "delta_max_deg", "delta_rate_max_deg"):
            out["car_dynamic"]["vehicle"].pop(key, None)
        for a in sorted({a_max, 0.0}, reverse=True):
            out[f"car_kinematic_{a:g}deg"] = _kinematic(car, a)
    return out


def car_study(cfg: dict) -> dict:
    """The robot study scaled to the car (module docstring): lengths x S, speeds and times x sqrt(S),
    the paths as splines through the scaled source paths, the controllers' gains Froude-scaled."""
    p = st.parameter_set(cfg["car"]["params"])
    s = (p.l_f + p.l_r) / ROBOT_WHEELBASE
    rs = math.sqrt(s)
    spec = copy.deepcopy(cfg["study"])
    spec["name"] = cfg["name"]
    spec["n_runs"] = spec["chunk_size"] = cfg["car"]["n_runs"]
    sim = spec["sim"]
    sim.update(dt=cfg["car"]["dt"], horizon=sim["horizon"] * rs, steady_window=sim["steady_window"] * rs)
    spec["success"] = {"band": spec["success"]["band"] * s, "from_s": spec["success"]["from_s"] * rs}
    scale = lambda d, f: (
        {k: (v * f if k in ("low", "high", "value") else v) for k, v in d.items()} if isinstance(d, dict) else d * f
    )
    ini = spec["initial"]
    ini["start_along_m"], ini["lateral_offset"] = scale(ini["start_along_m"], s), scale(ini["lateral_offset"], s)
    spec["vehicle"] = {"speed": scale(spec["vehicle"]["speed"], rs), "tau_delta_s": 0.05 * rs, "k_v": 5.0 / rs}
    # the kinematic arms get the car's wheelbase, steering limit and steering-rate limit (0.4 rad/s for
    # CommonRoad's cars), so that the arms differ by the tyres only
    spec["vehicle"].update(
        L=p.l_f + p.l_r, delta_max_deg=math.degrees(p.delta_max), delta_rate_max_deg=math.degrees(p.v_delta_max)
    )
    spec["paths"] = [{"kind": "spline", "name": q["kind"], "points": scaled_path(q["kind"], s)} for q in spec["paths"]]
    for c in spec["controllers"]:
        if c["type"] in ("pi", "stanley"):
            e, _ = C.resolve(c["type"], "type")
            flat = {**C.flat_gains(e), **c.get("gains", {})}
            c["gains"] = {k: v * s ** GAIN_SCALING.get(k, 0.0) for k, v in flat.items()}
    return spec


def scaled_path(kind: str, s: float, length: float = 45.0, n: int = 301) -> list[list[float]]:
    """Points of a source path (``kind``) from its study start (``start_u``) over ``length`` m of arc,
    scaled by ``s`` (m); equally spaced in arc length (``n`` points: a cubic spline through them
    reproduces the curvature to about 1e-3 relative)."""
    e = paths.entry(kind)
    assert e.build is not None
    shape = e.build()
    u = np.linspace(e.start_u, e.start_u + length, 20 * n)
    x, y = (np.asarray(a, float) for a in shape.point(u))
    arc = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(x), np.diff(y)))])
    keep = np.searchsorted(arc, np.linspace(0.0, length, n))
    keep = np.unique(np.minimum(keep, len(u) - 1))
    return [[float(s * x[i]), float(s * y[i])] for i in keep]


def designs(cfg: dict) -> tuple[list[dict], dict]:
    """The kinematic and the dynamic designs of the mixed, integral and polytopic gains at the robot
    scale (study's speed range and tau_delta; friction range [mu_low, mu_high]) as study controllers,
    and their records."""
    from pfjax.synthesis import (
        dynamic_design_plant,
        dynamic_mixed,
        integral_mixed,
        mixed_h2_hinf,
        polytopic_mixed,
        slip_design_plant,
    )

    d = cfg["designs"]
    w = {"alpha": d["alpha"], "beta": d["beta"]}
    speed = cfg["study"]["vehicle"]["speed"]
    v_lo, v_hi = (speed["low"], speed["high"]) if isinstance(speed, dict) else (speed, speed)
    v0, mu0 = 0.5 * (v_lo + v_hi), 0.5 * (cfg["mu_low"] + cfg["mu_high"])
    p, L = st.robot_params(), ROBOT_WHEELBASE
    tau = float(cfg["study"]["vehicle"].get("tau_delta_s", 0.05))

    def plants(mus, speeds, integral=False):
        out = []
        for mu in mus:
            for v in speeds:
                a, b = st.lateral_yaw_matrices(p._replace(mu=mu), v)
                out.append(dynamic_design_plant(a, b, v, p.l_r, L, tau, integral=integral))
        return out

    kin = {
        "mixed": mixed_h2_hinf(slip_design_plant(v0, L), **w).K,
        "integral": integral_mixed(v0, L, **w).K,
        "polytopic": polytopic_mixed((v_lo, v_hi), d["polytope_slip_deg"], L, **w).K,
    }
    dyn = {
        "mixed": dynamic_mixed(plants([mu0], [v0]), kin["mixed"], **w),
        "integral": dynamic_mixed(plants([mu0], [v0], True), kin["integral"], **w),
        "polytopic": dynamic_mixed(plants([cfg["mu_low"], cfg["mu_high"]], [v_lo, v_hi]), kin["mixed"], **w),
    }
    controllers, record = [], {}
    for name in ("mixed", "integral", "polytopic"):
        typ = "integral" if name == "integral" else "state_feedback"
        for origin, K in (("kin", kin[name]), ("dyn", dyn[name].K)):
            label = f"{name}-{origin}"
            flat = [float(k) for k in np.ravel(K)]
            controllers.append({"name": label, "type": typ, "K": flat})
            record[label] = {**(dyn[name].to_dict() if origin == "dyn" else {}), "K": flat}
    return controllers, {"operating_point": {"v": v0, "mu": mu0, "tau_delta_s": tau}, "gains": record}


def run(args) -> int:
    cfg = load_config(args)
    check_name("name", cfg["name"])
    out = Path(args.out) if args.out else ROOT / "results" / cfg["name"]
    with OutputDir(
        out, command="kinematic-vs-dynamic", config_sha256=config_hash(cfg), overwrite=args.overwrite
    ) as output:
        t0 = time.time()
        designed, design_record = designs(cfg) if cfg["designs"]["enabled"] else ([], {})
        frames, wall = [], {}
        with tempfile.TemporaryDirectory() as tmp:
            for name, spec in arms(cfg, designed).items():
                t = time.time()
                res = pfjax.run_study(spec, Path(tmp) / name, report=False, progress=False)
                wall[name] = time.time() - t
                frames.append(res.runs.assign(arm=name))
                print(f"{name}: {len(res.runs)} runs, {wall[name]:.1f} s", file=sys.stderr)
        runs = pd.concat(frames, ignore_index=True)
        bench = throughput(cfg)
        summary = summarise(cfg, runs)
        summary.update(
            study=cfg["name"],
            config=cfg,
            config_sha256=config_hash(cfg),
            pfjax_version=pfjax.__version__,
            machine=machine(),
            designs=design_record,
            throughput=bench,
            wall_s={"arms": wall, "total": time.time() - t0},
        )
        runs.to_parquet(output.staging / "runs.parquet", index=False)
        (output.staging / "summary.json").write_text(dumps(summary) + "\n")
        (output.staging / "report.md").write_text(report(summary))
        output.commit()
    print(report(summary))
    return 0


def throughput(cfg: dict) -> dict:
    """Wall time per rollout-step of the kinematic, ST and STD simulators on batches of the same size
    and step count (``bench_runs`` runs of the study's horizon and step on the sine path, Stanley,
    metrics only; best of ``bench_repeats`` interleaved calls after a compiling call), float32 and
    float64. The ST and kinematic runs are the robot's; the STD runs are vehicle 2's at 10 m/s with a
    2 ms step (its wheel modes need it), the same number of steps."""
    sim = cfg["study"].get("sim", {})
    horizon, dt = float(sim.get("horizon", 20.0)), float(sim.get("dt", 0.005))
    steps = round(horizon / dt)
    n = cfg["bench_runs"]
    out = {"runs": n, "steps": steps, "controller": "stanley", "path": "sine"}
    setups = {
        "kinematic": ({"beta_r_deg": 5.0, "beta_f_deg": 5.0}, dt),
        "st": ({"model": "st", "mu": 0.65}, dt),
        "std": ({"model": "std", "vehicle_params": "vehicle2", "mu": 0.65, "speed": 10.0}, 0.002),
    }
    for dtype in ("float32", "float64"):
        with jax.enable_x64(dtype == "float64"):
            calls = {}
            for model, (kw, step) in setups.items():
                runs = pfjax.scenarios("sine", n=n, lateral_offset=pfjax.uniform(-0.5, 0.5), key=0, **kw)
                config = {"horizon": steps * step, "dt": step}
                calls[model] = lambda runs=runs, config=config: pfjax.simulate(runs, "stanley", config=config)
                calls[model]()  # compiles
            best = dict.fromkeys(calls, math.inf)
            for _ in range(cfg["bench_repeats"]):  # interleaved, so all see the same load on a shared machine
                for model, call in calls.items():
                    t = time.perf_counter()
                    call()
                    best[model] = min(best[model], time.perf_counter() - t)
            row: dict = {m: {"wall_s": b, "ns_per_rollout_step": 1e9 * b / (n * steps)} for m, b in best.items()}
            row["ratio_st_over_kinematic"] = best["st"] / best["kinematic"]
            row["ratio_std_over_kinematic"] = best["std"] / best["kinematic"]
            out[dtype] = row
    return out


if __name__ == "__main__":
    sys.exit(main())
