"""Verdicts on the claims of the path-following source (Fakharian et al.; model documentation:
``docs/reproductions/path-following.md``): one row per claim, path and criterion, from the paper reproduction's runs.

The inputs are plain dicts and frames the study computes (``studies/paper_reproduction.py``):

* ``rows``: one dict per (path, controller) with the run's metrics (``status``, ``settling_time``
  s, ``steady_abs_d`` m and ``steady_abs_theta_e_rad`` rad over the final window, ``final_delta`` and
  ``final_theta_e`` rad, ``max_abs_delta_cmd`` the peak commanded steering before saturation and
  ``max_abs_delta`` the peak applied steering, rad, ``steer_energy`` ∫δ² dt of the applied
  steering in rad²·s, ``sat_fraction`` the fraction of the run with the command beyond the limit);
* ``stab``: the stability analysis (fractions over the slip grid, the source linearisation's
  eigenvalue maxima over the open square (−90°, 90°)², the paper case's equilibrium);
* ``pi_df``: the 24 readings of Table 3 with their filter columns (``c_*``) and ``filters``, the
  number of readings passing each filter and the sensitivity of the choice to the thresholds;
* ``sine``: where the sine test's error peaks; ``long_pi``: the PI's line test at a long horizon;
  ``ga``: the Table 2 crossover readings.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any, NamedTuple

from pfjax.paths import source_tests
from pfjax.reproduce.verdict import Verdict

CONTROLLERS = ("mixed", "pi")
LABEL = {"mixed": "mixed H2/H∞ (pfjax's K)", "paper-k": "mixed H2/H∞ (source's K)", "pi": "PI (Table 3)"}


def _holds(ok: bool) -> str:
    return "holds" if ok else "does not hold"


def _mm(x: float) -> str:
    return f"{1000 * x:.2f} mm"


def _s(x: float) -> str:
    return f"{x:.2f} s" if math.isfinite(x) else "never"


class Inputs(NamedTuple):
    """What the claims are checked on (module docstring): the runs by (path, controller), the
    source tests, the configured limit (deg), settling band (m), steady window (s), horizon (s), the
    source's published values, and the analyses."""

    R: dict
    paths: tuple
    dmax_deg: float
    band: float
    window: float
    horizon: float
    src: dict
    stab: dict
    pi_df: Any
    sine: dict
    long_pi: dict
    ga: dict


#: ``add(claim, path, subject, criterion, pfjax, source, verdict, basis=...)``: append one checked row
Add = Callable[..., None]


def _converge(inp: Inputs, add: Add) -> None:
    """Both controllers bring the robot onto all three paths."""
    R, paths, band = inp.R, inp.paths, inp.band
    claim = "Both controllers bring the robot onto all three paths"
    for p in paths:
        for c in CONTROLLERS:
            r = R[(p, c)]
            ok = r["status"] == "ok" and math.isfinite(r["settling_time"])
            add(
                claim,
                p,
                LABEL[c],
                f"the run ends ok and |d| stays within {100 * band:g} cm from a finite time on (the settling time)",
                _s(r["settling_time"]) + ("" if r["status"] == "ok" else f", status {r['status']}"),
                "—",
                _holds(ok),
            )


def _steering_limit(inp: Inputs, add: Add) -> None:
    """Both controllers respect the (assumed) steering limit."""
    R, paths, dmax_deg = inp.R, inp.paths, inp.dmax_deg
    claim = "Both controllers respect the steering limit"
    for p in paths:
        for c in CONTROLLERS:
            r = R[(p, c)]
            peak = math.degrees(r["max_abs_delta_cmd"])
            add(
                claim,
                p,
                LABEL[c],
                f"the commanded steering (before the ±{dmax_deg:g}° saturation; assumed limit) "
                f"stays within the limit: max |δ_cmd| ≤ {dmax_deg:g}°",
                f"max |δ_cmd| = {peak:.1f}°, saturated {100 * r['sat_fraction']:.1f} % of the run",
                "—",
                _holds(peak <= dmax_deg + 1e-9),
                basis="assumed",
            )


def _faster(inp: Inputs, add: Add) -> None:
    """The mixed design converges faster than the PI, per path."""
    R, paths, band = inp.R, inp.paths, inp.band
    claim = "The mixed design converges faster than the PI"
    for p in paths:
        m, q = R[(p, "mixed")], R[(p, "pi")]
        add(
            claim,
            p,
            "mixed vs PI",
            f"settling time into the {100 * band:g} cm band: mixed < PI",
            f"{_s(m['settling_time'])} vs {_s(q['settling_time'])}",
            "—",
            _holds(m["settling_time"] < q["settling_time"]),
        )


