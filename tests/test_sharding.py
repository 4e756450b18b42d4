"""Sharding the batch over devices: one CPU device per core by default, and 1 vs 2 devices give the
same results run for run.

The device count of a process is fixed when JAX starts, so the comparison runs the same study in
two subprocesses, one with ``PFJAX_HOST_DEVICES=1`` and one with two forced host devices.
"""

import os
import subprocess
import sys

import jax
import numpy as np
import pandas as pd
import pytest

import pfjax
import pfjax.metrics.running
from pfjax.sim import sharding

STUDY = """name = "shard"
n_runs = 45
seed = 3
chunk_size = 45
dtype = "{dtype}"
f64_check_runs = 0
[sim]
horizon = 2.0
steady_window = 1.0
[success]
from_s = 1.0
band = 0.2
[slip]
kind = "ou"
beta_r_deg = {{ dist = "uniform", low = -5, high = 5 }}
ou_sigma_deg = 2.0
[initial]
lateral_offset = {{ dist = "uniform", low = -0.3, high = 0.3 }}
[noise]
sigma_d = 0.01
[margin]
enabled = false
[[paths]]
kind = "sine"
[[controllers]]
name = "pi"
type = "pi"
"""  # one controller with state (the PI's integrators): the sharding does not depend on the controller

CHILD = """
import sys
import pfjax  # before JAX: sets the host device count from PFJAX_HOST_DEVICES
import jax
assert jax.device_count() == int(sys.argv[1]), jax.devices()
from pfjax.cli import main
sys.exit(main(["study", sys.argv[2], "--out", sys.argv[3], "--no-report", "--quiet"]))
"""


def test_default_host_devices_asks_for_one_device_per_core():
    env = {}
    assert pfjax.default_host_devices(env, modules={}) == (len(os.sched_getaffinity(0)) > 1)
    if len(os.sched_getaffinity(0)) > 1:
        assert env["XLA_FLAGS"] == f"--xla_force_host_platform_device_count={len(os.sched_getaffinity(0))}"
    env = {"PFJAX_HOST_DEVICES": "3", "XLA_FLAGS": "--xla_cpu_foo=1"}
    assert pfjax.default_host_devices(env, modules={})
    assert env["XLA_FLAGS"] == "--xla_cpu_foo=1 --xla_force_host_platform_device_count=3"
    for env, modules in (({"PFJAX_HOST_DEVICES": "1"}, {}),  # opted out
                         ({"XLA_FLAGS": "--xla_force_host_platform_device_count=4"}, {}),  # the user's own count
                         ({}, {"jax": object()})):  # too late: JAX is imported
        before = dict(env)
        assert not pfjax.default_host_devices(env, modules=modules)
        assert env == before


def test_shard_batch_pads_and_unpad_restores():
    tree = {"a": np.arange(5.0), "b": np.arange(10.0).reshape(5, 2)}
    sharded, n = sharding.shard_batch(tree, devices=jax.devices()[:1])
    assert n == 5 and sharded is tree  # one device: untouched
    padded = sharding._pad(tree, 8)
    assert padded["a"].shape == (8,) and np.all(np.asarray(padded["a"][5:]) == 0.0)  # copies of run 0
    back = sharding.unpad(padded, 5)
    np.testing.assert_array_equal(back["b"], tree["b"])


@pytest.mark.slow
@pytest.mark.parametrize("dtype", ["float32", "float64"])
def test_one_and_two_host_devices_give_the_same_runs(tmp_path, dtype):
    """45 runs (padded to 64, split 32 + 32 over two devices) of the PI controller with OU slip and
    sensor noise. float64: the run tables are bit-identical. float32: the sampled parameters,
    statuses, success flags and failure times are identical, and every metric agrees to 1e-6
    relative (XLA compiles the 32-run and the 64-run blocks into different vector code, which may
    round an accumulated metric differently in its last bit: measured 1-2 ulp in a few runs)."""
    cfg = tmp_path / "s.toml"
    cfg.write_text(STUDY.format(dtype=dtype))
    tables = {}
    for n in (1, 2):
        env = dict(os.environ, PFJAX_HOST_DEVICES=str(n), XLA_FLAGS="", JAX_PLATFORMS="cpu")
        out = tmp_path / f"dev{n}"
        r = subprocess.run([sys.executable, "-c", CHILD, str(n), str(cfg), str(out)], env=env, capture_output=True,
                           text=True, timeout=600)
        assert r.returncode == 0, r.stderr[-3000:]
        tables[n] = pd.read_parquet(out / "runs.parquet")
    one, two = tables[1], tables[2]
    assert len(one) == 45 and one["iae"].dtype == np.dtype(dtype)
    if dtype == "float64":
        pd.testing.assert_frame_equal(one, two, check_exact=True)
        return
    metrics = [m for m in pfjax.metrics.running.METRIC_NAMES if m != "success"]
    exact = [c for c in one.columns if c not in metrics]
    pd.testing.assert_frame_equal(one[exact], two[exact], check_exact=True)
    pd.testing.assert_frame_equal(one[metrics], two[metrics], check_exact=False, rtol=1e-6, atol=0)
