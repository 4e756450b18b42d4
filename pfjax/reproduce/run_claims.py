"""The path-following source's claims checked on the runs of its tests (:mod:`pfjax.reproduce.path_following`
assembles the verdict table): convergence, the steering limit, speed and accuracy of the designs, the yaw
error, the steering effort, the line test's errors and steering, the sine test's error peaks. Each claim
is ``claim(inputs, add)``: it reads :class:`Inputs` and appends its rows with ``add`` (:data:`Add`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any, NamedTuple

from pfjax.reproduce.verdict import ASSUMED, CONVENTION, FILTERED

CONTROLLERS = ("mixed", "pi")
#: The claim column's mark of a comparison pfjax adds: not among the source's claims
#: (docs/reproductions/path-following.md §6).
ADDED = "pfjax's comparison, not a claim of the source"

#: The Table 3 filters' thresholds, each a reading of the source's words
#: (docs/reproductions/path-following.md §5), halved and doubled by
#: :func:`pfjax.reproduce.paper_runs.pi_filter_stats`: ``sat``, a run "respects the steering limit"
#: if its command is beyond it less than 5 % of the time (fraction); ``delta_deg``, "about 10°" read
#: as 10° to the nearest degree, ±0.5° (deg); ``ss_factor``, "about 8 mm" within a factor 3, loose
#: because the source's horizon is not given.
PI_THRESHOLDS = {"sat": 0.05, "delta_deg": 0.5, "ss_factor": 3.0}
#: "About 8 mm" in the verdict on the PI's line error: within ±50 % of it (the error is of that
#: size, not of another order), a fraction.
ABOUT = 0.5
#: A "non-zero" yaw error: |θₑ| above 1°, far above the integration's rounding and a fifth of the
#: 5° that the equilibrium θₑ* = −β_r predicts (deg).
NONZERO_DEG = 1.0
LABEL = {"mixed": "mixed H2/H∞ (pfjax's K)", "paper-k": "mixed H2/H∞ (source's K)", "pi": "PI (Table 3)"}


def holds(ok: bool) -> str:
    return "holds" if ok else "does not hold"


def mm(x: float) -> str:
    return f"{1000 * x:.2f} mm"


def seconds(x: float) -> str:
    return f"{x:.2f} s" if math.isfinite(x) else "never"


class Inputs(NamedTuple):
    """What the claims are checked on (:mod:`pfjax.reproduce.path_following` describes each input): the runs by (path, controller), the
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


def settled_by(inp: Inputs) -> float:
    """The latest settling time that counts as settled, s (:func:`settled`)."""
    return inp.horizon - inp.window


def settled(ok: bool, settling_time, horizon: float, window: float) -> bool:
    """Whether a run settled: it ends ``ok`` and its settling time (s) is at most ``horizon -
    window``, so that |d| stays within the band over at least the final steady window. A later one
    leaves too little of the run to tell a settled error from one that leaves the band again (a
    periodic error peaking just above it). The Table 3 filter "converges on all three paths" and the
    verdicts on convergence use this one rule."""
    return bool(ok) and _finite(settling_time) and settling_time <= horizon - window + 1e-9


def settle_time(r: dict, inp: Inputs) -> float:
    """The run's settling time (s) if it :func:`settled`, else +inf."""
    t = r["settling_time"]
    return t if settled(r["status"] == "ok", t, inp.horizon, inp.window) else math.inf


