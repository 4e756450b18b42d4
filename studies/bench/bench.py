"""The performance benchmark as a study script: ``python studies/bench/bench.py [--quick] [--sizes ...]``.

The same as ``pfjax bench`` (:mod:`pfjax.bench`): pfjax's simulator as users call it (metrics on) against
NumPy, Numba and SciPy references on one random batch, in one process; writes ``results/bench/``
(``bench.json``, ``bench.parquet``, ``report.md``, ``figures/throughput.png|svg``) and prints the summary.
Speed is measured here, never asserted in tests.
"""

import sys

import pfjax  # noqa: F401  (before JAX: one CPU device per core)
from pfjax.cli import main

if __name__ == "__main__":
    sys.exit(main(["bench", *sys.argv[1:]]))
