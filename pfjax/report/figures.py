"""Matplotlib figure builders (NumPy in, ``Figure`` out; never under jit).

Each builder returns a figure; :func:`save` writes it as PNG (and SVG) and closes it. The
backend is left to the caller (scripts select Agg; notebooks keep their inline backend).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import matplotlib
import matplotlib.pyplot as plt
import numpy as np


def _style(name: str) -> dict:
    """Plot style of a controller (:func:`pfjax.controllers.style`: registry or design name)."""
    from pfjax.controllers import style

    return style(name)


def save(fig, out_dir: Path, name: str, svg: bool = True, *, dpi: int = 130, tight: bool = True) -> str:
    """Write ``fig`` as ``out_dir/name.png`` (``dpi``) and, with ``svg``, ``name.svg``, cropped to
    what is drawn unless not ``tight``; close it and return the PNG's name. The same figure gives
    the same bytes in both files (the SVG's element ids from a fixed salt, no date in it)."""
    out_dir.mkdir(parents=True, exist_ok=True)
    box = "tight" if tight else None
    fig.savefig(out_dir / f"{name}.png", dpi=dpi, bbox_inches=box)
    if svg:
        with matplotlib.rc_context({"svg.hashsalt": "pfjax"}):
            fig.savefig(out_dir / f"{name}.svg", bbox_inches=box, metadata={"Date": None})
    plt.close(fig)
    return f"{name}.png"


def tracking_figure(title: str, path_xy: np.ndarray, trajs: dict, delta_max: float):
    """2x2: the path and the robot's trajectories; steering; lateral error d; heading error.

    Args:
        title: figure title.
        path_xy: (n, 2) dense samples of the path, m.
        trajs: controller name -> dict of arrays t, x, y, delta, d, theta_e (SI units).
        delta_max: steering limit, rad.
    """
    fig, ax = plt.subplots(2, 2, figsize=(11, 7.5))
    a = ax[0, 0]
    a.plot(path_xy[:, 0], path_xy[:, 1], color="0.6", lw=4, alpha=0.5, label="path")
    for name, tr in trajs.items():
        a.plot(tr["x"], tr["y"], **_style(name))
    first = next(iter(trajs.values()))
    a.plot(first["x"][0], first["y"][0], "ko", ms=5, label="start")
    a.set(xlabel="x [m]", ylabel="y [m]", title="path and robot (rear axle)")
    a.set_aspect("equal", adjustable="datalim")
    a.legend(fontsize=7, loc="best")
    panels: list[tuple[Any, str, Callable[[np.ndarray], np.ndarray], str]] = [
        (ax[0, 1], "delta", np.degrees, "steering δ [deg]"),
        (ax[1, 0], "d", lambda v: 100 * v, "lateral error d [cm]"),
        (ax[1, 1], "theta_e", np.degrees, "heading error θₑ [deg]"),
    ]
    for a, key, scale, label in panels:
        for name, tr in trajs.items():
            a.plot(tr["t"], scale(tr[key]), **_style(name))
        a.axhline(0, color="0.7", lw=0.6)
        a.set(xlabel="t [s]", ylabel=label)
        a.grid(alpha=0.3)
    for s in (-1, 1):
        ax[0, 1].axhline(s * np.degrees(delta_max), color="k", ls=":", lw=0.8)
    # inset-like zoom on the steady state of d
    a = ax[1, 0]
    t = first["t"]
    late = t > 0.5 * t[-1]
    lo = min(float(np.min(100 * tr["d"][late])) for tr in trajs.values())
    hi = max(float(np.max(100 * tr["d"][late])) for tr in trajs.values())
    ins = a.inset_axes(_free_band(a, trajs, t > 0.4 * t[-1]))
    for name, tr in trajs.items():
        ins.plot(tr["t"][late], 100 * tr["d"][late], **{k: v for k, v in _style(name).items() if k != "label"})
    pad = 0.1 * max(hi - lo, 1e-3)
    ins.set_ylim(lo - pad, hi + pad)
    ins.set_title("second half (zoom), d [cm] against t [s]", fontsize=7)
    ins.tick_params(labelsize=7)
    fig.suptitle(title)
    fig.tight_layout()
    return fig


def stability_figure(
    beta_deg: np.ndarray,
    source_max_re: np.ndarray,
    true_max_re: np.ndarray,
    exists: np.ndarray,
    sim_converged: np.ndarray,
    delta_max_deg: float,
):
    """Three maps over (beta_r, beta_f): the source's linearisation, the true equilibrium, simulation."""
    fig, ax = plt.subplots(1, 3, figsize=(15, 4.6), sharey=True)
    ext = [beta_deg[0], beta_deg[-1], beta_deg[0], beta_deg[-1]]
    kw = dict(origin="lower", extent=ext, aspect="auto")
    im = ax[0].imshow(source_max_re.T, cmap="viridis", **kw)
    fig.colorbar(im, ax=ax[0], label="max Re λ [1/s]")
    ax[0].set_title("source's analysis: Jacobian at [0, −β_r]\n(max real part; < 0 everywhere = 'Hurwitz')")
    masked = np.where(exists, true_max_re, np.nan)
    im = ax[1].imshow(masked.T, cmap="viridis", **kw)
    fig.colorbar(im, ax=ax[1], label="max Re λ at the true equilibrium [1/s]")
    ax[1].set_title("true equilibrium (white: none exists,\n|β_r+β_f| > δ_max)")
    cmap = matplotlib.colors.ListedColormap(["#d62728", "#2ca02c"])
    ax[2].imshow(sim_converged.T.astype(float), cmap=cmap, vmin=0, vmax=1, **kw)
    ax[2].set_title("simulation (line test, 40 s): green = converged\nto the predicted equilibrium, red = not")
    b = np.array([beta_deg[0], beta_deg[-1]])
    for a in ax:
        for s in (-1, 1):
            a.plot(b, s * delta_max_deg - b, "--", color="0.3", lw=1)
        a.set(xlabel="β_r [deg]", xlim=(b[0], b[1]), ylim=(b[0], b[1]))
    ax[0].set_ylabel("β_f [deg]")
    fig.tight_layout()
    return fig


def pi_assignment_figure(labels: list[str], line_traces: dict, ok: dict):
    """d(t) on the line test for every reading of Table 3; consistent readings highlighted."""
    fig, ax = plt.subplots(figsize=(10, 5))
    for lab in labels:
        tr = line_traces[lab]
        if ok[lab]:
            ax.plot(tr["t"], 100 * tr["d"], lw=2, label=lab.replace("=", " = ").replace(",", ", "))
        else:
            ax.plot(tr["t"], 100 * tr["d"], color="0.75", lw=0.7)
    ax.plot([], [], color="0.75", lw=0.7, label="other readings")
    ax.set(
        xlabel="t [s]",
        ylabel="d [cm]",
        title="Line test, all 24 readings of Table 3 (β_r = β_f = 5°)",
        ylim=(-100, 100),
    )
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    return fig


def _free_band(a, trajs: dict, after: np.ndarray) -> list[float]:
    """Where the zoom of the lateral error goes in axes ``a`` (axes fractions ``[x0, y0, w, h]``):
    the right half, in the taller of the bands below and above every trajectory's ``d`` at the
    times ``after`` (past the transient), so that it covers none of them."""
    y0, y1 = a.get_ylim()
    lo = min(float(np.min(100 * tr["d"][after])) for tr in trajs.values())
    hi = max(float(np.max(100 * tr["d"][after])) for tr in trajs.values())
    below, above = (lo - y0) / (y1 - y0), (y1 - hi) / (y1 - y0)
    if max(below, above) < 0.3:  # no room clear of the curves: the upper right, as before
        return [0.45, 0.45, 0.5, 0.45]
    if below >= above:
        return [0.45, 0.1, 0.5, below - 0.2]  # room for its tick labels below it and its title above
    return [0.45, 1.0 - above + 0.06, 0.5, above - 0.16]


def sine_error_figure(x: np.ndarray, d: np.ndarray, xk: np.ndarray, kappa: np.ndarray, dkappa: np.ndarray, label: str):
    """|d| along the sine path (at closest-point x) against the path's |kappa| and |dkappa/ds| (at xk)."""
    fig, ax = plt.subplots(figsize=(10, 4))
    ax.plot(x, 1000 * np.abs(d), color="k", label=f"|d| ({label}) [mm]")
    ax.set(xlabel="x [m]", ylabel="|d| [mm]")
    ax2 = ax.twinx()
    ax2.plot(xk, np.abs(kappa), color="#1f77b4", ls="--", label="|κ| [1/m]")
    ax2.plot(xk, np.abs(dkappa), color="#ff7f0e", ls=":", label="|dκ/ds| [1/m²]")
    ax2.set_ylabel("|κ| [1/m], |dκ/ds| [1/m²]")
    lines = ax.get_lines() + ax2.get_lines()
    # below the axes: every x has a peak of one of the three curves
    ax.legend(
        lines, [str(l.get_label()) for l in lines], fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.15), ncol=3
    )
    ax.set_title("Sine path after the transient: error against curvature and its rate of change")
    fig.tight_layout()
    return fig
