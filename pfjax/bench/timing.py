"""Wall-clock timing of compiled calls for the benchmark: one function alone (:func:`best_of`), or
several in turn (:func:`interleaved`) so that a shared machine's slow periods slow them alike.

**A call's cost includes what it leaves behind.** XLA's CPU runtime releases a program's temporary
buffers after the result is ready: ``jax.block_until_ready`` returns before the memory goes back to
the system. A reverse-mode gradient of the benchmark problem (2,000 runs, 4,000 steps) stores each
step's values in such a buffer (112 MB per device), and its release took 0.012-0.016 s of system
time, which landed in whatever ran next: measured on a 2-core AMD EPYC (Zen 5), jax 0.10.2, the
forward pass took 0.034 s alone and 0.046-0.048 s right after a reverse-mode call (0.035-0.041 s
after the same call and a 0.1 s pause). Timing the three in turn, one call each, charged the
gradient's release to the forward pass: the forward-mode gradient's ratio to it came out about
27 % low and the reverse-mode gradient's about 34 % low.

So :func:`interleaved` times each function in a window of consecutive calls after an untimed one:
the untimed call absorbs what the previous function left, and the window holds as many releases of
the function's own buffers as it holds calls (its first call's release falls in it, its last's
outside) -- the steady state of a loop that calls the function again and again. Any window of
one call or more does that; :data:`WINDOW` = 2 averages each round's time over two calls.

Calls that leave little behind (a forward pass, whose results and temporaries are small) are timed
in turn without the untimed call (``settle=False``): one timed call each per round, as many calls as
:func:`best_of` each, and a slow period of the machine falls on all of them alike instead of on
whichever ran then.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from typing import Any

#: Timed consecutive calls per function and round in :func:`interleaved`.
WINDOW = 2


def best_of(f: Callable[[], Any], repeats: int) -> tuple[Any, float, float]:
    """``(result, first, best)``: ``f()`` called once (``first`` seconds: compilation and run), then
    ``repeats`` more times, each timed alone (``best``: the fastest; ``first`` when ``repeats`` is
    0). Consecutive calls of one function: each pays for the previous one's release."""
    t0 = time.perf_counter()
    out = f()
    first = time.perf_counter() - t0
    best = math.inf if repeats else first
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = f()
        best = min(best, time.perf_counter() - t0)
    return out, first, best


def interleaved(
    fs: Sequence[Callable[[], Any]], rounds: int, window: int = WINDOW, settle: bool = True
) -> tuple[list[Any], list[float], list[float]]:
    """``(results, firsts, bests)`` of several functions timed in turn (module docstring).

    Each function is called once first (``firsts``: compilation and run). Then, ``rounds`` times,
    each function in turn is called once untimed (``settle``; none with ``settle=False``) and
    ``window`` times timed back to back; ``bests`` are the fastest window's seconds per call
    (``firsts`` when ``rounds`` is 0)."""
    if rounds < 0 or window < 1:
        raise ValueError(f"rounds must be >= 0 and window >= 1, got {rounds} and {window}")
    fs = list(fs)
    outs, firsts = [], []
    for f in fs:
        t0 = time.perf_counter()
        outs.append(f())
        firsts.append(time.perf_counter() - t0)
    bests = list(firsts) if not rounds else [math.inf] * len(fs)
    for _ in range(rounds):
        for i, f in enumerate(fs):
            if settle:
                outs[i] = f()  # absorbs what the previous function left
            t0 = time.perf_counter()
            for _ in range(window):
                outs[i] = f()
            bests[i] = min(bests[i], (time.perf_counter() - t0) / window)
    return outs, firsts, bests


__all__ = ["WINDOW", "best_of", "interleaved"]
