"""Multi-start gradient tuning: space-filling screening, successive halving of projected BFGS chains,
restarts, optional smoothing.

One run of :func:`multistart_tune` on a box ``lower <= theta <= upper`` (normalised coordinates
``z = (theta - lower) / (upper - lower) in [0, 1]^D``, as in :mod:`pfjax.tuning.gradient`):

1. **Screening.** ``n_screen`` space-filling points (a scrambled Sobol sequence, a Latin
   hypercube or uniform draws, from the key) plus the caller's candidate starts (the source's
   gains, an LMI design) are evaluated by value only, in one batched call.
2. **Starts.** The ``n_starts`` lowest, at least ``separation`` apart (RMS distance, so that one
   broad basin does not take every start; :func:`select_starts`).
3. **Successive halving.** The starts are descended together (vmapped: one batched cost-and-
   gradient call per step) for ``rounds`` rounds of about ``steps / rounds`` steps; after every
   round but the last the worse half of the chains (by the best cost each has seen) is dropped, so
   the budget goes to the survivors.
4. **Restarts.** ``n_restarts`` perturbations of the incumbent (``z* + restart_scale * eps``,
   clipped to the box) and the incumbent itself are descended for ``restart_steps`` steps with a
   quarter of the first step.

The local descent (``local``) is a **projected BFGS** by default, one evaluation per chain and
step, so that every chain advances in lockstep: the trial point is ``z + d``, ``d = -H_F g_F`` on
the free coordinates (those not on a bound the gradient pushes against), steepest descent when
that is not a descent direction, scaled to ``|d|_inf <= radius`` and clipped to the box; a trial
that lowers the cost is accepted (radius doubled, up to 0.5) and its pair ``s = z_t - z``,
``y = g_t - g`` updates the inverse Hessian ``H`` when ``s.y > 0`` (Nocedal & Wright eq. 6.17,
``H`` first scaled by eq. 6.20); a rejected trial quarters the radius. Tuning costs have long
curved valleys (for the PI, the damping ratio ``~ kp_theta / sqrt(kp_d)`` sets the cost and the
valley runs along it), which a diagonal method such as Adam crosses back and forth; the curvature
pairs follow the valley. ``local="adam"`` keeps the cosine-decayed Adam of
:func:`pfjax.tuning.gradient.gradient_tune` (for comparison).

With ``smoothing = s > 0`` the first round evaluates each trial at ``z_t + sigma_k eps_k``
(``eps_k ~ N(0, I)``, one draw per chain and step, ``sigma_k`` falling linearly from ``s`` to 0
over the round): a one-sample randomised smoothing of the cost, which can step over basins
narrower than ``sigma``; later rounds see the true cost. The perturbed point is the one evaluated
and kept, so the incumbent is always a real evaluation.

The result is the best point ever evaluated (screening, trial and restart points alike).

Budget (:class:`~pfjax.tuning.gradient.TuneResult`): ``n_rollouts`` counts every simulated
rollout, ``n`` per cost evaluation (the batch), value-only or with its gradient. Forward-pass
equivalents ``n_forward_passes`` charge a value-only rollout 1 and a rollout with its gradient
``1 + D`` in forward mode (one tangent per gain propagated beside the primal; measured cost
1.3-3.0 passes for D = 1-4, :mod:`pfjax.numerics.autodiff`, so this over-counts) or 4 in reverse
mode (measured 3.2-3.4). ``wall_s`` excludes compilation (every program is compiled ahead of time,
timed in ``compile_s``; the compiled programs are cached per cost function and shape, so repeated
runs on one problem compile once).
"""

from __future__ import annotations

import functools
import time
from collections.abc import Callable
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import optax

from pfjax import errors
from pfjax.numerics import autodiff
from pfjax.tuning.gradient import TuneResult

SAMPLERS = ("sobol", "lhs", "uniform")


