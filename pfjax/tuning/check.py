"""Is a gain vector a local minimum of a tuning cost? First- and second-order checks in the box.

At ``theta`` (normalised ``z = (theta - lower) / (upper - lower)``) with gradient ``g`` (per box
width, :func:`pfjax.numerics.autodiff.value_and_grad`):

* a coordinate is **active** when it sits on a bound and ``g`` pushes against it (``z_i = 0``,
  ``g_i > 0`` or ``z_i = 1``, ``g_i < 0``); the rest are **free**, ``F``;
* the **projected gradient** is ``g`` with the active coordinates zeroed (zero at a smooth KKT
  point of the box-constrained problem);
* the **Hessian** on the free coordinates is the central difference of gradients,
  ``H[:, i] = (g(z + h e_i) - g(z - h e_i)) / (2 h)``, symmetrised (``2 |F|`` more gradient
  evaluations; ``h`` in box units; evaluated with the gradient at ``z`` in one program where no
  coordinate can be active, or where the pairs of those that can cost little: ``rollout_steps`` of
  :func:`check_point`); ``quadratic_model`` says whether it is positive definite
  (smallest eigenvalue above ``1e-8`` of the largest magnitude), ``indefinite`` or ``singular``,
  and the **Newton decrease** ``0.5 g_F^T H_F^{-1} g_F / |J|`` what one Newton step of that model
  would gain;
* the **probes**: the cost at ``clip(z + r u)`` for ``u`` in ``±e_i`` and ``(±e_i ± e_j)/sqrt(2)``
  (``2 D^2`` directions) and each radius ``r`` of ``radii`` (box units), value only.

Tuning costs built on ``|d|`` (IAE, ITAE) are piecewise smooth, and their minima often sit on a
kink (where the error trajectory gains or loses a zero crossing): there the gradient jumps, its
norm is not small from either side, and a difference of gradients across the kink reads as a
large curvature. So the **verdict** comes from the probes: ``"local minimum"`` when no probe
lowers the cost by more than ``rtol |J|`` (default 1e-4: a local minimum within the box at the
probed scales, up to 0.01 % of the cost),
``"not a local minimum"`` otherwise (``best_probe`` gives the direction and the decrease), and
``"flat"`` when every probe costs the same as the point (to 1e-12 relative) and the gradient is
exactly zero: a plateau, such as gains at which every run fails at once and costs the fail
penalty, where the probes cannot tell a minimum from its surroundings (none is claimed). The
gradient and Hessian are reported beside it as the smooth picture. A cost or gradient that is not
finite at ``theta`` (a failed rollout in the batch) is data, not an error: the verdict is
``"non-finite cost"`` where the cost itself is not finite, and the quadratic model is
``"non-finite"`` where a gradient is not.
"""

from __future__ import annotations

import functools
import json
from collections.abc import Callable
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from pfjax import errors
from pfjax.numerics import autodiff

VERDICTS = ("local minimum", "not a local minimum", "flat", "non-finite cost")
#: :func:`check_point`'s probe radii, box units.
RADII = (1e-3, 1e-2)


class CheckResult(NamedTuple):
    """The outcome of :func:`check_point` (normalised quantities per box width)."""

    theta: np.ndarray  # (D,) the point checked (gain units)
    cost: float  # its cost
    gradient: np.ndarray  # (D,) dJ/dtheta (cost units per gain unit)
    projected_gradient: np.ndarray  # (D,) dJ/dz with the active coordinates zeroed (cost units per box width)
    active: np.ndarray  # (D,) int: -1 on the lower bound, +1 on the upper bound (pushed against), 0 free
    hessian: np.ndarray  # (|F|, |F|) d2J/dz2 on the free coordinates (cost units per box width^2)
    eigenvalues: np.ndarray  # (|F|,) of ``hessian``, ascending
    quadratic_model: str  # positive definite | indefinite | singular | none (no free coordinate) | non-finite
    newton_decrease: float  # 0.5 g_F^T H_F^-1 g_F / |J| (nan unless H_F is positive definite)
    probe_decrease: float  # largest relative decrease (J - J_probe) / |J| over the probes (<= 0: none lower)
    best_probe: np.ndarray  # (D,) displacement of that probe, gain units
    verdict: str  # one of VERDICTS
    n_rollouts: int  # rollouts simulated (gradient, Hessian and probe evaluations, times the batch)
    n_forward_passes: int  # forward-pass equivalents (module pfjax.tuning.multistart)


