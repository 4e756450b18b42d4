"""A study's uncertain inputs on the standard-normal space (the isoprobabilistic transform), and
its discrete choices as strata.

Every continuous input ``x_i`` the study draws independently is the image of one standard-normal
coordinate ``u_i`` through its distribution: ``x_i = F_i^{-1}(Φ(u_i))``, so
``U ~ N(0, I)`` gives exactly the study's law of ``X``:

=============  ===================================================================
distribution   ``x = T(u)``
=============  ===================================================================
normal         ``mean + std u``
uniform        ``low + (high - low) Φ(u)``
truncnormal    ``mean + std Φ^{-1}(Φ(a) + (Φ(b) - Φ(a)) Φ(u))``, ``a, b`` the standardised bounds
               (evaluated by ``scipy.stats.truncnorm.ppf``, accurate in the tails)
=============  ===================================================================

Constants are not inputs. A ``choice`` is discrete: every combination of the choices' values is
a *stratum* with probability ``Π 1 / n_values``, and a study's paths are strata too (each path
weighs ``1 / n_paths``, as a study pools them), so ``p = Σ_s w_s p_s`` with each ``p_s`` estimated
on the continuous inputs alone. A sinusoidal slip's phases (uniform on ``[0, 2π)``) are inputs.

**Randomness that is not a list of scalars** is treated conditionally: an Ornstein-Uhlenbeck slip
sequence (its driving Gaussian increments; its ``ou_sigma_deg`` and ``ou_tau_s`` are inputs like
any scalar), sensor noise, a random path's geometry and a circle's random radius are drawn afresh
from the study's own law at every rollout, independent of ``u`` (:mod:`pfjax.rare.study`). Write
``ω`` for them; then ``p = E_u[P(fail | u)]`` with ``P(fail | u) = E_ω 1[g(u, ω) <= 0]``, and

* Monte Carlo and importance sampling stay unbiased: ``E[w(u) 1[g(u, ω) <= 0]] = E_q[w(u) P(fail | u)] = p``
  for any proposal on ``u`` (the weights depend on ``u`` alone); the proposal cannot tilt ``ω``, so a
  failure driven by ``ω`` alone gains no variance reduction (it is as rare under ``q`` as under
  ``φ``);
* subset simulation works on the pair ``(u, ω)``: a fresh ``ω'`` at every candidate is conditional
  sampling with ``ρ = 0`` on ``ω``'s block (its independent draw from its own law leaves that law
  invariant), so the chains keep ``φ(u) π(ω)`` restricted to each level.

The vehicle's friction ``mu`` of the single-track model is a scalar input like the others.
"""

from __future__ import annotations

import itertools
import math
from typing import NamedTuple

import numpy as np
from scipy import special, stats

from pfjax.montecarlo.config import Dist, StudySpec
from pfjax.montecarlo.sampling import SLIP_COLUMNS

#: A sinusoidal slip's phase (rad): uniform on [0, 2 pi), as the study draws it.
PHASE = Dist(dist="uniform", low=0.0, high=2 * math.pi)


class Input(NamedTuple):
    """One continuous uncertain input."""

    name: str  # the study quantity (pfjax.montecarlo.sampling.GIVEN), config units
    key: str  # its study-config key (slip.beta_r_deg, ...)
    dist: Dist  # its distribution


class Stratum(NamedTuple):
    """One combination of the discrete choices."""

    weight: float  # its probability
    path_index: int  # the study's path
    values: dict  # choice quantity -> value (config units)


def _quantities(spec: StudySpec) -> list[tuple[str, str, Dist]]:
    v, s, i = spec.vehicle, spec.slip, spec.initial
    out = [(n, f"vehicle.{n}", getattr(v, n)) for n in ("speed", "L", "delta_max_deg")]
    out += [(n, f"slip.{n}", getattr(s, n)) for n in ("beta_r_deg", "beta_f_deg", *SLIP_COLUMNS[s.kind])]
    if s.kind == "sinusoid":
        out += [("phase_r", "slip.phase_r", PHASE), ("phase_f", "slip.phase_f", PHASE)]
    out += [(n, f"initial.{n}", getattr(i, n)) for n in ("start_along_m", "lateral_offset", "heading_error_deg")]
    if v.model == "st" and v.mu is not None:
        out.append(("mu", "vehicle.mu", v.mu))
    return out