def converge(inp: Inputs, add: Add) -> None:
    """Both controllers bring the robot onto all three paths: each run settles into the band and
    stays there over at least the final steady window (:func:`settle_time`). The PI's rows check
    the filter "converges on all three paths" that chose its reading of Table 3
    (:data:`pfjax.reproduce.verdict.FILTERED`)."""
    R, paths, band = inp.R, inp.paths, inp.band
    claim = "Both controllers bring the robot onto all three paths"
    for p in paths:
        for c in CONTROLLERS:
            r = R[(p, c)]
            t = r["settling_time"]
            late = r["status"] == "ok" and _finite(t) and not math.isfinite(settle_time(r, inp))
            add(
                claim,
                p,
                LABEL[c],
                f"the run ends ok and |d| stays within {100 * band:g} cm from its settling time on, "
                f"over at least the final {inp.window:g} s (settling time ≤ {settled_by(inp):g} s: "
                f"the {inp.horizon:g} s horizon, assumed)",
                seconds(t if _finite(t) else math.inf)
                + (f", later than {settled_by(inp):g} s" if late else "")
                + ("" if r["status"] == "ok" else f", status {r['status']}"),
                "—",
                holds(math.isfinite(settle_time(r, inp))),
                **(dict(basis=FILTERED, also=ASSUMED) if c == "pi" else dict(basis=ASSUMED)),
            )


def steering_limit(inp: Inputs, add: Add) -> None:
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
                holds(peak <= dmax_deg + 1e-9),
                basis="assumed",
            )


def _mixed_below_pi(
    inp: Inputs,
    add: Add,
    claim: str,
    key: str,
    criterion: str,
    show: Callable[[float], str],
    bases: Callable[[str, float], dict] = lambda p, m: {},
) -> None:
    """One row per path: the claim holds where the mixed design's ``key`` is below the PI's; "no
    verdict" where either is NaN (the run gives no value; the status says why). ``bases(path,
    mixed value)`` gives the row's ``basis`` / ``also``."""
    for p in inp.paths:
        m, q = inp.R[(p, "mixed")][key], inp.R[(p, "pi")][key]
        nan = [c for c, x in (("mixed", m), ("PI", q)) if x is None or math.isnan(x)]
        failed = _failed(inp, (p, "mixed"), (p, "pi"))
        shown = f"{show(m)} vs {show(q)}" if not nan else f"no value for {' and '.join(nan)} (NaN)"
        shown += f" ({failed})" if failed and not nan else ""
        verdict = holds(m < q) if not (nan or failed) else "no verdict"
        add(claim, p, "mixed vs PI", criterion, shown, "—", verdict, **bases(p, m))


def faster(inp: Inputs, add: Add) -> None:
    """The mixed design converges faster than the PI, per path: settling times as in
    :func:`converge` (a run that did not settle never did); "no verdict" where neither settled or
    either settling time is NaN."""
    criterion = (
        f"settling time into the {100 * inp.band:g} cm band (settled by {settled_by(inp):g} s of the "
        f"{inp.horizon:g} s horizon, assumed, as above; else never): mixed < PI"
    )
    claim = "The mixed design converges faster than the PI"
    for p in inp.paths:
        m, q = inp.R[(p, "mixed")], inp.R[(p, "pi")]
        nan = [c for c, r in (("mixed", m), ("PI", q)) if r["settling_time"] is None or math.isnan(r["settling_time"])]
        if nan:
            shown = f"no value for {' and '.join(nan)} (NaN)"
            add(claim, p, "mixed vs PI", criterion, shown, "—", "no verdict", basis=ASSUMED)
            continue
        tm, tq = settle_time(m, inp), settle_time(q, inp)
        verdict = "no verdict" if math.isinf(tm) and math.isinf(tq) else holds(tm < tq)
        add(claim, p, "mixed vs PI", criterion, f"{seconds(tm)} vs {seconds(tq)}", "—", verdict, basis=ASSUMED)


def line_filter_decides(inp: Inputs, mixed_mm: float) -> bool:
    """Whether the Table 3 filter "line steady |d| within a factor f of the source's" alone decides
    the comparison with the mixed design's line error ``mixed_mm`` (mm): every PI reading it admits
    lies on one side of that value. False where the readings carry no thresholds (no filter chose)."""
    th = inp.pi_df.attrs.get("filters", {}).get("thresholds")
    if not th:
        return False
    f, src = th["ss_factor"], inp.src["line_ss_pi_mm"]
    return not src / f <= mixed_mm <= src * f