def probe_directions(D: int) -> np.ndarray:
    """``(2 D^2, D)`` unit directions: ``±e_i`` and ``(±e_i ± e_j) / sqrt(2)`` for ``i < j``."""
    dirs = [s * e for e in np.eye(D) for s in (1.0, -1.0)]
    for i in range(D):
        for j in range(i + 1, D):
            for si in (1.0, -1.0):
                for sj in (1.0, -1.0):
                    u = np.zeros(D)
                    u[i], u[j] = si, sj
                    dirs.append(u / np.sqrt(2.0))
    return np.asarray(dirs)


def check_point(
    cost: Callable,
    theta,
    lower,
    upper,
    *,
    h: float = 1e-4,
    radii=RADII,
    rtol: float = 1e-4,
    n_per_eval: int = 1,
    mode: str = "auto",
    rollout_steps: int | None = None,
) -> CheckResult:
    """First- and second-order check of ``theta`` as a minimiser of ``cost`` in the box (module docstring).

    Args:
        cost: ``theta (D,) -> scalar``, traceable.
        theta: ``(D,)`` point inside ``[lower, upper]``.
        lower: ``(D,)`` lower corner of the box.
        upper: ``(D,)`` upper corner of the box.
        h: finite-difference step of the Hessian, box units.
        radii: probe radii, box units.
        rtol: a probe lower than ``J - rtol |J|`` refutes a local minimum.
        n_per_eval: rollouts per ``cost`` call, for the budget count.
        mode: differentiation mode.
        rollout_steps: the simulated rollout-steps of one ``cost`` call (its runs times their
            steps), when known. The gradients at ``z`` and at ``z ± h e_i`` are then evaluated in
            one call of one program (traced and compiled once: seconds, where running a check's
            batch takes milliseconds) if no coordinate of ``z`` is on a bound, or if the pairs of
            the coordinates on a bound, which are not used when the gradient makes them active,
            add at most :data:`~pfjax.tuning.gradient.PAD_FORWARD_PASSES` forward-pass
            rollout-steps. Otherwise (and for ``None``, unless no coordinate is on a bound): the
            gradient at ``z`` first, then the free coordinates' pairs, two programs. The unused
            pairs are not counted in ``n_rollouts`` (as a tuner's padded chains are not).
    """
    from pfjax.numerics.autodiff import forward_passes_per_gradient
    from pfjax.tuning.gradient import pads_cheaply

    th, lo, hi = _checked_point(theta, lower, upper, h, rtol)
    radii = [errors.number("radii", r, positive=True, high=1.0) for r in np.ravel(radii)]
    dtype = jnp.result_type(float)
    span = hi - lo
    lo_j, span_j = jnp.asarray(lo, dtype), jnp.asarray(span, dtype)
    vg = lambda Z: _values_and_gradients(Z, lo_j, span_j, cost=cost, mode=mode)
    z = np.clip((th - lo) / span, 0.0, 1.0)
    fpp = forward_passes_per_gradient(lo.size, mode)
    unused = 2 * int(np.sum(_on_bound(z))) * fpp  # forward passes of the pairs that may go unused
    together = not unused or pads_cheaply(unused, rollout_steps)
    J, g, active, H, eig = _gradient_and_hessian(vg, z, h, dtype, together)
    pg = np.where(active == 0, g, 0.0)
    free = np.flatnonzero(active == 0)
    model, decrease = _quadratic_model(J, pg[free], H, eig)
    Zp, Jp = _probes(cost, z, radii, lo_j, span_j, dtype)
    i = int(np.argmin(Jp))  # a probe whose cost is not finite is inf (_probes): never the lowest
    jp = float(Jp[i])
    if J != 0 and np.isfinite(J) and np.isfinite(jp):
        probe_dec = (J - jp) / abs(J)
    else:  # a zero cost or a probe not finite: no relative decrease to state, only whether one is lower
        probe_dec = 0.0 if not jp < J else np.inf
    verdict = "not a local minimum" if probe_dec > rtol else "local minimum"
    if np.all(np.abs(Jp - J) <= 1e-12 * abs(J)) and not np.any(g):  # two programs: a rounding apart
        verdict = "flat"
    if not np.isfinite(J):
        verdict, probe_dec = "non-finite cost", float("nan")
    n_grad = 1 + 2 * free.size
    return CheckResult(
        th,
        J,
        g / span,
        pg,
        active.astype(int),
        H,
        eig,
        model,
        decrease,
        probe_dec,
        span * (Zp[i] - z),
        verdict,
        (n_grad + len(Zp)) * n_per_eval,
        (n_grad * fpp + len(Zp)) * n_per_eval,
    )


@functools.partial(jax.jit, static_argnames=("cost", "mode"))
def _values_and_gradients(Z, lo, span, *, cost, mode):
    """``cost(lo + span z)`` and its gradient in ``z`` at each row of ``Z`` (box units); one program
    per cost function, mode and batch shape, so checks of several points of one problem share it."""
    return jax.vmap(autodiff.value_and_grad(lambda z: cost(lo + span * z), mode=mode))(Z)


