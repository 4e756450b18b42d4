"""The performance benchmark: pfjax's simulator against NumPy, Numba and SciPy references
(``pfjax bench``, ``studies/bench/bench.py``). Numba is optional (``pip install 'pfjax[bench]'``):
without it the Numba reference is skipped and the result's notes say so."""