def more_accurate(inp: Inputs, add: Add) -> None:
    """The mixed design converges more accurately than the PI, per path, at the assumed horizon
    (the PI is still drifting there: :func:`line_pi_error`). On the line the row is also the filter
    that chose the PI's reading where that filter alone decides it (:func:`line_filter_decides`)."""
    criterion = (
        f"steady |d| (mean over the last {inp.window:g} s of the {inp.horizon:g} s horizon, assumed): mixed < PI"
    )

    def bases(p: str, m: float) -> dict:
        if p == "line" and _finite(m) and line_filter_decides(inp, 1000 * m):
            return dict(basis=FILTERED, also=ASSUMED)
        return dict(basis=ASSUMED)

    _mixed_below_pi(
        inp, add, "The mixed design converges more accurately than the PI", "steady_abs_d", criterion, mm, bases
    )


def yaw_error(inp: Inputs, add: Add) -> None:
    """The mixed design has the smaller yaw error, per path: pfjax's comparison (:data:`ADDED`), at
    the assumed horizon (on the sine the order changes with it)."""
    criterion = (
        f"steady |θₑ| (mean over the last {inp.window:g} s of the {inp.horizon:g} s horizon, assumed): mixed < PI"
    )
    _mixed_below_pi(
        inp,
        add,
        f"{ADDED}: the mixed design has the smaller yaw error",
        "steady_abs_theta_e_rad",
        criterion,
        lambda rad: f"{math.degrees(rad):.3f}°",
        lambda p, m: dict(basis=ASSUMED),
    )


def effort(inp: Inputs, add: Add) -> None:
    """The mixed design needs less steering effort than the PI, per path: pfjax's comparison
    (:data:`ADDED`), over the assumed horizon and, for the applied steering and the time beyond the
    limit, at the assumed steering limit. Equal values (both clipped at the limit) give "no verdict"."""
    R, paths = inp.R, inp.paths
    claim = f"{ADDED}: the mixed design needs less steering effort than the PI"
    for p in paths:
        m, q = R[(p, "mixed")], R[(p, "pi")]
        failed = _failed(inp, (p, "mixed"), (p, "pi"))
        for what, key, fmt in (
            (
                "peak commanded steering max |δ_cmd| (before saturation)",
                "max_abs_delta_cmd",
                lambda v: f"{math.degrees(v):.1f}°",
            ),
            (
                f"peak applied steering max |δ| (after the ±{inp.dmax_deg:g}° saturation, assumed)",
                "max_abs_delta",
                lambda v: f"{math.degrees(v):.1f}°",
            ),
            ("steering energy ∫δ² dt of the applied steering", "steer_energy", lambda v: f"{v:.4f} rad²·s"),
            (
                f"time with the command beyond the ±{inp.dmax_deg:g}° limit (assumed)",
                "sat_fraction",
                lambda v: f"{100 * v:.1f} % of the run",
            ),
        ):
            mv, qv = m[key], q[key]
            add(
                claim,
                p,
                "mixed vs PI",
                f"{what}, over the {inp.horizon:g} s horizon (assumed): mixed < PI",
                f"{fmt(mv)} vs {fmt(qv)}" + (f" ({failed})" if failed else "") + (", equal" if mv == qv else ""),
                "—",
                holds(mv < qv) if not (mv == qv or failed) else "no verdict",
                basis=ASSUMED,
            )


def line_mixed_error(inp: Inputs, add: Add) -> None:
    """Line: the mixed design's steady-state position error below the source's bound."""
    R, window, src, stab = inp.R, inp.window, inp.src, inp.stab
    claim = f"Line: steady-state position error below {src['line_ss_mixed_mm_below']:g} mm (mixed)"
    for c in ("mixed", "paper-k"):
        r, failed = R[("line", c)], _failed(inp, ("line", c))
        add(
            claim,
            "line",
            LABEL[c],
            f"steady |d| (mean over the last {window:g} s) < {src['line_ss_mixed_mm_below']:g} mm",
            f"{mm(r['steady_abs_d'])} (equilibrium d* = {mm(stab['paper_case']['d_star'])} for the source's K)"
            + (f" ({failed})" if failed else ""),
            f"< {src['line_ss_mixed_mm_below']:g} mm",
            holds(1000 * r["steady_abs_d"] < src["line_ss_mixed_mm_below"]) if not failed else "no verdict",
        )


