"""The vehicle-tracking source's claim, Lemma 8.1, checked: the verdict table of the reproduction
(docs/reproductions/vehicle-tracking.md §3), from the geometric test on random states and the
closed-loop grid of :mod:`pfjax.tracking.study`.

The lemma: for ``|gamma| <= gamma_max < pi/2`` and ``|p| < pi/(2 gamma_max)``, ``z~ -> 0`` if and
only if ``phi - p gamma -> 0``. Its two halves are checked apart, on states (where the geometry
decides them exactly) and on the simulated runs inside the bound (where "-> 0" is pfjax's
tolerance over a final window, an assumed criterion; :func:`verdicts` also reads the same runs at
tolerances :data:`TIGHTER` times smaller, which the runs' recorded window maxima allow without
simulating again).
"""

from __future__ import annotations

import math

import pandas as pd

from pfjax.reproduce.run_claims import ADDED
from pfjax.reproduce.verdict import ASSUMED, CONVENTION, Verdict
from pfjax.tracking.lemma import outcomes, read_at

CLAIM = "Lemma 8.1: for |p| < π/(2γ_max), lim z̃ = 0 if and only if lim (φ − pγ) = 0"
#: |phi - p gamma| on a state with z~ = 0 inside the bound counts as 0 up to this, rad: float64
#: rounding of the connection angle (atan2 of coordinates of order 10 m), far above 1e-15.
ROUNDING = 1e-12
#: The factor by which the closed-loop criterion's tolerances are also tightened (same runs).
TIGHTER = 10.0


def verdicts(cfg: dict, geometry: dict, lemma_df: pd.DataFrame) -> list[Verdict]:
    """The verdict rows: the "only if" half on states inside the bound (the source's claim) and
    outside it (pfjax's: the bound is needed), the "if" half on states, and the closed-loop grid
    inside the bound at the configured tolerances and at :data:`TIGHTER` times smaller ones."""
    s = cfg["sim"]
    rows = []
    inside_max = geometry["max_abs_phi_minus_pgamma_when_abs_pgamma_lt_pi_2"]
    convention = "φ ∈ (−π/2, π/2] and d signed (§2): the reading of eq. 8.4 under which the lemma's bound appears"
    rows.append(
        Verdict(
            CLAIM + ' (the "only if" half)',
            "—",
            "random states",
            f"on {geometry['n_states_z_err_0']:,} random states with z̃ = 0 (both modes, every |l|, p and γ_max of the "
            f"grid), those with |pγ| < π/2, as every state inside the bound has, have |φ − pγ| ≤ {ROUNDING:g} rad "
            f"(rounding); {convention}",
            f"max |φ − pγ| = {inside_max:.1e} rad",
            "holds inside the bound",
            "holds" if inside_max <= ROUNDING else "does not hold",
            basis=CONVENTION,
        ).check()
    )
    n_out, rng = geometry["n_counterexamples_abs_pgamma_gt_pi_2"], geometry["counterexample_abs_phi_minus_pgamma_range"]
    rows.append(
        Verdict(
            f'{ADDED}: the "only if" half fails outside the bound',
            "—",
            "random states",
            "every random state with z̃ = 0 and |pγ| > π/2 (possible only where |p| γ_max > π/2) has "
            f"|φ − pγ| > {ROUNDING:g} rad",
            f"{n_out:,} such states, |φ − pγ| from {rng[0]:.6f} to {rng[1]:.6f} rad (π: the other half of the "
            "connection line)"
            if rng
            else "no state with |pγ| > π/2 in the sample",
            "—",
            ("holds" if rng[0] > ROUNDING else "does not hold") if rng else "no verdict",
            basis=CONVENTION,
        ).check()
    )
    wrong = geometry["wrong_distance_min_z_err"]
    rows.append(
        Verdict(
            f'{ADDED}: on states, the "if" half needs the distance too (f d = l)',
            "—",
            "random states",
            "every random state with φ = pγ and the leader on the focus direction at 1.2 to 2 times the focus "
            "distance (d the measured distance of eq. 8.4) has |z̃| > 0: φ = pγ alone does not give z̃ = 0 (the "
            "closed-loop rows test the limits)",
            f"smallest |z̃| = {wrong:.3f} m (0.2 focus distances, where the sampler starts)",
            "—",
            "holds" if wrong > 1e-9 else "does not hold",
        ).check()
    )
    for factor in (1.0, TIGHTER):
        rows.append(_closed_loop(lemma_df, s, cfg["lemma"], abs(cfg["mc"]["l_abs"]), factor))
    return rows


def _closed_loop(lemma_df: pd.DataFrame, s: dict, lem: dict, mc_l: float, factor: float) -> Verdict:
    """The grid's runs inside the bound that ended ok: z~ -> 0 exactly when phi - p gamma -> 0, each
    "-> 0" the largest value over the final window at most the tolerance divided by ``factor``."""
    tol_z, tol_phi = s["tol_z"] / factor, s["tol_phi"] / factor
    runs = lemma_df[lemma_df["inside_bound"].astype(bool)]
    # the runs' own flags at the configured tolerances; read again from the window maxima at others
    masks = outcomes(runs if factor == 1.0 else read_at(runs, tol_z, tol_phi))
    names = {"both": "both", "z_only": "z̃ only", "phi_only": "φ − pγ only", "neither": "neither"}
    counts = {shown: int(masks[k].sum()) for k, shown in names.items()}
    shown = ", ".join(f"{k} {v}" for k, v in counts.items())
    failed = int(masks["failed"].sum())
    ok = runs[~masks["failed"]]
    l_min = min(abs(x) for x in lem["l_abs"])
    why = (
        f"tol_z is {100 * s['tol_z'] / mc_l:g} % of the Monte Carlo's |l| = {mc_l:g} m; tol_phi moves the focus point "
        f"by {1000 * l_min * math.sin(s['tol_phi']):.1f} mm at the grid's smallest |l| ({l_min:g} m); the window is "
        f"{s['window'] * s['k']:g} time constants of the gain k = {s['k']:g} 1/s"
        if factor == 1.0
        else f"the same runs read at tolerances {factor:g} times smaller"
    )
    return Verdict(
        CLAIM,
        "grid",
        f"{len(runs):,} runs inside the bound",
        f"every run inside the bound that ends ok has z̃ → 0 exactly when φ − pγ → 0; → 0: max |z̃| ≤ "
        f"{tol_z:g} m and max |φ − pγ| ≤ {tol_phi:g} rad over the last {s['window']:g} s (assumed: {why})",
        f"{shown} of {len(ok):,} ({failed:,} failed by status, testing neither half)",
        "holds inside the bound",
        ("holds" if counts["z̃ only"] == counts["φ − pγ only"] == 0 else "does not hold") if len(ok) else "no verdict",
        basis=ASSUMED,
    ).check()


__all__ = ["CLAIM", "ROUNDING", "TIGHTER", "verdicts"]
