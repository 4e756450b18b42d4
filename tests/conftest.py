"""Test configuration: float64 everywhere (references are compared to ~1e-9), CPU only, one
persistent compilation cache shared by the test workers and the notebook kernels they start
(``.pytest_cache/xla``: a program compiled by one test is loaded, not compiled, by the next)."""

import os
from pathlib import Path

os.environ.setdefault("JAX_PLATFORMS", "cpu")
os.environ.setdefault("PFJAX_CACHE_DIR", str(Path(__file__).resolve().parents[1] / ".pytest_cache" / "xla"))

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)

from pfjax import cache  # noqa: E402

cache.enable()