def line_pi_error(inp: Inputs, add: Add) -> None:
    """Line: the PI's steady-state position error near the source's, at the (assumed) horizon and
    settled. The first row checks the quantity of the filter "line steady |d| within a factor 3 of
    the source's" that chose the PI's reading of Table 3 (:data:`pfjax.reproduce.verdict.FILTERED`)."""
    R, window, src, long_pi = inp.R, inp.window, inp.src, inp.long_pi
    claim = f"Line: steady-state position error about {src['line_ss_pi_mm']:g} mm (PI)"
    tol = ABOUT
    r, failed = R[("line", "pi")], _failed(inp, ("line", "pi"))
    ratio = 1000 * r["steady_abs_d"] / src["line_ss_pi_mm"]
    add(
        claim,
        "line",
        LABEL["pi"],
        f"steady |d| at the {inp.horizon:g} s horizon (assumed; mean over the last "
        f"{window:g} s) within ±{100 * tol:g} % of {src['line_ss_pi_mm']:g} mm",
        mm(r["steady_abs_d"]) + (f" ({failed})" if failed else ""),
        f"about {src['line_ss_pi_mm']:g} mm",
        ("reproduced" if abs(ratio - 1) <= tol else "not reproduced") if not failed else "no verdict",
        basis=FILTERED,
        also=ASSUMED,
    )
    ratio = long_pi["steady_abs_d_mm"] / src["line_ss_pi_mm"]
    h, t = long_pi["horizon_s"], long_pi["settle_time_s"]
    # settled as the convergence rows count it: early enough that the final window lies after it
    ok = settled(long_pi["status"] == "ok", t, h, window)
    shown = f"{long_pi['steady_abs_d_mm']:.2f} mm, " + (
        f"settled from t = {seconds(t)}" if ok else f"not settled by {h - window:g} s ({_long_state(long_pi, t)})"
    )
    add(
        claim,
        "line",
        LABEL["pi"],
        f"steady |d| once settled (a {h:g} s run: mean over its last {window:g} s) within ±{100 * tol:g} % of "
        f"{src['line_ss_pi_mm']:g} mm; settled = |d| within 5 % of its final value from then on, from "
        f"{h - window:g} s at the latest (else no verdict: the run is still drifting)",
        shown,
        f"about {src['line_ss_pi_mm']:g} mm",
        ("reproduced" if abs(ratio - 1) <= tol else "not reproduced") if ok else "no verdict",
    )


def _long_state(long_pi: dict, t) -> str:
    """Why the long PI run did not settle in time: its status, or when it entered the 5 % band."""
    if long_pi["status"] != "ok":
        return f"status {long_pi['status']}"
    return f"within 5 % of its final value only from t = {seconds(t)}"


def line_steering(inp: Inputs, add: Add) -> None:
    """Line: the steering settles near the source's angle. The angle fixed the sign of the front slip
    (docs/reproductions/path-following.md §1), so every row agrees by construction; the PI's row
    is also the filter "line steering within 0.5° of the source's angle" that chose its reading of
    Table 3, on the same run (:data:`pfjax.reproduce.verdict.FILTERED`, the stronger of the two)."""
    R, src = inp.R, inp.src
    claim = f"Line: the steering settles at about {src['line_delta_deg']:g}° to compensate the slip"
    for c in CONTROLLERS:
        fd, failed = math.degrees(R[("line", c)]["final_delta"]), _failed(inp, ("line", c))
        add(
            claim,
            "line",
            LABEL[c],
            f"final applied steering within {PI_THRESHOLDS['delta_deg']:g}° of {src['line_delta_deg']:g}°",
            f"{fd:.3f}°" + (f" ({failed})" if failed else ""),
            f"about {src['line_delta_deg']:g}°",
            holds(abs(fd - src["line_delta_deg"]) < PI_THRESHOLDS["delta_deg"]) if not failed else "no verdict",
            **(dict(basis=FILTERED, also=CONVENTION) if c == "pi" else dict(basis=CONVENTION)),
        )