def config_keys(spec: StudySpec) -> dict[str, str]:
    """Study quantity -> its config key (``beta_r_deg`` -> ``slip.beta_r_deg``)."""
    return {n: k for n, k, _ in _quantities(spec)}


def nuisance(spec: StudySpec) -> list[str]:
    """The study keys whose randomness is drawn afresh at every rollout (module docstring)."""
    out = ["slip.kind = 'ou' (its increments)"] if spec.slip.kind == "ou" else []
    if spec.noise.sigma_d > 0 or spec.noise.sigma_theta_e_deg > 0:
        out.append("noise")
    for k, p in enumerate(spec.paths):
        if p.kind == "random":
            out.append(f"paths[{k}] (random geometry)")
        if p.kind == "circle" and p.radius.dist != "constant":
            out.append(f"paths[{k}].radius")
    return out


def study_inputs(spec: StudySpec) -> tuple[list[Input], list[Stratum]]:
    """The study's continuous inputs (in a fixed order: the coordinates of ``u``) and its strata."""
    qs = _quantities(spec)
    inputs = [Input(n, k, d) for n, k, d in qs if d.dist in ("uniform", "normal", "truncnormal")]
    choices = [(n, list(d.values or [])) for n, _, d in qs if d.dist == "choice"]
    strata = []
    for p in range(len(spec.paths)):
        for combo in itertools.product(*(vals for _, vals in choices)):
            w = 1.0 / len(spec.paths) / math.prod([len(vals) for _, vals in choices])
            strata.append(Stratum(w, p, {n: float(x) for (n, _), x in zip(choices, combo)}))
    return inputs, strata


def to_physical(inputs: list[Input], u: np.ndarray) -> dict[str, np.ndarray]:
    """``x = T(u)`` per input (module docstring): ``u`` of shape ``(n, len(inputs))`` -> arrays of ``n``."""
    u = np.asarray(u, dtype=float)
    out = {}
    for j, inp in enumerate(inputs):
        d, z = inp.dist, u[:, j]
        if d.dist == "normal":
            out[inp.name] = d.number("mean") + d.number("std") * z
        elif d.dist == "uniform":
            lo, hi = d.number("low"), d.number("high")
            out[inp.name] = lo + (hi - lo) * special.ndtr(z)
        else:
            mean, std, lo, hi = (d.number(k) for k in ("mean", "std", "low", "high"))
            a, b = (lo - mean) / std, (hi - mean) / std
            out[inp.name] = np.clip(stats.truncnorm.ppf(special.ndtr(z), a, b, loc=mean, scale=std), lo, hi)
    return out


def to_standard(inputs: list[Input], x: dict) -> np.ndarray:
    """The inverse map ``u = Φ^{-1}(F(x))``: per-input arrays (config units) -> ``(n, len(inputs))``."""
    cols = []
    for inp in inputs:
        d, v = inp.dist, np.asarray(x[inp.name], dtype=float)
        if d.dist == "normal":
            cols.append((v - d.number("mean")) / d.number("std"))
        elif d.dist == "uniform":
            lo, hi = d.number("low"), d.number("high")
            cols.append(special.ndtri((v - lo) / (hi - lo)))
        else:
            mean, std, lo, hi = (d.number(k) for k in ("mean", "std", "low", "high"))
            a, b = (lo - mean) / std, (hi - mean) / std
            cols.append(special.ndtri(stats.truncnorm.cdf(v, a, b, loc=mean, scale=std)))
    return np.stack(cols, axis=-1)