def _more_accurate(inp: Inputs, add: Add) -> None:
    """The mixed design converges more accurately than the PI, per path."""
    R, paths, window = inp.R, inp.paths, inp.window
    claim = "The mixed design converges more accurately than the PI"
    for p in paths:
        m, q = R[(p, "mixed")], R[(p, "pi")]
        add(
            claim,
            p,
            "mixed vs PI",
            f"steady |d| (mean over the last {window:g} s): mixed < PI",
            f"{_mm(m['steady_abs_d'])} vs {_mm(q['steady_abs_d'])}",
            "—",
            _holds(m["steady_abs_d"] < q["steady_abs_d"]),
        )


def _yaw_error(inp: Inputs, add: Add) -> None:
    """The mixed design has the smaller yaw error, per path."""
    R, paths, window = inp.R, inp.paths, inp.window
    claim = "The mixed design has the smaller yaw error"
    for p in paths:
        m, q = R[(p, "mixed")], R[(p, "pi")]
        dm, dq = math.degrees(m["steady_abs_theta_e_rad"]), math.degrees(q["steady_abs_theta_e_rad"])
        add(
            claim,
            p,
            "mixed vs PI",
            f"steady |θₑ| (mean over the last {window:g} s): mixed < PI",
            f"{dm:.3f}° vs {dq:.3f}°",
            "—",
            _holds(dm < dq),
        )


def _effort(inp: Inputs, add: Add) -> None:
    """The mixed design needs less steering effort than the PI, per path."""
    R, paths = inp.R, inp.paths
    claim = "The mixed design needs less steering effort than the PI"
    for p in paths:
        m, q = R[(p, "mixed")], R[(p, "pi")]
        for what, key, fmt in (
            (
                "peak commanded steering max |δ_cmd| (before saturation)",
                "max_abs_delta_cmd",
                lambda v: f"{math.degrees(v):.1f}°",
            ),
            ("peak applied steering max |δ| (after saturation)", "max_abs_delta", lambda v: f"{math.degrees(v):.1f}°"),
            ("steering energy ∫δ² dt of the applied steering", "steer_energy", lambda v: f"{v:.4f} rad²·s"),
            ("time with the command beyond the limit", "sat_fraction", lambda v: f"{100 * v:.1f} % of the run"),
        ):
            mv, qv = m[key], q[key]
            add(
                claim,
                p,
                "mixed vs PI",
                f"{what}: mixed < PI",
                f"{fmt(mv)} vs {fmt(qv)}",
                "—",
                _holds(mv < qv) if not (mv == qv == 0) else "no verdict",
            )


def _line_mixed_error(inp: Inputs, add: Add) -> None:
    """Line: the mixed design's steady-state position error below the source's bound."""
    R, window, src, stab = inp.R, inp.window, inp.src, inp.stab
    claim = f"Line: steady-state position error below {src['line_ss_mixed_mm_below']:g} mm (mixed)"
    for c in ("mixed", "paper-k"):
        r = R[("line", c)]
        add(
            claim,
            "line",
            LABEL[c],
            f"steady |d| (mean over the last {window:g} s) < {src['line_ss_mixed_mm_below']:g} mm",
            f"{_mm(r['steady_abs_d'])} (equilibrium d* = {_mm(stab['paper_case']['d_star'])} for the source's K)",
            f"< {src['line_ss_mixed_mm_below']:g} mm",
            _holds(1000 * r["steady_abs_d"] < src["line_ss_mixed_mm_below"]),
        )