class MultistartOptions(NamedTuple):
    """Settings of :func:`multistart_tune` (module docstring); lengths in normalised box units."""

    n_screen: int = 64  # space-filling points screened by value only
    sampler: str = "sobol"  # sobol | lhs | uniform
    n_starts: int = 8  # best screened points descended together
    separation: float = 0.1  # least RMS distance between two starts (0: the n_starts best)
    steps: int = 60  # cost-and-gradient evaluations of a chain that survives every round
    rounds: int = 3  # successive-halving rounds (1: no halving)
    local: str = "bfgs"  # bfgs | adam: the local descent
    learning_rate: float = 0.1  # bfgs: first trust radius (inf-norm); adam: step, cosine-decayed to a tenth
    smoothing: float = 0.0  # randomised-smoothing radius of the first round (0: off)
    n_restarts: int = 3  # perturbations of the incumbent descended at the end (0: off)
    restart_steps: int = 20
    restart_scale: float = 0.05  # standard deviation of the perturbations

    def check(self) -> MultistartOptions:
        """``self`` if valid; :class:`~pfjax.errors.InputError` naming the bad field otherwise."""
        errors.integer("n_screen", self.n_screen, low=0, high=1_000_000)
        if self.sampler not in SAMPLERS:
            raise errors.InputError(f"sampler: value {self.sampler!r}, expected one of {', '.join(SAMPLERS)}")
        if self.local not in LOCALS:
            raise errors.InputError(f"local: value {self.local!r}, expected one of {', '.join(LOCALS)}")
        errors.integer("n_starts", self.n_starts, low=1, high=1_000_000)
        errors.number("separation", self.separation, low=0.0, high=1.0)
        errors.integer("steps", self.steps, low=1, high=1_000_000)
        errors.integer("rounds", self.rounds, low=1, high=max(1, int(self.steps)))
        errors.number("learning_rate", self.learning_rate, positive=True)
        errors.number("smoothing", self.smoothing, nonnegative=True)
        errors.integer("n_restarts", self.n_restarts, low=0, high=1_000_000)
        errors.integer("restart_steps", self.restart_steps, low=0, high=1_000_000)
        errors.number("restart_scale", self.restart_scale, nonnegative=True)
        return self


def space_filling(n: int, dim: int, sampler: str, key) -> np.ndarray:
    """``(n, dim)`` points in ``[0, 1)^dim``: scrambled Sobol, Latin hypercube or uniform, seeded by ``key``."""
    if n == 0:
        return np.zeros((0, dim))
    if sampler == "uniform":
        return np.asarray(jax.random.uniform(key, (n, dim)), np.float64)
    from scipy.stats import qmc

    seed = int(np.asarray(jax.random.randint(key, (), 0, 2**31 - 1)))
    if sampler == "sobol":
        m = int(np.ceil(np.log2(max(n, 1))))
        return qmc.Sobol(dim, scramble=True, seed=seed).random_base2(m)[:n]
    return qmc.LatinHypercube(dim, seed=seed).random(n)


def select_starts(z, J, n: int, separation: float) -> np.ndarray:
    """Indices of ``n`` starts: greedily the lowest ``J`` at RMS distance ``|z_i - z_j| / sqrt(D)``
    of at least ``separation`` from every start taken, then the lowest remaining ``J`` if fewer
    than ``n`` are that far apart."""
    order = np.argsort(np.where(np.isfinite(J), J, np.inf), kind="stable")
    taken: list[int] = []
    for i in order:
        if len(taken) == n:
            break
        if all(np.sqrt(np.mean((z[i] - z[j]) ** 2)) >= separation for j in taken):
            taken.append(int(i))
    rest = [int(i) for i in order if int(i) not in taken]
    return np.asarray(taken + rest[: n - len(taken)])


