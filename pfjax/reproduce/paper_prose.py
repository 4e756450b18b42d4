"""The paper reproduction report's sentences that are decided from the study's numbers
(:mod:`pfjax.reproduce.paper_report` assembles them): whether the LMI optimum is flat, which norm
comparisons hold, how the controller is evaluated, which PI readings pass the filters, where the
source's gain has its equilibrium, and whether the PI's line error had settled.
"""

from __future__ import annotations

import math

#: the largest relative objective gap (source's K against pfjax's optimum) the report calls a flat
#: optimum: below the precision of the published bounds the objective is made of (γ₂ = 4.07 is
#: printed to ±0.12 %), so no published number could tell the two gains apart
FLAT_REL_TOL = 1e-3
#: |d*| below this (m), half the printed 0.001 mm, counts as zero: the equilibrium is the source's [0, −β_r]
D_STAR_ZERO = 5e-7


def fmt(x, p=3):
    """``x`` with ``p`` decimals; an en dash for a missing or non-finite number."""
    return "–" if x is None or (isinstance(x, float) and not math.isfinite(x)) else f"{x:.{p}f}"


def deg(x):
    """Radians to degrees; None stays None."""
    return None if x is None else math.degrees(x)


def finite(x) -> bool:
    """Whether ``x`` is a number (not None) and finite."""
    return x is not None and math.isfinite(x)


def control_sentence(sim: dict) -> str:
    """How the controller is evaluated, from ``sim.control_every`` and ``sim.dt``."""
    n = sim["control_every"]
    if n == 0:
        return "the controller is evaluated continuously inside every RK4 step, as in the source's Simulink model"
    steps = "step" if n == 1 else f"{n} steps"
    return (
        f"the controller is sampled every {steps} ({1000 * n * sim['dt']:g} ms) and held in between, not evaluated "
        "continuously as in the source's Simulink model"
    )


def objective_gap(syn: dict) -> tuple[float, float, bool]:
    """``(gap, relative gap, flat)``: the objective the source's K certifies minus pfjax's optimum,
    and whether it is within :data:`FLAT_REL_TOL` of that optimum."""
    ours, theirs = syn["ours"]["objective"], syn["source_K_checked_by_pfjax"]["objective"]
    gap = theirs - ours
    rel = gap / abs(ours)
    return gap, rel, abs(rel) <= FLAT_REL_TOL


def flatness(syn: dict, alpha: float, beta: float) -> str:
    """Whether the source's K and pfjax's optimum are equally good for the objective α γ∞² + β γ₂²
    (:func:`objective_gap` within :data:`FLAT_REL_TOL`), as a sentence."""
    gap, rel, flat = objective_gap(syn)
    where = "above" if gap >= 0 else "below"
    head = f"The source's gain certifies an objective {abs(gap):.2e} ({100 * abs(rel):.2g} %) {where} pfjax's optimum"
    if flat:
        return (
            f"{head}, within the {100 * FLAT_REL_TOL:g} % tolerance for a flat optimum: the objective is flat along K_d, so the "
            "K_d difference is where each solver stopped on a flat optimum, not a different formulation."
        )
    return (
        f"{head}, beyond the {100 * FLAT_REL_TOL:g} % tolerance for a flat optimum: the two gains are not equally good for "
        f"this objective (α = {alpha:g}, β = {beta:g}), so the difference in K is not that of a flat optimum."
    )


def norms_vs_bounds(syn: dict) -> str:
    """Each gain's true norms against the source's published bounds and the bounds pfjax certifies
    for that gain: which comparisons hold."""
    o, p, c = syn["ours"], syn["source_published"], syn["source_K_checked_by_pfjax"]
    gains = (
        ("pfjax's K", o["hinf_norm"], o["h2_norm"], o["gamma_inf"], o["gamma_2"]),
        ("the source's K", c["hinf_norm"], c["h2_norm"], c["gamma_inf_certified"], c["gamma_2_certified"]),
    )
    misses, n = [], 0
    for gain, hinf, h2, own_inf, own_2 in gains:
        for norm, v, bounds in (
            ("‖T∞‖∞", hinf, (("the source's γ∞", p["gamma_inf"]), ("pfjax's γ∞ for it", own_inf))),
            ("‖T₂‖₂", h2, (("the source's γ₂", p["gamma_2"]), ("pfjax's γ₂ for it", own_2))),
        ):
            for name, b in bounds:
                n += 1
                if not v < b:
                    misses.append(f"{gain}'s true {norm} {v:.4f} is not below {name} {b:.4g}")
    scope = "each gain's true norms against the source's published bounds and against the bounds pfjax certifies for it"
    if not misses:
        return f"The true norms of both gains are below both sets of bounds ({scope}: all {n} hold)."
    return f"Of the {n} comparisons ({scope}), {n - len(misses)} hold; " + "; ".join(misses) + "."