def _line_pi_error(inp: Inputs, add: Add) -> None:
    """Line: the PI's steady-state position error near the source's, at the horizon and settled."""
    R, window, src, long_pi = inp.R, inp.window, inp.src, inp.long_pi
    claim = f"Line: steady-state position error about {src['line_ss_pi_mm']:g} mm (PI)"
    tol = 0.5
    r = R[("line", "pi")]
    ratio = 1000 * r["steady_abs_d"] / src["line_ss_pi_mm"]
    add(
        claim,
        "line",
        LABEL["pi"],
        f"steady |d| at the {inp.horizon:g} s horizon (mean over the last "
        f"{window:g} s) within ±{100 * tol:g} % of {src['line_ss_pi_mm']:g} mm",
        _mm(r["steady_abs_d"]),
        f"about {src['line_ss_pi_mm']:g} mm",
        "reproduced" if abs(ratio - 1) <= tol else "not reproduced",
        basis="assumed",
    )
    ratio = long_pi["steady_abs_d_mm"] / src["line_ss_pi_mm"]
    add(
        claim,
        "line",
        LABEL["pi"],
        f"steady |d| once settled (a {long_pi['horizon_s']:g} s run: mean over its last "
        f"{window:g} s) within ±{100 * tol:g} % of {src['line_ss_pi_mm']:g} mm; settled = |d| within 5 % of its final "
        f"value from then on",
        f"{long_pi['steady_abs_d_mm']:.2f} mm, settled from t = {_s(long_pi['settle_time_s'])}",
        f"about {src['line_ss_pi_mm']:g} mm",
        "reproduced" if abs(ratio - 1) <= tol else "not reproduced",
    )


def _line_steering(inp: Inputs, add: Add) -> None:
    """Line: the steering settles near the source's angle."""
    R, src = inp.R, inp.src
    claim = f"Line: the steering settles at about {src['line_delta_deg']:g}° to compensate the slip"
    for c in CONTROLLERS:
        fd = math.degrees(R[("line", c)]["final_delta"])
        add(
            claim,
            "line",
            LABEL[c],
            f"final applied steering within 0.5° of {src['line_delta_deg']:g}°",
            f"{fd:.3f}°",
            f"about {src['line_delta_deg']:g}°",
            _holds(abs(fd - src["line_delta_deg"]) < 0.5),
            basis="used to choose the convention",
        )


def _line_yaw(inp: Inputs, add: Add) -> None:
    """Line: the yaw error settles at a non-zero value."""
    R = inp.R
    claim = "Line: the yaw error settles at a non-zero value"
    for c in CONTROLLERS:
        te = math.degrees(R[("line", c)]["final_theta_e"])
        add(
            claim,
            "line",
            LABEL[c],
            "final |θₑ| > 1° (the equilibrium needs θₑ* = −β_r)",
            f"{te:.3f}°",
            "non-zero",
            _holds(abs(te) > 1.0),
        )


def _sine_peaks(inp: Inputs, add: Add) -> None:
    """Sine: where the errors peak against the curvature."""
    sine = inp.sine
    claim = "Sine: the errors grow where the curvature changes fastest (near the extrema)"
    to_k, to_dk = sine["median_peak_to_kappa_max_m"], sine["median_peak_to_dkappa_max_m"]
    add(
        claim,
        "sine",
        LABEL["mixed"],
        "after 5 s, |d| peaks within a quarter period (π/4 m of x) of the sine's extrema (|κ| maxima)",
        f"median distance {to_k:.2f} m",
        "near the extrema",
        _holds(to_k < math.pi / 4),
    )
    add(
        claim,
        "sine",
        LABEL["mixed"],
        "the |d| peaks lie closer to the |dκ/ds| maxima (curvature changing fastest) than to the |κ| maxima",
        f"{to_dk:.2f} m vs {to_k:.2f} m",
        "where κ changes fastest",
        _holds(to_dk < to_k),
    )


def _hurwitz(inp: Inputs, add: Add) -> None:
    """Theorem 4, Figs. 4-5: the linearised loop over the slip square."""
    stab = inp.stab
    claim = "Theorem 4, Figs. 4-5: the linearised loop is Hurwitz for every slip in (−90°, 90°)²"
    em = stab["eigen_maxima"]
    add(
        claim,
        "line",
        "source's K",
        "the source's linearisation at [0, −β_r] is Hurwitz on the whole grid "
        f"(±{em['grid_max_deg']:g}°, {em['n']}² points)",
        f"{100 * em['hurwitz_fraction']:.1f} % of the grid",
        "100 %",
        "reproduced" if em["hurwitz_fraction"] == 1.0 else "not reproduced",
    )
    for name, key in (("λ₁", "max_re_slow"), ("λ₂", "max_re_fast")):
        v, s = em[key], em[f"source_{key}"]
        add(
            claim,
            "line",
            "source's K",
            f"max Re {name} of the source's linearisation over the open square, within 0.1 % of the source's figure",
            f"{v:.4f} 1/s (at β_r, β_f = {em[key + '_at'][0]:.1f}°, {em[key + '_at'][1]:.1f}°)",
            f"{s:.4f} 1/s",
            "reproduced" if abs(v - s) <= 1e-3 * abs(s) else "not reproduced",
        )
    add(
        claim,
        "line",
        "source's K",
        "the true equilibrium (not [0, −β_r]) exists and is Hurwitz for every slip on "
        f"the ±{stab['grid_deg'][1]:g}° grid",
        f"exists on {100 * stab['equilibrium_exists_fraction']:.0f} % "
        f"(|β_r + β_f| ≤ δ_max), Hurwitz on {100 * stab['hurwitz_where_exists_fraction']:.0f} % of those; simulation "
        f"agrees on {100 * stab['sim_agrees_with_analysis_fraction']:.1f} %",
        "every slip",
        _holds(stab["equilibrium_exists_fraction"] == 1.0 and stab["hurwitz_where_exists_fraction"] == 1.0),
    )