def multistart_tune(
    cost: Callable,
    lower,
    upper,
    *,
    key,
    options: MultistartOptions = MultistartOptions(),
    candidates=None,
    n_per_eval: int = 1,
    mode: str = "auto",
    progress: bool = False,
) -> TuneResult:
    """Minimise ``cost(theta)`` over the box by screened, halved, restarted projected descent.

    Args:
        cost: ``theta (D,) -> scalar``, traceable (e.g. :func:`pfjax.tuning.cost.batch_cost`).
        lower, upper: ``(D,)`` box, ``lower < upper``.
        key: JAX PRNG key (space-filling points, smoothing noise, restarts).
        options: :class:`MultistartOptions`.
        candidates: ``(K, D)`` extra points screened beside the space-filling ones (clipped to
            the box), e.g. the source's gains or an LMI design.
        n_per_eval: rollouts per ``cost`` call, for the budget count.
        mode: differentiation mode (:func:`pfjax.numerics.autodiff.value_and_grad`).
        progress: tqdm bar over the gradient steps.

    Returns:
        :class:`~pfjax.tuning.gradient.TuneResult`; ``history`` has one entry after the screening
        and one per gradient step (best cost so far).
    """
    o = options.check()
    lo, hi = np.asarray(lower, np.float64), np.asarray(upper, np.float64)
    span, D = hi - lo, lo.size
    autodiff.resolve_mode(mode, D)
    cand = np.zeros((0, D)) if candidates is None else np.atleast_2d(np.asarray(candidates, np.float64))
    if cand.shape[1:] != (D,):
        raise errors.InputError(f"candidates: shape {cand.shape}, expected (K, {D})")
    k_screen, k_smooth, k_restart = jax.random.split(key, 3)
    z0 = np.concatenate([np.clip((cand - lo) / span, 0.0, 1.0), space_filling(o.n_screen, D, o.sampler, k_screen)])
    if len(z0) < o.n_starts:  # too few screened points: fill the starts uniformly
        z0 = np.concatenate([z0, np.asarray(jax.random.uniform(k_restart, (o.n_starts - len(z0), D)), np.float64)])
    dtype = jnp.result_type(float)
    lo_j, span_j = jnp.asarray(lo, dtype), jnp.asarray(span, dtype)
    per_round = [o.steps // o.rounds + (1 if r < o.steps % o.rounds else 0) for r in range(o.rounds)]
    sizes, n = [], o.n_starts
    for _ in range(o.rounds):
        sizes.append(n)
        n = max(1, n // 2)
    n_restart_chains = o.n_restarts + 1 if (o.n_restarts and o.restart_steps) else 0
    local = _local(o.local, float(o.learning_rate), int(o.steps))
    local_r = _local(o.local, float(o.learning_rate) / 4.0, max(int(o.restart_steps), 1))

    # --- compile every program ahead of time (not in wall_s) ---
    t_c = time.perf_counter()
    screen = _compiled(_value, (z0.shape, dtype), cost=cost)
    steps_c = {}
    for m, lc in [(s, local) for s in sorted(set(sizes))] + ([(n_restart_chains, local_r)] if n_restart_chains else []):
        steps_c[(m, lc)] = _compiled(_step, ((m, D), dtype), cost=cost, local=lc, mode=mode)
    compile_s = time.perf_counter() - t_c

    t0 = time.perf_counter()
    fpp = autodiff.forward_passes_per_gradient(D, mode)
    n_roll = n_fwd = n_bad = 0
    hist, hist_r, hist_t = [], [], []
    best = {"J": np.inf, "z": z0[0]}

    def record(J, Z, n_runs, passes):
        nonlocal n_roll, n_fwd
        J = np.where(np.isfinite(J), J, np.inf)
        n_roll += n_runs * n_per_eval
        n_fwd += n_runs * n_per_eval * passes
        i = int(np.argmin(J))
        if J[i] < best["J"]:
            best["J"], best["z"] = float(J[i]), np.asarray(Z[i], np.float64)
        hist.append(best["J"])
        hist_r.append(n_roll)
        hist_t.append(time.perf_counter() - t0)
        return J

    J0 = record(np.asarray(screen(jnp.asarray(z0, dtype), lo_j, span_j), np.float64), z0, len(z0), 1)
    order = select_starts(z0, J0, o.n_starts, o.separation)
    state = local.init(jnp.asarray(z0[order], dtype))
    chain_best = J0[order].copy()
    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=o.steps + (o.restart_steps if n_restart_chains else 0), desc="multistart", leave=False)
    k_iter = 0
    for r, (m, n_steps) in enumerate(zip(sizes, per_round)):
        if len(chain_best) > m:  # successive halving: keep the m chains with the best costs seen
            keep = np.sort(np.argsort(chain_best, kind="stable")[:m])
            chain_best = chain_best[keep]
            state = jax.tree_util.tree_map(lambda x, keep=keep: x[keep] if np.ndim(x) else x, state)
        for k in range(n_steps):
            sigma = o.smoothing * (1.0 - k / n_steps) if r == 0 and o.rounds > 1 else 0.0
            noise = sigma * jax.random.normal(jax.random.fold_in(k_smooth, k_iter), (m, D), dtype)
            J, zp, state, nb = steps_c[(m, local)](state, noise, lo_j, span_j)
            J = record(np.asarray(J, np.float64), np.asarray(zp), m, fpp)
            chain_best = np.minimum(chain_best, J)
            n_bad += int(nb)
            k_iter += 1
            if bar is not None:
                bar.update(1)
                bar.set_postfix(best=f"{best['J']:.5g}")
    if n_restart_chains:
        eps = np.asarray(jax.random.normal(k_restart, (o.n_restarts, D)), np.float64)
        zr = np.concatenate([best["z"][None], np.clip(best["z"] + o.restart_scale * eps, 0.0, 1.0)])
        state = local_r.init(jnp.asarray(zr, dtype))
        zeros = jnp.zeros((n_restart_chains, D), dtype)
        for _ in range(o.restart_steps):
            J, zp, state, nb = steps_c[(n_restart_chains, local_r)](state, zeros, lo_j, span_j)
            record(np.asarray(J, np.float64), np.asarray(zp), n_restart_chains, fpp)
            n_bad += int(nb)
            if bar is not None:
                bar.update(1)
                bar.set_postfix(best=f"{best['J']:.5g}")
    if bar is not None:
        bar.close()
    return TuneResult(
        lo + span * best["z"],
        best["J"],
        np.asarray(hist),
        np.asarray(hist_r, dtype=np.int64),
        np.asarray(hist_t),
        int(n_roll),
        time.perf_counter() - t0,
        n_bad,
        int(n_fwd),
        compile_s,
    )


# --- local descents: one cost-and-gradient evaluation per chain and step ---------------------------

LOCALS = ("bfgs", "adam")


class _Local(NamedTuple):
    """A batched local descent: ``init(z (m, D)) -> state``; ``trial(state) -> z_t`` (per chain);
    ``update(state, z_t, J_t, g_t) -> state`` (per chain). Hashable (static under jit)."""

    name: str
    learning_rate: float
    steps: int

    def init(self, z):
        m, D = z.shape
        if self.name == "adam":
            return (z, _adam(self.learning_rate, self.steps).init(z))
        eye = jnp.broadcast_to(jnp.eye(D, dtype=z.dtype), (m, D, D))
        inf = jnp.full((m,), jnp.inf, z.dtype)
        return BFGSState(z, inf, jnp.zeros_like(z), eye, jnp.full((m,), self.learning_rate, z.dtype), inf < 0)


@functools.lru_cache(maxsize=32)
def _local(name: str, learning_rate: float, steps: int) -> _Local:
    return _Local(name, learning_rate, steps)


class BFGSState(NamedTuple):
    """Per-chain state of the projected BFGS descent (leading axis: chains)."""

    z: jnp.ndarray  # (D,) accepted point, normalised
    J: jnp.ndarray  # () its cost (inf before the first evaluation)
    g: jnp.ndarray  # (D,) its gradient, normalised units
    H: jnp.ndarray  # (D, D) inverse-Hessian approximation
    radius: jnp.ndarray  # () step bound, inf-norm, normalised units
    scaled: jnp.ndarray  # () bool: H has been scaled by the first curvature pair


def _bfgs_trial(st: BFGSState):
    """Projected quasi-Newton trial point: ``d = -H_F g_F`` on the free coordinates ``F`` (not at a
    bound the gradient pushes against), steepest descent if that is not a descent direction, scaled
    to ``|d|_inf <= radius``, clipped to the box. Before the first evaluation: the start itself."""
    at_lo, at_hi = (st.z <= 0.0) & (st.g > 0.0), (st.z >= 1.0) & (st.g < 0.0)
    free = ~(at_lo | at_hi)
    gf = jnp.where(free, st.g, 0.0)
    d = -(st.H * free[:, None] * free[None, :]) @ gf
    d = jnp.where(jnp.dot(gf, d) < 0.0, d, -gf)
    d = d * jnp.minimum(1.0, st.radius / jnp.maximum(jnp.max(jnp.abs(d)), 1e-30))
    return jnp.where(jnp.isfinite(st.J), jnp.clip(st.z + d, 0.0, 1.0), st.z)


def _bfgs_update(st: BFGSState, zt, Jt, gt):
    """Accept the trial if it lowers the cost (then double the radius up to 0.5; else quarter it),
    and update ``H`` by BFGS with the accepted pair ``s = z_t - z``, ``y = g_t - g`` when
    ``s.y > 0`` (the first pair scales ``H`` to ``(s.y / y.y) I`` first, Nocedal & Wright eq. 6.20)."""
    first = ~jnp.isfinite(st.J)
    accept = jnp.isfinite(Jt) & (Jt < st.J)
    s, y = zt - st.z, gt - st.g
    sy = jnp.dot(s, y)
    curv = accept & ~first & (sy > 1e-12 * jnp.linalg.norm(s) * jnp.linalg.norm(y)) & (sy > 0)
    D = s.shape[0]
    eye = jnp.eye(D, dtype=s.dtype)
    H0 = jnp.where(st.scaled, st.H, eye * sy / jnp.maximum(jnp.dot(y, y), 1e-300))
    rho = 1.0 / jnp.where(curv, sy, 1.0)
    V = eye - rho * jnp.outer(s, y)
    Hn = V @ H0 @ V.T + rho * jnp.outer(s, s)
    H = jnp.where(curv, Hn, st.H)
    radius = jnp.where(first, st.radius, jnp.where(accept, jnp.minimum(2.0 * st.radius, 0.5), st.radius / 4.0))
    return BFGSState(
        jnp.where(accept, zt, st.z),
        jnp.where(accept, Jt, st.J),
        jnp.where(accept, gt, st.g),
        H,
        radius,
        st.scaled | curv,
    )


@functools.lru_cache(maxsize=32)
def _adam(learning_rate: float, steps: int) -> optax.GradientTransformation:
    """Adam with the step cosine-decayed from ``learning_rate`` to a tenth of it over ``steps``."""
    return optax.adam(optax.cosine_decay_schedule(learning_rate, max(steps, 1), alpha=0.1))


_COMPILED: dict = {}


def _compiled(fun, shape_dtype, **static):
    """``fun`` compiled ahead of time for ``(n, D)`` chains (cached: seeds of one problem share it)."""
    (n, D), dtype = shape_dtype
    k = (fun, n, D, jnp.dtype(dtype).name, tuple(sorted(static.items(), key=lambda kv: kv[0])))
    if k not in _COMPILED:
        if len(_COMPILED) > 64:
            _COMPILED.clear()
        z, v = jnp.zeros((n, D), dtype), jnp.zeros((D,), dtype)
        args = (z, v, v) if fun is _value else (static["local"].init(z), z, v, v)
        _COMPILED[k] = fun.lower(*args, **static).compile()
    return _COMPILED[k]


@functools.partial(jax.jit, static_argnames=("cost",))
def _value(z, lo, span, *, cost):
    """Costs of ``(n, D)`` normalised points (value only)."""
    return jax.vmap(lambda zz: cost(lo + span * zz))(z)


@functools.partial(jax.jit, static_argnames=("cost", "local", "mode"))
def _step(state, noise, lo, span, *, cost, local, mode="auto"):
    """One evaluation of every chain: the cost and its gradient at the trial point (plus ``noise``:
    randomised smoothing; 0 for the true cost), then the local update. Returns the costs at the
    evaluated points, those points, the new state and the number of non-finite gradient components
    (zeroed)."""
    vg = jax.vmap(autodiff.value_and_grad(lambda zz: cost(lo + span * zz), mode=mode))
    if local.name == "adam":
        z, opt_state = state
        zp = jnp.clip(z + noise, 0.0, 1.0)
        J, g = vg(zp)
        bad = ~jnp.isfinite(g)
        g = jnp.where(bad, 0.0, g)
        opt = _adam(local.learning_rate, local.steps)
        upd, opt_state = opt.update(g, opt_state, z)
        return J, zp, (jnp.clip(optax.apply_updates(z, upd), 0.0, 1.0), opt_state), jnp.sum(bad)
    zp = jnp.clip(jax.vmap(_bfgs_trial)(state) + noise, 0.0, 1.0)
    J, g = vg(zp)
    bad = ~jnp.isfinite(g)
    g = jnp.where(bad, 0.0, g)
    return J, zp, jax.vmap(_bfgs_update)(state, zp, J, g), jnp.sum(bad)
