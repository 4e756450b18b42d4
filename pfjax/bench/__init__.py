"""The performance benchmark: pfjax's simulator against NumPy, Numba and SciPy references
(``pfjax bench``, ``studies/bench/bench.py``)."""
