"""Multi-start gradient tuning: space-filling screening, successive halving of projected BFGS chains,
restarts, a compass polish, optional smoothing.

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
5. **Compass polish.** ``polish_steps`` value-only compass iterations around the incumbent, first
   step ``polish_scale`` (:mod:`pfjax.tuning.local`): ``2 D`` rollouts of one forward pass each per
   iteration; they walk along the kinks of IAE costs where gradient steps stall.

The local descent (``local``) is a projected BFGS by default, or Adam (:mod:`pfjax.tuning.local`).
Tuning costs have long curved valleys (for the PI, the damping ratio ``~ kp_theta / sqrt(kp_d)``
sets the cost and the valley runs along it), which a diagonal method such as Adam crosses back and
forth; the BFGS curvature pairs follow the valley.

With ``smoothing = s > 0`` (at most 1, the box's width) the first round evaluates each trial at
``z_t + sigma_k eps_k`` (``eps_k ~ N(0, I)``, one draw per chain and step, ``sigma_k`` falling
linearly from ``s`` to 0 over the round): a one-sample randomised smoothing of the cost, which can step over basins
narrower than ``sigma``; later rounds see the true cost. The perturbed point is the one evaluated
and kept, so the incumbent is always a real evaluation.

The result is the best point ever evaluated (screening, trial, restart and polish points alike).

Budget (:class:`~pfjax.tuning.gradient.TuneResult`): ``n_rollouts`` counts every simulated
rollout, ``n`` per cost evaluation (the batch), value-only or with its gradient. Forward-pass
equivalents ``n_forward_passes`` charge a value-only rollout 1 and a rollout with its gradient
``1 + D`` in forward mode (one tangent per gain propagated beside the primal; measured cost
1.3-3.0 passes for D = 1-4, :mod:`pfjax.numerics.autodiff`, so this over-counts) or 4 in reverse
mode (measured 3.15 for 500 runs and 4.82-4.87 for 2,000 through the per-step loop a tuner's cost
runs, docs/performance.md). ``wall_s`` excludes compilation (every program is compiled ahead of time,
timed in ``compile_s``; the compiled programs are cached per cost function and shape, so repeated
runs on one problem compile once).

Programs: the screening's and the polish's (value only) and one cost-and-gradient step per chain
count (8, 4 and 2 chains by default; BFGS restarts reuse the one of their count). When the caller
gives the rollout-steps of one evaluation and they are few (``rollout_steps`` of
:func:`multistart_tune`), every round and the BFGS restarts run on the first round's program
instead, and the polish on the screening's, the dropped chains' and missing points' places taken
by copies of the first whose results are not used: three compilations fewer at the defaults, for
a few tenths of a second of extra simulation. The chains and points are independent lanes of one
vmapped program, so the results agree with one program per chain count and purpose: to the bit
in the tests (a quadratic, the simulator's cost), in general up to the float rounding of a
differently compiled program (which could change a halving's choice between two chains of nearly
equal cost).
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
from pfjax.tuning import local as L
from pfjax.tuning.gradient import TuneResult, adam, pad_rows, pads_cheaply

SAMPLERS = ("sobol", "lhs", "uniform")
LOCALS = L.LOCALS


#: The successive-halving rounds when none are given (fewer when ``steps`` is below them).
DEFAULT_ROUNDS = 3


class MultistartOptions(NamedTuple):
    """Settings of :func:`multistart_tune` (module docstring); lengths in normalised box units."""

    n_screen: int = 64  # space-filling points screened by value only
    sampler: str = "sobol"  # sobol | lhs | uniform
    n_starts: int = 8  # best screened points descended together
    separation: float = 0.1  # least RMS distance between two starts (0: the n_starts best)
    steps: int = 60  # cost-and-gradient evaluations of a chain that survives every round
    rounds: int | None = None  # successive-halving rounds (1: no halving; None: 3, or steps when below 3)
    local: str = "bfgs"  # bfgs | adam: the local descent
    learning_rate: float = 0.1  # bfgs: first trust radius (inf-norm); adam: step, cosine-decayed to a tenth
    smoothing: float = 0.0  # randomised-smoothing radius of the first round, in [0, 1] (0: off)
    n_restarts: int = 3  # perturbations of the incumbent descended at the end (0: off)
    restart_steps: int = 20
    restart_scale: float = 0.05  # standard deviation of the perturbations
    polish_steps: int = 8  # value-only compass iterations around the incumbent (0: off)
    polish_scale: float = 0.05  # first compass step

    @property
    def n_rounds(self) -> int:
        """The successive-halving rounds run: ``rounds``; unset, :data:`DEFAULT_ROUNDS`, or ``steps``
        when below them."""
        return min(DEFAULT_ROUNDS, int(self.steps)) if self.rounds is None else int(self.rounds)

    def check(self) -> MultistartOptions:
        """``self`` with ``rounds`` resolved (None: :data:`DEFAULT_ROUNDS`, or ``steps`` when below
        them) if valid; :class:`~pfjax.errors.InputError` naming the bad field otherwise (``rounds``
        above ``steps`` among them)."""
        errors.integer("n_screen", self.n_screen, low=0, high=1_000_000)
        if self.sampler not in SAMPLERS:
            raise errors.InputError(f"sampler: value {self.sampler!r}, expected one of {', '.join(SAMPLERS)}")
        if self.local not in LOCALS:
            raise errors.InputError(f"local: value {self.local!r}, expected one of {', '.join(LOCALS)}")
        errors.integer("n_starts", self.n_starts, low=1, high=1_000_000)
        errors.number("separation", self.separation, low=0.0, high=1.0)
        errors.integer("steps", self.steps, low=1, high=1_000_000)
        rounds = min(DEFAULT_ROUNDS, int(self.steps)) if self.rounds is None else self.rounds  # unchecked
        if errors.is_number(rounds) and rounds > self.steps:
            raise errors.InputError(f"rounds: must be <= steps ({self.steps}), got {rounds}", "rounds")
        errors.integer("rounds", rounds, low=1, high=int(self.steps))
        errors.number("learning_rate", self.learning_rate, positive=True)
        errors.number("smoothing", self.smoothing, low=0.0, high=1.0)
        if (
            self.smoothing > 0 and rounds == 1
        ):  # the smoothed round is the first of several: the last sees the true cost
            more = "rounds >= 2" if self.steps >= 2 else "steps >= 2 and rounds >= 2"  # rounds <= steps
            raise errors.InputError(
                f"smoothing: smooths the first of several rounds, and rounds = 1; give {more} or smoothing = 0, "
                f"got {self.smoothing:g}",
                "smoothing",
            )
        errors.integer("n_restarts", self.n_restarts, low=0, high=1_000_000)
        errors.integer("restart_steps", self.restart_steps, low=0, high=1_000_000)
        errors.number("restart_scale", self.restart_scale, nonnegative=True)
        errors.integer("polish_steps", self.polish_steps, low=0, high=1_000_000)
        errors.number("polish_scale", self.polish_scale, low=0.0, high=1.0)
        return self._replace(rounds=int(rounds))


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
    rollout_steps: int | None = None,
    mode: str = "auto",
    progress: bool = False,
) -> TuneResult:
    """Minimise ``cost(theta)`` over the box by screened, halved, restarted, polished projected descent.

    Args:
        cost: ``theta (D,) -> scalar``, traceable (e.g. :func:`pfjax.tuning.cost.batch_cost`).
        lower: ``(D,)`` lower corner of the box, ``lower < upper``.
        upper: ``(D,)`` upper corner of the box.
        key: JAX PRNG key (space-filling points, smoothing noise, restarts).
        options: :class:`MultistartOptions`.
        candidates: ``(K, D)`` extra points screened beside the space-filling ones (clipped to
            the box), e.g. the source's gains or an LMI design.
        n_per_eval: rollouts per ``cost`` call, for the budget count.
        rollout_steps: the simulated rollout-steps of one ``cost`` call (its runs times their
            steps), when known. Then the halving rounds and the restarts share the first round's
            compiled step program if their padded chains add at most
            :data:`~pfjax.tuning.gradient.PAD_FORWARD_PASSES` forward-pass rollout-steps to the
            run (a rollout charged as in ``n_forward_passes``), and the polish the screening's
            value-only program if the rest of that budget covers its padded points (padded with
            copies of the first, whose results are dropped): a fraction of a second, against about
            a second to compile each further program. ``None`` (a cost of unknown size): one
            program per chain count and purpose.
        mode: differentiation mode (:func:`pfjax.numerics.autodiff.value_and_grad`).
        progress: tqdm bar over the gradient steps and polish iterations.

    Returns:
        :class:`~pfjax.tuning.gradient.TuneResult`; ``history`` has one entry after the screening
        and one per gradient step and polish iteration (best cost so far).
    """
    if not isinstance(options, MultistartOptions):
        raise errors.InputError(
            f"options: expected a MultistartOptions, got {type(options).__name__} (MultistartOptions(**d) takes a dict)",
            "options",
        )
    o = options.check()
    lo, hi = errors.box(lower, upper)
    if key is None:
        raise errors.InputError("key: required, a JAX PRNG key (space-filling points, smoothing, restarts)", "key")
    span, D = hi - lo, lo.size
    autodiff.resolve_mode(mode, D)
    cand = np.zeros((0, D)) if candidates is None else np.atleast_2d(np.asarray(candidates, np.float64))
    if cand.shape[1:] != (D,):
        raise errors.InputError(f"candidates: shape {cand.shape}, expected (K, {D})")
    k_screen, k_smooth, k_restart = jax.random.split(key, 3)
    z0 = np.concatenate([np.clip((cand - lo) / span, 0.0, 1.0), space_filling(o.n_screen, D, o.sampler, k_screen)])
    if len(z0) < o.n_starts:  # too few screened points: fill the starts uniformly (a key of their own,
        # not the restarts', whose perturbations would repeat these draws)
        k_fill = jax.random.fold_in(k_restart, 1)
        z0 = np.concatenate([z0, np.asarray(jax.random.uniform(k_fill, (o.n_starts - len(z0), D)), np.float64)])
    dtype = jnp.result_type(float)
    fpp = autodiff.forward_passes_per_gradient(D, mode)
    plan = _Plan.of(o, len(z0), D, None if rollout_steps is None else int(rollout_steps), fpp)
    t_c = time.perf_counter()
    progs = plan.compile(cost, D, dtype, mode)
    compile_s = time.perf_counter() - t_c

    bud = _Budget(n_per_eval, fpp, z0[0], progress and plan.n_iter(o))
    args = (jnp.asarray(lo, dtype), jnp.asarray(span, dtype))
    J0 = bud.record(progs["screen"](jnp.asarray(z0, dtype), *args), z0, 1, tick=False)
    order = select_starts(z0, J0, o.n_starts, o.separation)
    _halving(o, plan, progs, bud, z0[order], J0[order], k_smooth, args, dtype)
    if plan.n_restart_chains:
        eps = np.asarray(jax.random.normal(k_restart, (o.n_restarts, D)), np.float64)
        zr = np.concatenate([bud.z[None], np.clip(bud.z + o.restart_scale * eps, 0.0, 1.0)])
        m, size = plan.n_restart_chains, plan.restart_program
        state = _rows(plan.local_r.init(jnp.asarray(zr, dtype)), pad_rows(np.arange(m), size))
        zeros = jnp.zeros((size, D), dtype)
        for _ in range(o.restart_steps):
            J, zp, nb, state = _chains_step(progs[size, plan.local_r.program], state, zeros, m, args)
            bud.record(J, zp, bud.fpp, nb)
    h = float(o.polish_scale)
    for _ in range(o.polish_steps if plan.polish else 0):
        z_c, J_c, Zp = bud.z, bud.J, L.compass_points(bud.z, h)
        Jp = np.asarray(progs["polish"](jnp.asarray(pad_rows(Zp, plan.polish_program), dtype), *args))
        Jp = bud.record(Jp[: len(Zp)], Zp, 1)
        h = L.compass_update(z_c, J_c, h, Zp, Jp)[2]  # the incumbent moves in bud.record
    return bud.result(lo, span, compile_s)


class _Plan(NamedTuple):
    """Chain counts and local descents of one run, and the programs they need."""

    sizes: tuple  # chains per halving round
    per_round: tuple  # steps per halving round
    n_restart_chains: int
    polish: bool  # a compass polish at the end
    local: L.Local
    local_r: L.Local
    programs: tuple  # chain count of each halving round's step program (>= its chains: padded)
    restart_program: int  # chain count of the restarts' step program
    screen_program: int  # points of the screening's value-only program
    polish_program: int  # points of the polish's value-only program (the screening's where shared)

    @classmethod
    def of(cls, o: MultistartOptions, n_screen: int, D: int, rollout_steps: int | None = None, fpp: int = 1) -> _Plan:
        """The plan of ``o`` for ``n_screen`` screened points in ``D`` dimensions; ``rollout_steps``:
        the rollout-steps of one evaluation (None: unknown, no shared program), ``fpp``: the
        forward passes a gradient is charged."""
        rounds = o.n_rounds
        per_round = [o.steps // rounds + (1 if r < o.steps % rounds else 0) for r in range(rounds)]
        sizes, n = [], o.n_starts
        for _ in range(rounds):
            sizes.append(n)
            n = max(1, n // 2)
        n_r = o.n_restarts + 1 if (o.n_restarts and o.restart_steps) else 0
        lr, lc = float(o.learning_rate), L.local(o.local, float(o.learning_rate), int(o.steps))
        local_r = L.local(o.local, lr / 4.0, max(int(o.restart_steps), 1))
        # shared: every round on the first round's program, and the restarts too where that program
        # is theirs (BFGS) and has room, if the padded chains' rollouts are cheap
        top = sizes[0]
        pad_r = top if (n_r and local_r.program == lc.program and n_r <= top) else n_r
        padding = sum((top - m) * k for m, k in zip(sizes, per_round)) + (pad_r - n_r) * o.restart_steps
        polish = bool(o.polish_steps and o.polish_scale > 0)
        # and the polish's 2 D compass points on the screening's program, if it has room and the
        # budget left after the steps' padding covers theirs
        pad_p = n_screen if (polish and n_screen >= 2 * D) else 2 * D
        value_padding = (pad_p - 2 * D) * o.polish_steps if polish else 0
        share = pads_cheaply(padding * fpp, rollout_steps)  # unknown: none
        share_p = share and pads_cheaply(padding * fpp + value_padding, rollout_steps)
        return cls(
            tuple(sizes),
            tuple(per_round),
            n_r,
            polish,
            lc,
            local_r,
            tuple(top if share else m for m in sizes),
            pad_r if share else n_r,
            n_screen,
            pad_p if share_p else 2 * D,
        )

    def n_iter(self, o: MultistartOptions) -> int:
        return o.steps + (o.restart_steps if self.n_restart_chains else 0) + (o.polish_steps if self.polish else 0)

    def compile(self, cost, D: int, dtype, mode: str) -> dict:
        """Every program compiled ahead of time: ``"screen"``, ``"polish"`` (value only; one program
        where the polish's points are padded to the screening's) and one step per ``(chains,
        local.program)`` (the restarts reuse a halving round's program when their chain count,
        padded or not, is the round's)."""
        progs: dict = {"screen": _compiled(box_value, ((self.screen_program, D), dtype), cost=cost)}
        if self.polish:
            progs["polish"] = _compiled(box_value, ((self.polish_program, D), dtype), cost=cost)
        pairs = {(m, self.local.program) for m in self.programs}
        pairs |= {(self.restart_program, self.local_r.program)} if self.n_restart_chains else set()
        for m, lc in sorted(pairs):
            progs[m, lc] = _compiled(_step, ((m, D), dtype), cost=cost, local=lc, mode=mode)
        return progs


def _chains_step(program, state, noise, m: int, args):
    """One step of a (possibly padded) step program: the costs, points and non-finite counts of
    the ``m`` real chains, and the new state (every chain)."""
    J, zp, state, nb = program(state, noise, *args)
    return (*(np.asarray(x)[:m] for x in (J, zp, nb)), state)


def _rows(state, idx: np.ndarray):
    """The chains ``idx`` of a descent state, gathered on the host (no program to compile)."""
    return jax.tree_util.tree_map(lambda x: np.asarray(x)[idx] if np.ndim(x) else x, state)


def _halving(o, plan: _Plan, progs, bud: _Budget, z_starts, J_starts, k_smooth, args, dtype) -> None:
    """Successive halving (module docstring, step 3): the chains from ``z_starts`` descended
    together round by round, the worse half (by the best cost each has seen) dropped between rounds."""
    state = plan.local.init(jnp.asarray(z_starts, dtype))
    chain_best = np.asarray(J_starts, np.float64).copy()
    k_iter = 0
    for r, (m, size, n_steps) in enumerate(zip(plan.sizes, plan.programs, plan.per_round)):
        keep = np.arange(m)
        if len(chain_best) > m:  # successive halving: keep the m chains with the best costs seen
            keep = np.sort(np.argsort(chain_best, kind="stable")[:m])
            chain_best = chain_best[keep]
        state = _rows(state, pad_rows(keep, size))  # a shared program's extra chains: copies of the first
        pad = np.zeros((size - m, z_starts.shape[1]), dtype)
        for k in range(n_steps):
            sigma = o.smoothing * (1.0 - k / n_steps) if r == 0 and o.n_rounds > 1 else 0.0
            shape = (m, z_starts.shape[1])
            noise = (  # no draw where it would be scaled by 0
                np.asarray(sigma * jax.random.normal(jax.random.fold_in(k_smooth, k_iter), shape, dtype))
                if sigma
                else np.zeros(shape, dtype)
            )
            noise = np.concatenate([noise, pad])
            J, zp, nb, state = _chains_step(progs[size, plan.local.program], state, noise, m, args)
            chain_best = np.minimum(chain_best, bud.record(J, zp, bud.fpp, nb))
            k_iter += 1


class _Budget:
    """Rollouts and forward passes counted, the best point so far and the history (host side)."""

    def __init__(self, n_per_eval: int, fpp: int, z0, bar_total):
        self.n_per_eval, self.fpp = n_per_eval, fpp
        self.n_roll = self.n_fwd = self.n_bad = 0
        self.J, self.z = np.inf, np.asarray(z0, np.float64)
        self.hist: list[float] = []
        self.hist_r: list[int] = []
        self.hist_t: list[float] = []
        self.bar = None
        if bar_total:
            from tqdm.auto import tqdm

            self.bar = tqdm(total=bar_total, desc="multistart", leave=False)
        self.t0 = time.perf_counter()

    def record(self, J, Z, passes: int, n_bad=0, tick: bool = True) -> np.ndarray:
        """Count ``len(J)`` evaluations of ``passes`` forward passes per rollout at the points ``Z``
        (``n_bad``: their non-finite gradient components, per point or in all); returns the costs
        with non-finite ones as ``inf``."""
        J = np.asarray(J, np.float64)
        J = np.where(np.isfinite(J), J, np.inf)
        self.n_roll += len(J) * self.n_per_eval
        self.n_fwd += len(J) * self.n_per_eval * passes
        self.n_bad += int(np.sum(n_bad))
        i = int(np.argmin(J))
        if J[i] < self.J:
            self.J, self.z = float(J[i]), np.asarray(Z[i], np.float64)
        self.hist.append(self.J)
        self.hist_r.append(self.n_roll)
        self.hist_t.append(time.perf_counter() - self.t0)
        if self.bar is not None and tick:
            self.bar.update(1)
            self.bar.set_postfix(best=f"{self.J:.5g}")
        return J

    def result(self, lo, span, compile_s: float) -> TuneResult:
        if self.bar is not None:
            self.bar.close()
        return TuneResult(
            lo + span * self.z,
            self.J,
            np.asarray(self.hist),
            np.asarray(self.hist_r, dtype=np.int64),
            np.asarray(self.hist_t),
            int(self.n_roll),
            time.perf_counter() - self.t0,
            self.n_bad,
            int(self.n_fwd),
            compile_s,
        )


_COMPILED: dict = {}


def _compiled(fun, shape_dtype, **static):
    """``fun`` compiled ahead of time for ``(n, D)`` chains (cached: seeds of one problem share it)."""
    (n, D), dtype = shape_dtype
    k = (fun, n, D, jnp.dtype(dtype).name, tuple(sorted(static.items(), key=lambda kv: kv[0])))
    if k not in _COMPILED:
        if len(_COMPILED) > 64:
            _COMPILED.clear()
        z, v = jnp.zeros((n, D), dtype), jnp.zeros((D,), dtype)
        args = (z, v, v) if fun is box_value else (static["local"].init(z), z, v, v)
        _COMPILED[k] = fun.lower(*args, **static).compile()
    return _COMPILED[k]


@functools.partial(jax.jit, static_argnames=("cost",))
def box_value(z, lo, span, *, cost):
    """Costs of ``(n, D)`` normalised points (value only)."""
    return jax.vmap(lambda zz: cost(lo + span * zz))(z)


@functools.partial(jax.jit, static_argnames=("cost", "local", "mode"))
def _step(state, noise, lo, span, *, cost, local, mode="auto"):
    """One evaluation of every chain: the cost and its gradient at the trial point (plus ``noise``:
    randomised smoothing; 0 for the true cost), then the local update. Returns the costs at the
    evaluated points, those points, the new state and each chain's number of non-finite gradient
    components (zeroed)."""
    vg = jax.vmap(autodiff.value_and_grad(lambda zz: cost(lo + span * zz), mode=mode))
    if local.name == "adam":
        z, opt_state = state
        zp = jnp.clip(z + noise, 0.0, 1.0)
        J, g = vg(zp)
        bad = ~jnp.isfinite(g)
        g = jnp.where(bad, 0.0, g)
        opt = adam(local.learning_rate, local.steps)
        upd, opt_state = opt.update(g, opt_state, z)
        return J, zp, (jnp.clip(optax.apply_updates(z, upd), 0.0, 1.0), opt_state), jnp.sum(bad, axis=-1)
    zp = jnp.clip(jax.vmap(L.bfgs_trial)(state) + noise, 0.0, 1.0)
    J, g = vg(zp)
    bad = ~jnp.isfinite(g)
    g = jnp.where(bad, 0.0, g)
    return J, zp, jax.vmap(L.bfgs_update)(state, zp, J, g), jnp.sum(bad, axis=-1)