def line_yaw(inp: Inputs, add: Add) -> None:
    """Line: the yaw error settles at a non-zero value."""
    R = inp.R
    claim = "Line: the yaw error settles at a non-zero value"
    for c in CONTROLLERS:
        te, failed = math.degrees(R[("line", c)]["final_theta_e"]), _failed(inp, ("line", c))
        add(
            claim,
            "line",
            LABEL[c],
            f"final |θₑ| > {NONZERO_DEG:g}° (the equilibrium needs θₑ* = −β_r)",
            f"{te:.3f}°" + (f" ({failed})" if failed else ""),
            "non-zero",
            holds(abs(te) > NONZERO_DEG) if not failed else "no verdict",
        )


def _finite(x) -> bool:
    """``x`` is a finite number (a summary read back from JSON holds ``None`` for NaN)."""
    return x is not None and math.isfinite(x)


def _failed(inp: Inputs, *runs: tuple[str, str]) -> str:
    """The runs ``(path, controller)`` among ``runs`` that did not end ``ok``, as the row shows them
    (``"mixed H2/H∞ (pfjax's K): status diverged"``); ``""`` if every one did. A failed run's
    metrics stop at its failure, so a claim compared on them gets "no verdict", as the convergence
    rows do."""
    bad = [f"{LABEL.get(c, c)}: status {inp.R[(p, c)]['status']}" for p, c in runs if inp.R[(p, c)]["status"] != "ok"]
    return "; ".join(bad)


def sine_peaks(inp: Inputs, add: Add) -> None:
    """Sine: where the errors peak against the curvature. On y = sin x the |κ| maxima lie π m apart
    in x, so a point placed at random is a median π/4 m from the nearest one: the first row's
    threshold is that chance level, and passing it is weak evidence. A median that is not finite (no
    |d| peak after 5 s, or no maximum to measure to) gives "no verdict", with the reason."""
    sine = inp.sine
    claim = "Sine: the errors grow where the curvature changes fastest (near the extrema)"
    to_k, to_dk = sine["median_peak_to_kappa_max_m"], sine["median_peak_to_dkappa_max_m"]
    chance = math.pi / 4

    failed = _failed(inp, ("sine", "mixed")) if ("sine", "mixed") in inp.R else ""
    if failed:  # the peaks of a run that stopped at its failure
        to_k = to_dk = math.nan

    def undecided(what: str) -> str:
        if failed:
            return f"no verdict on a failed run ({failed})"
        if not sine.get("peak_x", [None]):
            return "no |d| peak after 5 s (no median)"
        return f"no {what} maximum in x after 5 s (no median)"

    add(
        claim,
        "sine",
        LABEL["mixed"],
        "after 5 s, the median distance in x from a |d| peak to the nearest extremum of the sine (|κ| maximum; "
        f"they are π m apart) is below π/4 = {chance:.2f} m, the median for points placed at random "
        "(chance level: weak evidence)",
        f"median distance {to_k:.2f} m" if _finite(to_k) else undecided("|κ|"),
        "near the extrema",
        holds(to_k < chance) if _finite(to_k) else "no verdict",
    )
    add(
        claim,
        "sine",
        LABEL["mixed"],
        "the |d| peaks lie closer to the |dκ/ds| maxima (curvature changing fastest) than to the |κ| maxima",
        f"{to_dk:.2f} m vs {to_k:.2f} m"
        if _finite(to_k) and _finite(to_dk)
        else undecided("|κ|" if not _finite(to_k) else "|dκ/ds|"),
        "where κ changes fastest",
        holds(to_dk < to_k) if _finite(to_k) and _finite(to_dk) else "no verdict",
    )
