"""Sharding the batch over devices: one CPU device per core by default, and 1 vs 2 devices give the
same results run for run.

The device count of a process is fixed when JAX starts, so the comparison runs the same study in
two subprocesses, one with ``PFJAX_HOST_DEVICES=1`` and one with two forced host devices.
"""

import importlib
import math
import os
import subprocess
import sys
from types import SimpleNamespace

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
for cfg, out in zip(sys.argv[2::2], sys.argv[3::2]):  # (config, --out) pairs, one study after the other
    rc = main(["study", cfg, "--out", out, "--no-report", "--quiet"])
    if rc:
        sys.exit(rc)
"""


def test_default_host_devices_asks_for_one_device_per_core():
    env = {}
    assert pfjax.default_host_devices(env, modules={}) == (len(os.sched_getaffinity(0)) > 1)
    if len(os.sched_getaffinity(0)) > 1:
        assert env["XLA_FLAGS"] == f"--xla_force_host_platform_device_count={len(os.sched_getaffinity(0))}"
    env = {"PFJAX_HOST_DEVICES": "3", "XLA_FLAGS": "--xla_cpu_foo=1"}
    assert pfjax.default_host_devices(env, modules={})
    assert env["XLA_FLAGS"] == "--xla_cpu_foo=1 --xla_force_host_platform_device_count=3"
    for env, modules in (
        ({"PFJAX_HOST_DEVICES": "1"}, {}),  # opted out
        ({"XLA_FLAGS": "--xla_force_host_platform_device_count=4"}, {}),  # the user's own count
        ({}, {"jax": object()}),
    ):  # too late: JAX is imported
        before = dict(env)
        assert not pfjax.default_host_devices(env, modules=modules)
        assert env == before


def test_small_loop_option_sets_the_threshold_unless_the_user_did():
    env = {"XLA_FLAGS": "--xla_cpu_foo=1"}
    assert pfjax.small_loop_option(env, modules={})
    assert env["XLA_FLAGS"] == (
        f"--xla_cpu_foo=1 --xla_backend_extra_options=xla_cpu_small_while_loop_byte_threshold={pfjax.SMALL_LOOP_BYTES}"
    )
    env = {"PFJAX_SMALL_LOOP_BYTES": "1000"}
    assert pfjax.small_loop_option(env, modules={}) and env["XLA_FLAGS"].endswith("threshold=1000")
    for env, modules in (
        ({"PFJAX_SMALL_LOOP_BYTES": "0"}, {}),  # opted out
        ({"XLA_FLAGS": "--xla_backend_extra_options=xla_cpu_foo=2"}, {}),  # the user's own
        ({}, {"jax": object()}),
    ):  # too late: JAX is imported
        before = dict(env)
        assert not pfjax.small_loop_option(env, modules=modules)
        assert env == before


def test_a_setting_in_the_environment_that_is_not_a_number_is_ignored_with_a_warning():
    """PFJAX_HOST_DEVICES, PFJAX_SMALL_LOOP_BYTES and PFJAX_MEMORY_BUDGET set to something that is not
    a whole number: the default, and a warning naming the variable (not silence)."""
    from pfjax.resources import memory_budget

    with pytest.warns(UserWarning, match="^PFJAX_HOST_DEVICES: value 'abc' ignored"):
        env = {"PFJAX_HOST_DEVICES": "abc"}
        assert pfjax.default_host_devices(env, modules={}) == (len(os.sched_getaffinity(0)) > 1)
    with pytest.warns(UserWarning, match="^PFJAX_SMALL_LOOP_BYTES: value '1e6' ignored"):
        env = {"PFJAX_SMALL_LOOP_BYTES": "1e6"}
        assert pfjax.small_loop_option(env, modules={}) and env["XLA_FLAGS"].endswith(f"={pfjax.SMALL_LOOP_BYTES}")
    with pytest.warns(UserWarning, match="^PFJAX_MEMORY_BUDGET: value '8GB' ignored"):
        assert memory_budget({"PFJAX_MEMORY_BUDGET": "8GB"}) == memory_budget({})
    assert memory_budget({"PFJAX_MEMORY_BUDGET": "123"}) == 123


def test_shard_batch_pads_and_unpad_restores():
    tree = {"a": np.arange(5.0), "b": np.arange(10.0).reshape(5, 2)}
    sharded, n = sharding.shard_batch(tree, devices=jax.devices()[:1])
    assert n == 5 and sharded is tree  # one device: untouched
    padded = sharding._pad(tree, 8)
    assert padded["a"].shape == (8,) and np.all(np.asarray(padded["a"][5:]) == 0.0)  # copies of run 0
    back = sharding.unpad(padded, 5)
    np.testing.assert_array_equal(back["b"], tree["b"])


UNPAD_CHILD = """
import pfjax  # before JAX: two host devices (PFJAX_HOST_DEVICES=2)
import jax
import numpy as np
from pfjax.sim import sharding