def pi_choice(f: dict) -> str:
    """The readings passing all four filters and, when exactly one does, how it fares with each
    threshold halved or doubled (with none or several there is no choice to test)."""
    n, names = f["consistent"], ", ".join(f["consistent_readings"])
    if n == 1:
        return (
            f"1 ({names}). With each threshold halved or doubled (the others kept), that reading stays the only one "
            f"in {f['sensitivity_unique']} of {f['sensitivity_cases']} settings."
        )
    which = "none" if n == 0 else f"{n} ({names})"
    return f"{which}. No single reading passes all four, so there is no choice whose sensitivity to test."


def why_readings_fail() -> str:
    """Why a PI reading fails under rear slip (β_r ≠ 0)."""
    return (
        "Why readings fail: with rear slip, d' = 0 needs θₑ = −β_r ≠ 0, so the integral on θₑ ramps at Ki_θ·β_r "
        "for ever and the PI loop has no equilibrium. The best it can do is a quasi-equilibrium in which the "
        "integral on d ramps the other way, which needs a standing offset d_q = (Ki_θ / Ki_d)·β_r — metres for the "
        "readings with a large Ki_θ / Ki_d — approached through a slow pole. "
    )


def paper_case(s: dict) -> str:
    """The source's K at the configured slip: ``"none"`` (no equilibrium: |δ*| beyond δ_max, 1e-9 rad
    of rounding allowed), ``"limit"`` (on δ_max), ``"zero"`` (|d*| below :data:`D_STAR_ZERO`: the
    source's [0, −β_r]) or ``"offset"``."""
    pc, dmax = s["stability"]["paper_case"], math.radians(s["config"]["model"]["delta_max_deg"])
    d, delta = pc["d_star"], pc["delta_star"]
    if not (finite(d) and finite(delta)) or abs(delta) > dmax + 1e-9:
        return "none"
    return "limit" if abs(delta) >= dmax - 1e-9 else "zero" if abs(d) < D_STAR_ZERO else "offset"


def paper_equilibrium(s: dict) -> str:
    """Where the source's K's equilibrium is, or that it has none (:func:`paper_case`)."""
    pc, m, K = s["stability"]["paper_case"], s["config"]["model"], s["config"]["source"]["K"]
    head = f"For the source's K = [{K[0]:g}, {K[1]:g}] and β_r = {m['beta_r_deg']:g}°, β_f = {m['beta_f_deg']:g}°, "
    d, delta, case = pc["d_star"], pc["delta_star"], paper_case(s)
    if case == "none":
        return head + f"there is no equilibrium: it needs |δ*| = {fmt(deg(delta))}° > δ_max = {m['delta_max_deg']:g}°."
    source = "the source's [0, −β_r]" if abs(d) < D_STAR_ZERO else "not the source's [0, −β_r]"
    eig = ", ".join(f"{z[0]:.3f}" for z in pc["eig"])
    if case == "limit":
        eig = f"the unsaturated loop's eigenvalues {eig} 1/s (which do not apply there)"
        limit = " It lies on the steering limit, where the steering saturates and the point is not locally stable."
    else:
        eig, limit = f"eigenvalues {eig} 1/s", ""
    return (
        head + f"the true equilibrium is d* = {1000 * d:.3f} mm, θₑ* = {math.degrees(pc['theta_e_star']):.3f}°, "
        f"δ* = {math.degrees(delta):.3f}°, with {eig} — {source}.{limit}"
    )


def long_pi(lp: dict, cfg: dict) -> str:
    """The PI's line test at the long horizon, and whether |d| had settled by the study's horizon
    (settled: within 5 % of its final value from then on)."""
    from pfjax.reproduce.run_claims import settled

    h, long_h, ts = cfg["sim"]["horizon"], lp["horizon_s"], lp["settle_time_s"]
    window = cfg["sim"]["steady_window"]
    if lp.get("status", "ok") != "ok":
        run = f"Run for {long_h:g} s, the run ends with status {lp['status']}"
    elif not finite(ts):
        run = f"Run for {long_h:g} s, |d| does not settle (it does not stay within 5 % of its final value)"
    elif not settled(True, ts, long_h, window):  # too late for the final window to lie after it: still drifting
        run = (
            f"Run for {long_h:g} s, |d| is within 5 % of its final value only from t = {ts:.1f} s, later than "
            f"{long_h - window:g} s: it has not settled"
        )
    else:
        run = f"Run for {long_h:g} s, |d| settles (within 5 % of its final value from then on) at t = {ts:.1f} s"
    if long_h < h:
        at_h = ""
    elif finite(ts) and ts <= min(h, long_h - window):
        at_h = f"At the {h:g} s horizon the PI's line error has settled. "
    else:
        at_h = f"At the {h:g} s horizon the PI's line error is still drifting. "
    return (
        f"{at_h}{run}; its steady |d| is {lp['steady_abs_d_mm']:.2f} mm (final d = {lp['final_d_mm']:.2f} mm); "
        f"the source reports about {cfg['source']['line_ss_pi_mm']:g} mm."
    )


__all__ = [
    "D_STAR_ZERO",
    "FLAT_REL_TOL",
    "control_sentence",
    "deg",
    "finite",
    "flatness",
    "fmt",
    "long_pi",
    "norms_vs_bounds",
    "objective_gap",
    "paper_case",
    "paper_equilibrium",
    "pi_choice",
    "why_readings_fail",
]
