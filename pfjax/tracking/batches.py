"""Scenario batches of the tracking study: the Lemma 8.1 grid and the robustness Monte Carlo sample.

Both return ``(scenarios, rows)``: a stacked :class:`TrackScenario` and one dict per run with the
sampled settings in readable units, so results join on the run index; :func:`run_chunks` simulates
them in fixed-size chunks and :func:`frame` joins the rows with the metrics.
"""

from __future__ import annotations

import itertools
import math

import jax
import numpy as np
import pandas as pd
from tqdm import tqdm

from pfjax.sim.slip_profiles import constant_slip
from pfjax.tracking import leader as L
from pfjax.tracking.controller import FocusGains
from pfjax.tracking.geometry import lemma_bound, p_bound
from pfjax.tracking.model import FollowerParams, as_arrays
from pfjax.tracking.simulate import (
    TRACK_STATUS_NAMES,
    SensorNoise,
    TrackConfig,
    TrackScenario,
    initial_states,
    simulate_batch,
    stack,
)


def _assemble(params, leaders, offsets, heading_errors, gains, slips, noise, keys) -> TrackScenario:
    """Stack per-run pieces and place every follower with one batched :func:`initial_states`."""
    P, Ld = stack([as_arrays(p) for p in params]), stack(leaders)
    init = initial_states(Ld, P, np.asarray(offsets, dtype=float), np.asarray(heading_errors, dtype=float))
    n = len(params)
    return TrackScenario(
        params=P,
        gains=FocusGains(k=np.full((n,), float(gains))),
        leader=Ld,
        init=init,
        slip=stack(slips),
        noise=SensorNoise(*(np.full((n,), float(x)) for x in (noise or (0.0, 0.0, 0.0)))),
        key=stack(keys),
    )


MC_LEADERS = ("line", "circle", "sine", "lane-change", "stop-and-go", "random")


def grid_leaders(radius: float, key) -> dict:
    return {
        "line": L.line(),
        "circle": L.circle(radius=radius),
        "sine": L.sine(),
        "lane-change": L.lane_change(),
        "stop-and-go": L.line(depth=1.0),
        "random": L.random_smooth(key),
    }


def lemma_grid(cfg: dict, key):
    """Every combination of mode, ``p``, ``|l|``, ``gamma_max``, leader and initial offset."""
    s, g = cfg["sim"], cfg["lemma"]
    leaders = grid_leaders(g["circle_radius"], key)
    prms, lds, offs, rows = [], [], [], []
    for f, p, la, gdeg, (lname, ld), off in itertools.product(
        (1, -1), g["p"], g["l_abs"], g["gamma_max_deg"], leaders.items(), g["offsets"]
    ):
        gm = math.radians(gdeg)
        prms.append(FollowerParams(a=s["a"], f=f, l=f * la, p=p, gamma_max=gm))
        lds.append(ld)
        offs.append(off)
        lo, hi = p_bound(gm, f)
        rows.append(
            {
                "mode": "forward" if f > 0 else "backward",
                "p": p,
                "l": f * la,
                "gamma_max_deg": gdeg,
                "leader": lname,
                "offset_along": off[0],
                "offset_left": off[1],
                "inside_bound": abs(p) < lemma_bound(gm),
                "invertible": lo < p < hi,
            }
        )
    n = len(rows)
    zero = constant_slip(0.0, 0.0)
    return _assemble(prms, lds, offs, [0.0] * n, s["k"], [zero] * n, None, [jax.random.PRNGKey(0)] * n), rows