assert jax.device_count() == 2, jax.devices()
tree = {"a": np.arange(9.0, dtype=np.float32), "b": np.arange(18.0).reshape(9, 2)}  # 9 runs: padded to 10
placed, n, _ = sharding.plan_batch(tree, None, block=None)
assert placed["a"].shape[0] > n and len(placed["a"].sharding.device_set) == 2
def fail(*a):
    raise AssertionError("cut in a program")
sharding._head_jit = fail
out = sharding.unpad(placed, n)
for k in tree:
    np.testing.assert_array_equal(np.asarray(out[k]), tree[k])
    assert len(out[k].sharding.device_set) == 1
print("ok")
"""


def test_a_padded_batch_over_several_devices_is_cut_without_a_collective():
    """unpad cuts a batch spread over devices on the host (no program, so no rendezvous of the devices
    that another thread's work could hold up) and gives the same runs, on one device."""
    env = dict(os.environ, PFJAX_HOST_DEVICES="2")
    env.pop("XLA_FLAGS", None)
    out = subprocess.run([sys.executable, "-c", UNPAD_CHILD], env=env, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0 and out.stdout.strip() == "ok", out.stderr[-2000:]


def test_plan_batch_splits_devices_into_blocks():
    tree = {"a": np.arange(11.0)}
    devices = jax.devices()
    placed, n, layout = sharding.plan_batch(tree, devices, block=3)
    k = len(devices)
    per_device = -(-11 // k)
    blocks = -(-per_device // 3)
    assert n == 11 and layout.blocks == blocks and (layout.mesh is None) == (k == 1)
    size = placed["a"].shape[0]
    assert (
        size % (k * blocks) == 0 and size // (k * blocks) <= 3 and size - 11 < k * blocks
    )  # padding < 1 run per block
    np.testing.assert_array_equal(np.asarray(placed["a"])[11:], 0.0)  # copies of run 0
    placed, _, layout = sharding.plan_batch({"a": np.arange(1001.0)}, devices, block=None)
    per = placed["a"].shape[0] // k
    assert layout.blocks == 1 and per % sharding.ALIGN == 0 and 0 <= per - -(-1001 // k) < sharding.ALIGN
    assert sharding.plan_batch(tree, devices[:1], block=None)[2] == sharding.Layout(None, 1)  # placed: runs 0
    # block sizes: the rule's bytes per array on CPU, none on another platform
    rule = sharding.block_bytes_rule()  # the tests run without a calibration (conftest)
    assert sharding.default_block({"x": np.zeros(3, np.float32)}, devices[:1]) == rule // 4
    assert sharding.default_block({"x": np.zeros(3, np.float64)}, devices[:1]) == rule // 8
    assert sharding.default_block({"x": np.zeros(3)}, [SimpleNamespace(platform="tpu")]) is None
    # the one decision between the CPU's and the GPU's rule
    assert sharding.block_platform(devices[:1]) == "cpu" and sharding.block_platform() == "cpu"
    assert sharding.block_platform([SimpleNamespace(platform="gpu")]) == "gpu"
    assert sharding.block_platform([SimpleNamespace(platform="tpu")]) is None


def test_gpu_blocks_hold_the_gpu_rules_bytes_per_array(monkeypatch):
    """On a GPU a block holds :data:`GPU_BLOCK_BYTES` per array (1 MB: 250,000 float32 runs, 125,000
    float64, fewer for forward-mode tangents); ``PFJAX_GPU_BLOCK_BYTES`` overrides it, ``0`` runs the
    whole batch at once, and a value that is not a whole number is ignored with a warning naming it."""
    gpu = [SimpleNamespace(platform="gpu")]
    f32, f64 = {"x": np.zeros(3, np.float32)}, {"x": np.zeros(3, np.float64)}
    monkeypatch.delenv(sharding.GPU_BLOCK_ENV, raising=False)
    assert sharding.GPU_BLOCK_BYTES == 1_000_000 and sharding.gpu_block_bytes() == 1_000_000
    assert sharding.default_block(f32, gpu) == 250_000 and sharding.default_block(f64, gpu) == 125_000
    assert sharding.default_block(f32, gpu, tangents=2) == 83_333
    monkeypatch.setenv(sharding.GPU_BLOCK_ENV, " 400000 ")
    assert sharding.default_block(f32, gpu) == 100_000 and sharding.default_block(f64, gpu) == 50_000
    monkeypatch.setenv(sharding.GPU_BLOCK_ENV, "0")
    assert sharding.gpu_block_bytes() is None and sharding.default_block(f32, gpu) is None
    monkeypatch.setenv(sharding.GPU_BLOCK_ENV, "1MB")
    with pytest.warns(UserWarning, match=f"^{sharding.GPU_BLOCK_ENV}: value '1MB' ignored"):
        assert sharding.default_block(f32, gpu) == 250_000
    # the CPU's blocks do not read it
    assert sharding.default_block(f32, jax.devices()[:1]) == sharding.block_bytes_rule() // 4
    # a batch planned for a GPU in the rule's blocks: 10^6 float32 runs in 4 blocks (no device needed)
    assert sharding.traced_layout(1_000_000, 250_000, 1).blocks == 4


def test_a_traced_batch_is_split_into_interleaved_blocks_only_when_given_a_size():
    """Under ``jit`` an ``"auto"`` or ``None`` block leaves the batch whole; a number of runs splits
    it inside the program (the device shares padded at their ends, interleaved blocks), and the runs
    come back in their order, with no run moved between devices where the run count is a multiple
    of them."""
    from pfjax import errors

    devices = jax.devices()
    k, seen = len(devices), {}

    def run(tree, block):
        placed, n, layout = sharding.plan_batch(tree, devices, block=block)
        seen[(placed["a"].shape[0], block)] = layout
        return sharding.unpad(sharding.map_runs(lambda t: 10.0 * t["a"] + t["b"], placed, layout), n)

    for n in (11, 12 * k):
        tree = {"a": np.arange(float(n)), "b": np.arange(float(n)) ** 2}
        for block in ("auto", None, 2):
            out = jax.jit(lambda t, block=block: run(t, block))(tree)
            np.testing.assert_array_equal(out, 10.0 * tree["a"] + tree["b"])
        # runs: each device's runs in all its blocks (they decide reverse mode's checkpoints)
        assert seen[(n, "auto")] == seen[(n, None)] == sharding.Layout(None, 1, runs=math.ceil(n / k))
        blocks = math.ceil(math.ceil(n / k) / 2)
        shares = k if n % k == 0 else 1
        size = math.ceil(n // shares / blocks)
        assert seen[(n, 2)] == sharding.Layout(None, blocks, shares, size, runs=math.ceil(blocks * size * shares / k))
    if k > 1:  # the runs stay on their devices: no collective moves them
        placed, _ = sharding.shard_batch({"a": np.arange(24.0 * k)})
        text = jax.jit(lambda t: run(t, 5)).lower({"a": placed["a"], "b": placed["a"]}).compile().as_text()
        for collective in ("all-gather", "all-to-all", "collective-permute"):
            assert collective not in text
    for bad in (0, -3, 2.5, "big"):
        with pytest.raises(errors.InputError, match="^block: "):
            sharding.plan_batch({"a": np.arange(4.0)}, devices, block=bad)
    # the splits themselves: block j holds runs j, j + 3, j + 6, j + 9 (interleaved) or 4j..4j + 3
    runs = {"a": np.arange(12.0), "b": np.arange(24.0).reshape(12, 2)}
    inter, contiguous = sharding.split_blocks(runs, 3, True), sharding.split_blocks(runs, 3)
    np.testing.assert_array_equal(inter["a"], [[0, 3, 6, 9], [1, 4, 7, 10], [2, 5, 8, 11]])
    np.testing.assert_array_equal(inter["b"][1], runs["b"][1::3])
    np.testing.assert_array_equal(contiguous["a"], np.arange(12.0).reshape(3, 4))
    for split, interleaved in ((inter, True), (contiguous, False)):
        back = sharding.join_blocks(split, interleaved)
        np.testing.assert_array_equal(back["a"], runs["a"])
        np.testing.assert_array_equal(back["b"], runs["b"])


def test_forward_mode_blocks_share_an_arrays_budget():
    """A value and its D tangents share one array's budget: 1 + D times fewer runs per block."""
    cpu = jax.devices()[:1]
    tree = {"x": np.zeros(3, np.float32)}
    for tangents in (0, 1, 2, 4):
        want = sharding.cpu_block_bytes(4) // (4 * (1 + tangents))
        assert sharding.default_block(tree, cpu, tangents=tangents) == want
    with pytest.raises(ValueError, match="tangents"):
        sharding.default_block(tree, cpu, tangents=-1)


def test_forward_mode_gradients_in_blocks_equal_the_unblocked_ones():
    """The value and gradient (forward mode, 2 gains) of a batch-mean IAE through ``simulate_batch``
    under ``jit``, 13 runs in blocks of 2 runs per device (padded, interleaved) and whole: equal to
    1e-12 relative in float64 (each block shape is compiled into its own vector code, so a metric
    may differ by an ulp; measured bit-identical)."""
    import jax.numpy as jnp

    from pfjax.bench import problem as P
    from pfjax.controllers import state_feedback
    from pfjax.numerics import autodiff
    from pfjax.sim import SimConfig, simulate_batch

    sc = P.scenarios(P.random_batch(13, seed=2), np.float64)
    config = SimConfig(horizon=0.5, record=False)

    def loss(K, block):
        gains = sc.gains._replace(K=jnp.broadcast_to(K, sc.gains.K.shape))
        res = simulate_batch(sc._replace(gains=gains), controller=state_feedback, config=config, block=block)
        return jnp.mean(res.metrics.iae)

    K = jnp.asarray(P.K, jnp.float64)
    whole = jax.jit(autodiff.value_and_grad(lambda K: loss(K, "auto")))(K)
    blocked = jax.jit(autodiff.value_and_grad(lambda K: loss(K, 2)))(K)
    np.testing.assert_allclose(blocked[0], whole[0], rtol=1e-12)
    np.testing.assert_allclose(blocked[1], whole[1], rtol=1e-12)
    assert np.all(np.asarray(whole[1]) != 0.0)


def _tracking_batch(n: int, seed: int):
    """``n`` followers on a straight leader, alternately forward and backward, displaced at random."""
    from pfjax import tracking as T
    from pfjax.tracking import leader as L

    line = L.line(speed=1.0, heading=0.4)
    prm = [T.FollowerParams(a=1.0, f=f, l=f, p=f * (1.0 + 0.1 * i)) for i, f in enumerate(([1.0, -1.0] * n)[:n])]
    rng = np.random.default_rng(seed)
    inits = T.initial_states(
        T.stack([line] * n), T.stack(prm), rng.uniform(-0.5, 0.5, (n, 2)), rng.uniform(-0.3, 0.3, n)
    )
    return T.stack([T.scenario(p, line, init=T.unstack(inits, i)) for i, p in enumerate(prm)])


def _assert_same_runs(ref, got, msg: str) -> None:
    """Leaf by leaf: the same shapes, integers equal, floats to 1e-13 relative (1e-15 absolute)."""
    for a, b in zip(jax.tree_util.tree_leaves(ref), jax.tree_util.tree_leaves(got)):
        assert np.shape(a) == np.shape(b), msg
        if np.asarray(a).dtype.kind == "f":
            np.testing.assert_allclose(a, b, rtol=1e-13, atol=1e-15, err_msg=msg)
        else:
            np.testing.assert_array_equal(a, b, err_msg=msg)


@pytest.mark.parametrize("model", ["slip", "tracking"])
def test_blocks_and_devices_give_the_same_runs(model):
    """The same 11 runs in one block on one device, in blocks of 3 and 4 (padded), and over every
    device: identical statuses and integer results, floats equal to 1e-13 relative. Each run is
    computed by the same per-run code, but XLA compiles each block shape into its own vector code,
    which may contract a multiply-add differently (measured: at most 1 ulp, 4e-16 m s, in a few runs'
    IAE)."""
    if model == "slip":
        from pfjax.bench import problem as P
        from pfjax.controllers import state_feedback
        from pfjax.sim import SimConfig, simulate_batch

        sc = P.scenarios(P.random_batch(11, seed=1), np.float64)
        go = lambda **kw: simulate_batch(
            sc, controller=state_feedback, config=SimConfig(horizon=0.5, record=True), **kw
        )
    else:
        from pfjax import tracking as T

        scs = _tracking_batch(11, seed=0)
        go = lambda **kw: T.simulate_batch(scs, config=T.TrackConfig(dt=0.01, horizon=1.0), **kw)
    ref = jax.device_get(go(devices=jax.devices()[:1], block=None))
    for kw in ({"block": 3}, {"devices": jax.devices()[:1], "block": 4}, {"block": None}, {}):
        got = jax.device_get(go(**kw))
        for a, b in zip(jax.tree_util.tree_leaves(ref), jax.tree_util.tree_leaves(got)):
            assert a.dtype == b.dtype == (np.float64 if a.dtype.kind == "f" else a.dtype)
        _assert_same_runs(ref, got, str(kw))


@pytest.mark.parametrize("model", ["slip", "st", "tracking"])
def test_one_run_alone_gives_its_numbers_in_a_batch(model):
    """``simulate_one`` (the unbatched program ``pfjax simulate`` calls) on each of 3 runs against the
    same runs of a batch of 3: identical statuses and integer results, floats to 1e-13 relative. The
    per-run code is the same; XLA compiles the unbatched program into other machine code, which may
    round a step's arithmetic differently in its last bit (measured: at most 1 ulp in a metric)."""
    from pfjax.sim import SimConfig, stack, unstack

    if model == "slip":
        from pfjax.bench import problem as P
        from pfjax.controllers import state_feedback
        from pfjax.sim.simulate import simulate_batch, simulate_one

        batch = P.scenarios(P.random_batch(3, seed=2), np.float64)
        controller = state_feedback
    elif model == "tracking":
        from pfjax import tracking as T

        batch = _tracking_batch(3, seed=3)
        cfg = T.TrackConfig(dt=0.01, horizon=1.0, record=True)
        run_batch = lambda b: T.simulate_batch(b, config=cfg)
        run_one = lambda sc: T.simulate_one(sc, config=cfg)
    else:
        from pfjax import controllers as C
        from pfjax import paths
        from pfjax.sim.dynamic import simulate_batch, simulate_one
        from pfjax.sim.scenario import make_dynamic_scenario

        e = C.entry("stanley")
        gains = C.params_from_flat(e, C.flat_gains(e))
        sine = paths.entry("sine")
        assert sine.build is not None and sine.start_pose is not None
        batch = stack([make_dynamic_scenario(sine.build(), sine.start_pose, gains, mu=mu) for mu in (0.3, 0.6, 1.0)])
        controller = e.controller
    if model != "tracking":
        cfg = SimConfig(horizon=0.5, record=True)
        run_batch = lambda b: simulate_batch(b, controller=controller, config=cfg)
        run_one = lambda sc: simulate_one(sc, controller=controller, config=cfg)
    ref = jax.device_get(run_batch(batch))
    for i in range(3):
        _assert_same_runs(unstack(ref, i), jax.device_get(run_one(unstack(batch, i))), f"run {i}")


@pytest.fixture(scope="module")
def device_runs(tmp_path_factory):
    """The study (float32 and float64) run by a process with one host device and by a process with
    two: ``{devices: directory}``, each holding ``float32/`` and ``float64/`` outputs."""
    base = tmp_path_factory.mktemp("devices")
    pairs = []
    for dtype in ("float32", "float64"):
        cfg = base / f"{dtype}.toml"
        cfg.write_text(STUDY.format(dtype=dtype))
        pairs.append((cfg, dtype))
    dirs = {}
    for n in (1, 2):
        env = dict(os.environ, PFJAX_HOST_DEVICES=str(n), XLA_FLAGS="", JAX_PLATFORMS="cpu")
        dirs[n] = base / f"dev{n}"
        args = [str(a) for cfg, dtype in pairs for a in (cfg, dirs[n] / dtype)]
        r = subprocess.run(
            [sys.executable, "-c", CHILD, str(n), *args], env=env, capture_output=True, text=True, timeout=600
        )
        assert r.returncode == 0, r.stderr[-3000:]
    return dirs


@pytest.mark.slow
@pytest.mark.parametrize("dtype", ["float32", "float64"])
def test_one_and_two_host_devices_give_the_same_runs(device_runs, dtype):
    """45 runs (padded to 64, split 32 + 32 over two devices) of the PI controller with OU slip and
    sensor noise. float64: the run tables are bit-identical. float32: the sampled parameters,
    statuses, success flags and failure times are identical, and every metric agrees to 1e-5
    relative, or, for the metrics in metres, to 1e-6 m (4 float32 ulps of the vehicle's coordinates,
    which stay below 2 m: the lateral error is a difference of coordinates, so its rounding is
    absolute). XLA compiles the 32-run and the 64-run blocks into different vector code, which may
    round a step's arithmetic differently in its last bit; the closed loop and the 400-step sums
    carry that along. Measured (Zen 4): bit-identical with XLA's default vector width; with the
    512-bit vectors pfjax asks for on AVX-512 CPUs (pfjax.numerics.compiler) in 1-35 of the 45 runs
    per metric, at most 3.2e-6 relative, except the late maximum of |d|: 1.2e-7 m on 8 mm (1.5e-5
    relative, half an ulp of a 2 m coordinate)."""
    one, two = (pd.read_parquet(device_runs[n] / dtype / "runs.parquet") for n in (1, 2))
    assert len(one) == 45 and one["iae"].dtype == np.dtype(dtype)
    if dtype == "float64":
        pd.testing.assert_frame_equal(one, two, check_exact=True)
        return
    metrics = [m for m in pfjax.metrics.running.METRIC_NAMES if m != "success"]
    exact = [c for c in one.columns if c not in metrics]
    pd.testing.assert_frame_equal(one[exact], two[exact], check_exact=True)
    metres = ["max_abs_d", "steady_abs_d", "late_max_abs_d"]
    others = [m for m in metrics if m not in metres]
    pd.testing.assert_frame_equal(one[others], two[others], check_exact=False, rtol=1e-5, atol=0)
    pd.testing.assert_frame_equal(one[metres], two[metres], check_exact=False, rtol=1e-5, atol=1e-6)


@pytest.mark.parametrize("model", ["slip", "st"])
def test_reverse_mode_in_checkpointed_segments_gives_the_per_sample_gradient(model, monkeypatch):
    """A traced batch tells the loop how many runs each device evaluates together
    (``Layout.runs``; a placed batch, never differentiated, 0), and past
    :data:`pfjax.sim.loop.SEGMENT_BYTES` of carry the loop checkpoints its samples in segments.
    The gradient is the per-sample checkpoints' (float64, 1e-12 relative: the same arithmetic,
    compiled into other machine code), for the slip vehicle and the dynamic (ST) vehicle."""
    import jax.numpy as jnp

    from pfjax import controllers as C
    from pfjax.sim import SimConfig, loop, stack

    cfg = SimConfig(dt=0.01, horizon=0.37, record=False)  # 38 samples: segments of 7, a tail of 3
    if model == "slip":
        from pfjax.bench import problem as P

        sim = importlib.import_module("pfjax.sim.simulate")  # the module (the package exports the function)
        batch, controller = P.scenarios(P.random_batch(13, seed=4), np.float64), C.state_feedback
        name = "K"
    else:
        from pfjax import paths
        from pfjax.sim.scenario import make_dynamic_scenario

        e = C.entry("stanley")
        gains = C.params_from_flat(e, C.flat_gains(e))
        sine = paths.entry("sine")
        assert sine.build is not None and sine.start_pose is not None
        runs = [make_dynamic_scenario(sine.build(), sine.start_pose, gains, mu=0.4 + 0.05 * i) for i in range(13)]
        batch, controller, name = stack(runs), e.controller, "k"
        sim = importlib.import_module("pfjax.sim.dynamic")
    gain = getattr(batch.gains, name)
    assert loop.checkpoint_segment(cfg.n_steps + 1, 1, 10**9) == 7

    def loss(g, runs):
        sc = batch._replace(gains=batch.gains._replace(**{name: g}))
        res = jax.vmap(lambda s: sim.simulate(controller, s, cfg, runs=runs))(sc)
        return jnp.sum(res.metrics.iae)

    g1, g2 = (np.asarray(jax.jit(jax.grad(lambda g, r=r: loss(g, r)))(gain)) for r in (1, 10**9))
    assert np.all(np.isfinite(g1)) and np.any(g1 != 0.0)
    np.testing.assert_allclose(g2, g1, rtol=1e-12, atol=1e-15)

    seen = []
    real = loop.run
    monkeypatch.setattr(loop, "run", lambda *a, **kw: seen.append(kw["runs"]) or real(*a, **kw))
    # every traced batch in segments: SEGMENT_BYTES is read when the loop is traced and is in no
    # cache key, so this test's config (a 0.37 s horizon) is traced nowhere else; `seen` below
    # proves the loop was traced anew
    monkeypatch.setattr(loop, "SEGMENT_BYTES", 0)

    def batch_loss(g):
        sc = batch._replace(gains=batch.gains._replace(**{name: g}))
        return jnp.sum(sim.simulate_batch(sc, controller=controller, config=cfg).metrics.iae)

    k = len(jax.devices())
    text = str(jax.make_jaxpr(jax.grad(batch_loss))(gain))
    assert seen == [-(-13 // k)] and text.count("scan[") > 1
    np.testing.assert_allclose(np.asarray(jax.jit(jax.grad(batch_loss))(gain)), g1, rtol=1e-12, atol=1e-15)
    seen.clear()
    sim.simulate_batch(batch, controller=controller, config=cfg)  # placed: never differentiated
    assert seen == [0]
