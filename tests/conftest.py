"""Test configuration: float64 everywhere (references are compared to ~1e-9), CPU only, one device
per worker with pfjax's compiler settings, one
persistent compilation cache shared by the test workers and the notebook kernels they start
(``.pytest_cache/xla``: a program compiled by one test is loaded, not compiled, by the next)."""

import os
from pathlib import Path

os.environ.setdefault("JAX_PLATFORMS", "cpu")
os.environ.setdefault("PFJAX_CACHE_DIR", str(Path(__file__).resolve().parents[1] / ".pytest_cache" / "xla"))
# Studies draw their report figures in-process here (each figure worker costs ~2 s of CPU to start);
# tests/test_study_report.py runs its study with the worker and checks it against in-process figures.
os.environ.setdefault("PFJAX_FIGURE_WORKER", "0")
# The suite's numbers must not depend on a calibration the machine's user measured (pfjax calibrate).
os.environ.setdefault("PFJAX_CALIBRATION", "off")
# Before JAX: the compiler settings users get (pfjax.small_loop_option), but one CPU device per
# xdist worker (2 workers on 2 cores); subprocesses (CLI, notebooks) still get one per core.
_host = os.environ.get("PFJAX_HOST_DEVICES")
os.environ["PFJAX_HOST_DEVICES"] = "1"
import pfjax  # noqa: E402,F401

if _host is None:
    del os.environ["PFJAX_HOST_DEVICES"]
else:
    os.environ["PFJAX_HOST_DEVICES"] = _host

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)

from pfjax import cache  # noqa: E402

cache.enable()