def mc_sample(cfg: dict, f: int, key):
    """``n_runs`` random scenarios of one mode; run ``i`` draws from ``fold_in(key, i)``."""
    s, m = cfg["sim"], cfg["mc"]
    gm = math.radians(m["gamma_max_deg"])
    prm = FollowerParams(a=s["a"], f=f, l=f * m["l_abs"], p=m["p_forward"] if f > 0 else m["p_backward"], gamma_max=gm)
    noise = (m["sigma_pos"], math.radians(m["sigma_theta_deg"]), math.radians(m["sigma_gamma_deg"]))
    lds, offs, hes, slips, keys, rows = [], [], [], [], [], []
    for i in range(m["n_runs"]):
        k = jax.random.fold_in(key, i)
        u = np.asarray(jax.random.uniform(jax.random.fold_in(k, 0), (10,)))
        kind = MC_LEADERS[int(u[0] * len(MC_LEADERS))]
        speed = m["speed_low"] + u[1] * (m["speed_high"] - m["speed_low"])
        radius = (3.0 + 5.0 * u[2]) * (1 if u[3] < 0.5 else -1)
        ld = {
            "line": lambda: L.line(speed=speed),
            "circle": lambda: L.circle(radius=radius, speed=speed),
            "sine": lambda: L.sine(amplitude=0.5 + u[2], wavenumber=0.2 + 0.2 * u[3], speed=speed),
            "lane-change": lambda: L.lane_change(width=2.0 + 2.0 * u[2], speed=speed),
            "stop-and-go": lambda: L.line(speed=speed, depth=0.5 + 0.5 * u[2], period=6.0 + 8.0 * u[3]),
            "random": lambda: L.random_smooth(jax.random.fold_in(k, 1), speed=speed),
        }[kind]()
        off = ((2 * u[4] - 1) * m["offset_max"], (2 * u[5] - 1) * m["offset_max"])
        he = (2 * u[6] - 1) * m["heading_error_max_deg"]
        br, bf = (2 * u[7] - 1) * m["slip_max_deg"], (2 * u[8] - 1) * m["slip_max_deg"]
        lds.append(ld)
        offs.append(off)
        hes.append(math.radians(he))
        slips.append(constant_slip(math.radians(br), math.radians(bf)))
        keys.append(jax.random.fold_in(k, 2))
        rows.append(
            {
                "mode": "forward" if f > 0 else "backward",
                "run": i,
                "leader": kind,
                "speed": speed,
                "offset_along": off[0],
                "offset_left": off[1],
                "heading_error_deg": he,
                "beta_r_deg": br,
                "beta_f_deg": bf,
            }
        )
    n = len(rows)
    return _assemble([prm] * n, lds, offs, hes, s["k"], slips, tuple(noise), keys), rows


def result_columns(r) -> dict:
    """Per-run numbers of a batched :class:`TrackResult` as NumPy columns."""
    m = {k: np.asarray(v) for k, v in r.metrics._asdict().items()}
    m["max_abs_gamma_deg"] = np.degrees(m.pop("max_abs_gamma"))
    m["status_code"] = np.asarray(r.status)
    m["fail_time"] = np.asarray(r.fail_time)
    return m


def run_chunks(scs: TrackScenario, cfg: TrackConfig, chunk: int, desc: str = "tracking runs") -> dict:
    """:func:`simulate_batch` over ``chunk``-sized slices (the last one padded: one compilation), as NumPy columns."""
    scs = jax.tree_util.tree_map(np.asarray, scs)  # slice on the host, not op by op on the device
    n = int(np.shape(scs.params.p)[0])
    outs = []
    for i in tqdm(range(0, n, chunk), desc=desc, leave=False, disable=None):
        part = jax.tree_util.tree_map(lambda x: x[i : i + chunk], scs)
        m = int(part.params.p.shape[0])
        if m < chunk:
            part = jax.tree_util.tree_map(lambda x: np.concatenate([x, np.repeat(x[-1:], chunk - m, 0)]), part)
        cols = result_columns(simulate_batch(part, config=cfg))
        outs.append({k: v[:m] for k, v in cols.items()})
    return {k: np.concatenate([o[k] for o in outs]) for k in outs[0]}


def frame(rows: list[dict], cols: dict) -> pd.DataFrame:
    """One row per run: the sampled settings, the metrics and a readable ``status``."""
    df = pd.concat([pd.DataFrame(rows), pd.DataFrame(cols)], axis=1)
    df["status"] = [TRACK_STATUS_NAMES[int(c)] for c in df["status_code"]]
    return df