def _checked_point(theta, lower, upper, h: float, rtol: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(theta, lower, upper)`` as flat float64 arrays: the box's corners finite with ``lower <
    upper``, ``theta`` of its size, finite and inside it (a point outside would be checked where
    the box clips it); :class:`~pfjax.errors.InputError` naming the argument otherwise, or a bad
    ``h`` or ``rtol``."""
    lo, hi = errors.box(lower, upper)
    th = np.asarray(theta, np.float64).reshape(-1)
    if th.shape != (lo.size,):
        raise errors.InputError(f"theta: {th.size} values, expected {lo.size}", "theta")
    bad = np.flatnonzero(~np.isfinite(th) | (th < lo) | (th > hi))
    if bad.size:
        i = int(bad[0])
        raise errors.InputError(f"theta[{i}]: {th[i]:g} is not a finite value in [{lo[i]:g}, {hi[i]:g}]", "theta")
    errors.number("h", h, positive=True, high=0.1)
    errors.number("rtol", rtol, nonnegative=True)
    return th, lo, hi


#: A coordinate within this of a bound (box units) is on it (:func:`_gradient_and_hessian`).
_ON_BOUND = 1e-12


def _on_bound(z: np.ndarray) -> np.ndarray:
    """``(D,)`` bool: the coordinates on a bound of the box, the only ones that can be active."""
    return (z <= _ON_BOUND) | (z >= 1 - _ON_BOUND)


def _gradient_and_hessian(vg, z: np.ndarray, h: float, dtype, together: bool = False):
    """At ``z`` (box units): cost ``J``, gradient ``g``, active bounds (-1 lower, +1 upper, 0 free),
    and the Hessian on the free coordinates by central differences of the gradient,
    ``H_ij = (g_j(z + h e_i) - g_j(z - h e_i)) / 2h`` (symmetrised), with its eigenvalues.

    ``together``: the gradients at ``z`` and at ``z ± h e_i`` of every coordinate in one call of
    ``vg`` (one program), the pairs of the coordinates found active then dropped; else ``z``'s
    first and the free coordinates' pairs after (two programs: the batches differ in size). Each
    row is an independent lane of the vmapped program, so both give the same numbers up to the
    rounding of a differently compiled program."""
    D = z.size
    if together:
        E = np.eye(D) * h
        J, G_all = vg(jnp.asarray(np.concatenate([z[None], z + E, z - E]), dtype))
        G_all = np.asarray(G_all, np.float64)
        J, g = float(J[0]), G_all[0]
    else:
        J, g = vg(jnp.asarray(z[None], dtype))
        J, g = float(J[0]), np.asarray(g[0], np.float64)
    active = np.where((z <= _ON_BOUND) & (g > 0), -1, np.where((z >= 1 - _ON_BOUND) & (g < 0), 1, 0))
    free = np.flatnonzero(active == 0)
    if not free.size:
        return J, g, active, np.zeros((0, 0)), np.zeros(0)
    if together:
        G = np.concatenate([G_all[1 : 1 + D][free], G_all[1 + D :][free]])
    else:
        E = np.eye(D)[free] * h
        _, G = vg(jnp.asarray(np.concatenate([z + E, z - E]), dtype))
        G = np.asarray(G, np.float64)
    with np.errstate(invalid="ignore"):  # inf - inf where a gradient is not finite: nan, reported as data
        H = (G[: free.size, free] - G[free.size :, free]) / (2 * h)
        H = 0.5 * (H + H.T)
    eig = np.linalg.eigvalsh(H) if np.all(np.isfinite(H)) else np.full(free.size, np.nan)
    return J, g, active, H, eig


def _quadratic_model(J: float, gf: np.ndarray, H: np.ndarray, eig: np.ndarray) -> tuple[str, float]:
    """The local quadratic model's kind on the free coordinates (``positive definite``, ``indefinite``,
    ``singular``, ``none``) and, when positive definite, its predicted relative decrease
    ``g^T H^-1 g / (2 |J|)``."""
    if not eig.size:
        return "none", float("nan")
    if not (np.isfinite(J) and np.all(np.isfinite(eig)) and np.all(np.isfinite(gf))):
        return "non-finite", float("nan")
    scale = max(float(np.max(np.abs(eig))), 1e-300)
    if eig[0] > 1e-8 * scale:
        return "positive definite", 0.5 * float(gf @ np.linalg.solve(H, gf)) / max(abs(J), 1e-300)
    if eig[0] < -1e-8 * scale:
        return "indefinite", float("nan")
    return "singular", float("nan")


def _probes(cost, z: np.ndarray, radii, lo_j, span_j, dtype) -> tuple[np.ndarray, np.ndarray]:
    """The probe points at each radius around ``z`` (clipped to the box) and their costs (non-finite: inf)."""
    from pfjax.tuning.multistart import box_value

    U = probe_directions(z.size)
    Zp = np.clip(np.concatenate([z + r * U for r in radii]), 0.0, 1.0)
    Jp = np.asarray(jax.jit(box_value, static_argnames=("cost",))(jnp.asarray(Zp, dtype), lo_j, span_j, cost=cost))
    return Zp, np.where(np.isfinite(Jp), Jp, np.inf)


def parse_gains(gains, fields, sizes, lower, upper, *, key: str = "check") -> np.ndarray:
    """Gains as a flat ``theta``: a ``{field: value}`` mapping (a vector field as a list), its JSON
    text, or numbers in field order (a sequence or a comma-separated string); every value finite
    and inside the box ``[lower, upper]``. :class:`~pfjax.errors.InputError` naming ``key`` otherwise."""
    lo, hi = np.asarray(lower, np.float64), np.asarray(upper, np.float64)
    names = ", ".join(f"{f}[{n}]" if n > 1 else f for f, n in zip(fields, sizes))
    if isinstance(gains, str):
        text = gains.strip()
        if text.startswith("{"):
            try:
                gains = json.loads(text)
            except json.JSONDecodeError as e:
                raise errors.InputError(f"{key}: not valid JSON ({e.msg}): {text!r}", key) from None
        else:
            items = [v.strip() for v in text.replace(";", ",").split(",")]
            if "" in items:
                raise errors.InputError(f"{key}: an empty item in {text!r}; expected {names}", key)
            try:
                gains = [float(v) for v in items]
            except ValueError:
                raise errors.InputError(
                    f"{key}: expected numbers ({names}) or a JSON object, got {text!r}", key
                ) from None
    if isinstance(gains, dict):
        unknown = sorted(set(gains) - set(fields))
        missing = [f for f in fields if f not in gains]
        if unknown or missing:
            wrong = [
                f"{', '.join(missing)} missing" if missing else "",
                f"{', '.join(unknown)} unknown" if unknown else "",
            ]
            raise errors.InputError(f"{key}: {'; '.join(w for w in wrong if w)}; expected {names}", key)
        flat = []
        for f, n in zip(fields, sizes):
            v = np.ravel(np.asarray(gains[f], dtype=object))
            if v.size != n:
                raise errors.InputError(f"{key}: {f} has {v.size} values, expected {n}", key)
            flat += list(v)
        gains = flat
    values = list(np.ravel(np.asarray(gains, dtype=object)))
    if len(values) != lo.size:
        raise errors.InputError(f"{key}: {len(values)} values, expected {lo.size} ({names})", key)
    th = np.array([errors.number(key, v) for v in values], np.float64)
    out = (th < lo) | (th > hi)
    if out.any():
        i = int(np.flatnonzero(out)[0])
        element = [f"{f}[{j}]" if n > 1 else f for f, n in zip(fields, sizes) for j in range(n)][i]
        raise errors.InputError(
            f"{key}.{element}: {th[i]:g} outside the tuning box [{lo[i]:g}, {hi[i]:g}]; bounds {lo.tolist()} to "
            f"{hi.tolist()}",
            key,
        )
    return th


def coordinate_names(fields, sizes) -> list[str]:
    """The tuning box's coordinates by name: a scalar field by its name, a vector field's elements
    as ``K[0]``, ``K[1]``, ... (``sizes``: each field's number of elements)."""
    return [f"{f}[{i}]" if n > 1 else f for f, n in zip(fields, sizes) for i in range(n)]


def as_dict(r: CheckResult, fields, sizes) -> dict:
    """``r`` as JSON-ready values, coordinates named by the box's ``fields`` (:func:`coordinate_names`)."""
    names = coordinate_names(fields, sizes)
    return {
        "verdict": r.verdict,
        "gradient": dict(zip(names, r.gradient.tolist())),
        "projected_gradient_norm": float(np.linalg.norm(r.projected_gradient)),
        "active_bounds": {f: ("lower" if a < 0 else "upper") for f, a in zip(names, r.active) if a != 0},
        "free": [f for f, a in zip(names, r.active) if a == 0],
        "hessian_eigenvalues": r.eigenvalues.tolist(),
        "quadratic_model": r.quadratic_model,
        "newton_decrease_relative": float(r.newton_decrease) if np.isfinite(r.newton_decrease) else None,
        "probe_decrease_relative": float(r.probe_decrease),
        "best_probe": dict(zip(names, r.best_probe.tolist())),
        "n_rollouts": int(r.n_rollouts),
        "n_forward_passes": int(r.n_forward_passes),
    }