def _table3(inp: Inputs, add: Add) -> None:
    """Table 3: the reading of the PI gains."""
    pi_df = inp.pi_df
    claim = "Table 3: GA-optimal PI gains 1.6390, 0.0230, 39.5204, 11.6124 (row labels lost)"
    f = pi_df.attrs["filters"]
    counts = "; ".join(f"{k}: {v} of 24" for k, v in f["passing"].items())
    add(
        claim,
        "line, parabola, sine",
        "24 readings",
        "exactly one reading passes every filter taken from the source's claims about its PI (" + counts + ")",
        f"{f['consistent']} reading(s): {', '.join(f['consistent_readings'])}",
        "one PI",
        _holds(f["consistent"] == 1),
        basis="chosen by filters from the source",
    )
    add(
        claim,
        "line, parabola, sine",
        "24 readings",
        "the chosen reading stays the only one under each filter threshold halved and doubled",
        f"unique in {f['sensitivity_unique']} of {f['sensitivity_cases']} threshold settings",
        "—",
        _holds(f["sensitivity_unique"] == f["sensitivity_cases"]),
        basis="chosen by filters from the source",
    )


def _table2(inp: Inputs, add: Add) -> None:
    """Table 2: the GA's crossover readings."""
    ga = inp.ga
    claim = "Table 2: MATLAB ga with crossover fraction 0.8 (and a row 'Crossover Operation: none')"
    a, b = ga["crossover"], ga["none"]
    add(
        claim,
        ga["scenario"],
        "PI tuned by the GA",
        f"median cost ({ga['cost']}) over {len(a['costs'])} seeds: "
        "adopted reading (scattered crossover, fraction 0.8) vs the other (no crossover: children by mutation only)",
        f"{a['median_cost']:.4f} vs {b['median_cost']:.4f}",
        "—",
        "no verdict",
    )
    add(
        claim,
        ga["scenario"],
        "PI tuned by the GA",
        "the tuned gains change with the reading (largest relative difference of the best gains, per gain)",
        ga["gain_change"],
        "—",
        "no verdict",
    )


#: every claim, in the order of the verdict table
CLAIMS = (
    _converge,
    _steering_limit,
    _faster,
    _more_accurate,
    _yaw_error,
    _effort,
    _line_mixed_error,
    _line_pi_error,
    _line_steering,
    _line_yaw,
    _sine_peaks,
    _hurwitz,
    _table3,
    _table2,
)


def verdicts(cfg: dict, rows: list[dict], stab: dict, pi_df, sine: dict, long_pi: dict, ga: dict) -> list[Verdict]:
    """Every verdict row of the reproduction (module docstring), claim by claim (:data:`CLAIMS`)."""
    inp = Inputs(
        R={(r["path"], r["controller"]): r for r in rows},
        paths=source_tests(),
        dmax_deg=cfg["model"]["delta_max_deg"],
        band=cfg["sim"]["settle_band"],
        window=cfg["sim"]["steady_window"],
        horizon=cfg["sim"]["horizon"],
        src=cfg["source"],
        stab=stab,
        pi_df=pi_df,
        sine=sine,
        long_pi=long_pi,
        ga=ga,
    )
    out: list[Verdict] = []

    def add(*a, **k) -> None:
        out.append(Verdict(*a, **k).check())

    for claim in CLAIMS:
        claim(inp, add)
    return out
