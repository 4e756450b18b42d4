"""Failure points of the gradient falsifier (:mod:`pfjax.falsification`) on the estimators'
standard-normal space: gradients find the failure region, the importance sampler weighs it.

For one stratum of a study with constant slip, :func:`pfjax.falsification.falsify` ascends the
failure metric (``rare_event.metric``, ``late_max_abs_d`` where the falsifier has no such
objective) over constant slips ``|β_a| < A`` and start errors in a box, with every other input at
its median (``u_i = 0``). The box is the image of ``[-U, U]`` (``U = 6``, default) per input:
``A = max_a max(|T_a(-U)|, |T_a(U)|)`` deg, the start offset and heading error in
``[T(-U), T(U)]`` (their whole support when uniform). The falsifier's worst run and the last run of each of its
``falsifier.n_restarts`` starts (several local maxima: a failure region of several parts) map back to

$$
u^* = T^{-1}(x^*) = Φ^{-1}(F(x^*))
$$

(:func:`pfjax.rare.transform.to_standard`). A worst case lies at the edge of the box, far out in
the tails; the most likely failure points lie nearer the origin, so ``u*`` is pulled in along its
ray to the failure boundary: ``g`` at ``t u*`` for ``t`` on a grid of ``[0, 1]`` (``n_ray``
rollouts per point, in one batch), and the start is ``t_min u*`` with ``t_min`` the smallest grid
value that fails (points whose ray does not fail are dropped). The estimate stays unbiased whatever the starts (they only centre the first proposal).
"""

from __future__ import annotations

import numpy as np

from pfjax.montecarlo.config import StudySpec
from pfjax.rare.estimate import evaluate
from pfjax.rare.transform import Input, Stratum, to_physical, to_standard

#: The box searched, in standard deviations of u per input.
U_BOX = 6.0
#: Rollouts along each ray of :func:`pull_in` (one per grid value of ``t``).
N_RAY = 32
#: The falsifier's objectives (pfjax.falsification.search.OBJECTIVES) a rare-event metric can be.
_OBJECTIVES = ("iae", "ise", "itae", "max_abs_d", "late_max_abs_d")


def _box(inputs: list[Input], name: str) -> tuple[float, float] | None:
    """``(T(-U), T(U))`` of the input ``name`` (config units), None where it is not an input."""
    names = [inp.name for inp in inputs]
    if name not in names:
        return None
    j = names.index(name)
    u = np.zeros((2, len(inputs)))
    u[:, j] = (-U_BOX, U_BOX)
    x = to_physical(inputs, u)[name]
    return float(x[0]), float(x[1])


def falsifier_points(spec: StudySpec, stratum: Stratum, inputs: list[Input], controller, *, seed: int = 0):
    """The falsifier's worst run of one stratum and every start's last run, mapped to the
    standard-normal space (module docstring): ``(u* (1 + n_restarts, len(inputs)), rollouts,
    gradient rollouts)``, or ``None`` where the study's
    slip is not constant or the stratum's inputs have no slip (the falsifier searches constant
    slips and start errors)."""

    from pfjax import paths
    from pfjax.falsification import falsify
    from pfjax.montecarlo.runner import sim_config
    from pfjax.montecarlo.sampling import sample_runs
    from pfjax.numerics.random import seed_key
    from pfjax.sim.simulate import unstack

    if not falsifier_applies(spec, inputs):
        return None
    slips = [b for b in (_box(inputs, "beta_r_deg"), _box(inputs, "beta_f_deg")) if b is not None]
    nominal = to_physical(inputs, np.zeros((1, len(inputs))))
    given = {**nominal, **{k: np.full(1, v) for k, v in stratum.values.items()}}
    run0 = unstack(sample_runs(spec, stratum.path_index, np.arange(1), given=given).scenarios, 0)
    ic: dict = {}
    for key, name in (("d", "lateral_offset"), ("theta_e_deg", "heading_error_deg")):
        dist = getattr(spec.initial, name)
        fixed = stratum.values.get(name, dist.number("value") if dist.dist == "constant" else 0.0)
        ic[key] = _box(inputs, name) or fixed
    ic["u"] = paths.entry(spec.paths[stratum.path_index].kind).start_u
    f, rare = spec.falsifier, spec.rare_event
    ctrl, gains, _ = controller
    fr = falsify(
        ctrl,
        gains,
        run0.path,
        config=sim_config(spec),
        slip_bound_deg=min(89.0, max(abs(v) for b in slips for v in b)),
        f_max_hz=0.0,
        ic_bounds=ic,
        objective=rare.metric if rare.metric in _OBJECTIVES else "late_max_abs_d",
        n_restarts=f.n_restarts,
        steps=f.steps,
        key=seed_key(seed),
        params=run0.params,
    )
    assert fr.restarts is not None  # falsify records every start's last run
    seqs, ics = (np.asarray(a) for a in fr.restarts)
    slip = np.degrees(np.concatenate([np.asarray(fr.slip)[None, 0], seqs[:, 0]]))  # (R + 1, 2) deg
    ic_all = np.concatenate([np.asarray(fr.ic)[None], ics])
    x = {k: np.repeat(np.asarray(v, dtype=float), len(slip)) for k, v in nominal.items()}
    found = {"beta_r_deg": slip[:, 0], "beta_f_deg": slip[:, 1], "lateral_offset": ic_all[:, 0]}
    found["heading_error_deg"] = np.degrees(ic_all[:, 1])
    for k, v in found.items():
        if k in x:
            x[k] = v
    u = to_standard(inputs, x)
    return np.where(np.isfinite(u), u, np.sign(u) * U_BOX), int(fr.n_rollouts), int(fr.n_gradients)


def falsifier_applies(spec: StudySpec, inputs: list[Input]) -> bool:
    """Whether the falsifier searches the study's runs: constant slip with a slip angle among the
    uncertain ``inputs`` (it searches constant slips and start errors)."""
    slips = [b for b in (_box(inputs, "beta_r_deg"), _box(inputs, "beta_f_deg")) if b is not None]
    return spec.slip.kind == "constant" and bool(slips)


def pull_in(g, u_star: np.ndarray, *, n_ray: int = N_RAY, batch: int = 4096) -> tuple[np.ndarray, int]:
    """``t_min u*`` for each row of ``u_star`` (``(m, dim)``, module docstring): ``(starts (k, dim)``
    of the rows whose ray fails somewhere, ``rollouts)``."""
    t = np.linspace(0.0, 1.0, n_ray + 1)[1:]
    m, dim = u_star.shape
    fails = (evaluate(g, (t[None, :, None] * u_star[:, None, :]).reshape(-1, dim), batch) <= 0).reshape(m, n_ray)
    hit = fails.any(axis=1)
    return t[np.argmax(fails[hit], axis=1), None] * u_star[hit], m * n_ray
