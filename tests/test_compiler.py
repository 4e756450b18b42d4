"""The simulators' compiler options (pfjax.numerics.compiler): 512-bit vectors on AVX-512 CPUs.

XLA's own atan is wrong under the option, so the option is set per program and never in
``XLA_FLAGS``; these tests check the choice of the option, that every simulator entry point
carries it, and that each simulator gives the same results with and without it (float64 to
1e-12 relative: the same arithmetic in other vector lanes; float32 to rounding accumulated over
the run). pfjax's elementary functions are checked under it in tests/test_elementary.py.
"""

import os

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from pfjax.numerics import compiler

WIDE = {"xla_cpu_prefer_vector_width": 512}


def _cpuinfo(tmp_path, flags):
    p = tmp_path / "cpuinfo"
    p.write_text(f"processor\t: 0\nmodel name\t: test\nflags\t\t: {flags}\n\nprocessor\t: 1\nflags\t\t: {flags}\n")
    return str(p)


def test_avx512_is_read_from_the_cpu_flags(tmp_path):
    assert compiler.has_avx512(_cpuinfo(tmp_path, "fpu sse2 avx2 fma avx512f avx512dq avx512vl"))
    assert not compiler.has_avx512(_cpuinfo(tmp_path, "fpu sse2 avx2 fma"))
    assert not compiler.has_avx512(_cpuinfo(tmp_path, "fpu avx512_bf16"))  # not Foundation
    assert not compiler.has_avx512(str(tmp_path / "missing"))


def test_cpu_info_reads_the_first_processor(tmp_path):
    p = tmp_path / "cpuinfo"
    p.write_text(
        "processor\t: 0\nvendor_id\t: AuthenticAMD\ncpu family\t: 26\nmodel\t\t: 2\nmodel name\t: AMD EPYC\n"
        "flags\t\t: fpu avx512f\n\nprocessor\t: 1\ncpu family\t: 25\nmodel name\t: other\n"
    )
    assert compiler.cpu_info(str(p)) == {
        "vendor_id": "AuthenticAMD",
        "cpu family": "26",
        "model": "2",
        "model name": "AMD EPYC",
        "flags": "fpu avx512f",
    }
    assert compiler.cpu_info(str(tmp_path / "missing")) == {}
    if os.path.exists(compiler.CPUINFO):  # this machine's: the bench records it
        assert compiler.cpu_info()["flags"]


def test_vector_width_choice_and_override(tmp_path):
    wide, narrow = _cpuinfo(tmp_path, "avx2 avx512f"), str(tmp_path / "missing")
    assert compiler.options({}, wide) == WIDE
    assert compiler.options({}, narrow) == {}
    assert compiler.options({"PFJAX_VECTOR_WIDTH": "0"}, wide) == {}
    assert compiler.options({"PFJAX_VECTOR_WIDTH": "256"}, wide) == {"xla_cpu_prefer_vector_width": 256}
    assert compiler.options({"PFJAX_VECTOR_WIDTH": "512"}, narrow) == WIDE
    with pytest.warns(UserWarning, match="PFJAX_VECTOR_WIDTH"):
        assert compiler.options({"PFJAX_VECTOR_WIDTH": "wide"}, narrow) == {}


def test_the_option_is_not_process_wide():
    """A user's own program in the same process keeps XLA's defaults (and a correct jnp.arctan)."""
    import os

    assert "prefer_vector_width" not in os.environ.get("XLA_FLAGS", "")
    x = np.linspace(-50.0, 50.0, 4096)
    np.testing.assert_allclose(np.asarray(jax.jit(jnp.arctan)(x)), np.arctan(x), rtol=1e-15)


def _kvs(f):
    kvs = getattr(getattr(f, "_jit_info", None), "compiler_options_kvs", None)
    if kvs is None:
        pytest.skip("this JAX keeps a jitted function's compiler options elsewhere")
    return dict(kvs)


def test_every_simulator_entry_point_carries_the_options():
    from importlib import import_module

    # the modules (the packages export functions of the same name)
    slip, tracking, parking = (import_module(f"pfjax.{p}.simulate") for p in ("sim", "tracking", "parking"))
    for f in (
        slip._simulate_vmapped,
        tracking._simulate_vmapped,
        parking.run_jit,
        parking.run_recorded_jit,
        parking.run_batch,
    ):
        assert _kvs(f) == compiler.OPTIONS
    with pytest.MonkeyPatch.context() as m:
        m.setattr(compiler, "OPTIONS", dict(WIDE))
        f = compiler.jit(lambda x: x)
        assert _kvs(f) == WIDE and _kvs(f.top) == WIDE and _kvs(f.nested) == {}
        assert _kvs(compiler.jit(static_argnums=1)(lambda x, n: x * n)) == WIDE
        m.setattr(compiler, "OPTIONS", {})
        assert _kvs(compiler.jit(lambda x: x)) == {}


def test_top_level_is_read_from_jax():
    from jax._src.core import trace_state_clean  # noqa: F401  (at_top_level reads it: moved, this fails)

    seen = []
    spy = lambda x: (seen.append(compiler.at_top_level()), x)[1]
    assert compiler.at_top_level()
    jax.jit(spy)(1.0), jax.vmap(spy)(np.ones(2)), jax.grad(spy)(1.0)
    assert seen == [False, False, False]


def test_a_wide_program_runs_inside_other_transformations():
    """JAX accepts compiler options on the outermost jit only: inside a user's jit, grad or vmap,
    or with a batch closed over as a constant, the simulator is traced plainly into that program."""
    from pfjax.bench import problem as P
    from pfjax.controllers import state_feedback
    from pfjax.sim import SimConfig, simulate_batch

    cfg = SimConfig(dt=0.01, horizon=0.5, record=False)
    with pytest.MonkeyPatch.context() as m:
        m.setattr(compiler, "OPTIONS", dict(WIDE))
        f = compiler.jit(lambda sc: simulate_batch(sc, controller=state_feedback, config=cfg, block=None).metrics.iae)
        sc = P.scenarios(P.random_batch(8, 1), np.float64)
        top = np.asarray(f(sc))
        inner = np.asarray(jax.jit(lambda s: f(s))(sc))
        const = np.asarray(jax.jit(lambda: f(sc))())
        mapped = np.asarray(jax.vmap(f)(jax.tree_util.tree_map(lambda a: a[None], sc)))[0]
        g = jax.grad(
            lambda K: jnp.sum(f(sc._replace(gains=sc.gains._replace(K=jnp.broadcast_to(K, sc.gains.K.shape)))))
        )(jnp.asarray(P.K))
    for other in (inner, const, mapped):
        np.testing.assert_allclose(other, top, rtol=1e-12)
    assert np.all(np.isfinite(np.asarray(g)))


def test_other_backends_get_the_plain_program(monkeypatch):
    """Where JAX's default backend is not the CPU, the wide program is never compiled or called."""
    monkeypatch.setattr(compiler, "OPTIONS", dict(WIDE))
    f = compiler.jit(lambda x: 2.0 * x)
    assert np.asarray(f(np.float32(1.5))) == 3.0 and f.top._cache_size() == 1 and f.nested._cache_size() == 0
    monkeypatch.setattr(jax, "default_backend", lambda: "gpu")
    assert np.asarray(f(np.float32(2.5))) == 5.0 and f.top._cache_size() == 1 and f.nested._cache_size() == 1


def _both(f, *args):
    """``f(*args)`` compiled with XLA's default vector width and with 512 bits, as float64 NumPy."""
    out = [
        jax.tree_util.tree_map(lambda a: np.asarray(a, np.float64), jax.jit(f, compiler_options=o)(*args))
        for o in (None, WIDE)
    ]
    return out


def _assert_close(a, b, rtol, atol):
    for x, y in zip(jax.tree_util.tree_leaves(a), jax.tree_util.tree_leaves(b)):
        np.testing.assert_allclose(y, x, rtol=rtol, atol=atol)


# The same per-run arithmetic in wider vectors: measured bit-identical here (64-4096 runs, float32
# and float64, Zen 4 and jax 0.10.2); in the benchmark's 10^5 runs over 4000 steps the float32
# IAE moved by ~2e-6 relative (the loops' remainders), float64 not at all. The tolerances allow
# for rounding differences on other CPUs and XLA versions.
TOL = {"float64": (1e-12, 1e-12), "float32": (2e-4, 2e-5)}


@pytest.mark.parametrize("dtype", ["float64", "float32"])
@pytest.mark.parametrize("name", ["state_feedback", "stanley"])
def test_slip_simulator_agrees_with_and_without_wide_vectors(name, dtype):
    from pfjax import controllers as C
    from pfjax.bench import problem as P
    from pfjax.sim import SimConfig
    from pfjax.sim.simulate import simulate

    sc = P.scenarios(P.random_batch(64, 3), np.dtype(dtype))
    ctrl, gains = C.REGISTRY[name][0], C.REGISTRY[name][1]()
    if name != "state_feedback":
        sc = sc._replace(
            gains=jax.tree_util.tree_map(lambda g: np.broadcast_to(np.asarray(g, dtype), (64,) + np.shape(g)), gains)
        )
    cfg = SimConfig(dt=0.01, horizon=2.0, record=False)
    a, b = _both(jax.vmap(lambda s: simulate(ctrl, s, cfg)), sc)
    np.testing.assert_array_equal(b.status, a.status)
    _assert_close(a.metrics, b.metrics, *TOL[dtype])
    _assert_close(a.final, b.final, *TOL[dtype])


def test_tracking_and_parking_simulators_agree_with_and_without_wide_vectors():
    from pfjax import tracking as T
    from pfjax.parking.maps import PARALLEL, to_obstacle_map
    from pfjax.parking.simulate import ParkingConfig, run, run_params
    from pfjax.sim import stack
    from pfjax.tracking import leader as L

    params = T.FollowerParams(a=1.0, f=1.0, l=1.0, p=1.0)
    sc = stack(
        [
            T.scenario(params, L.sine(), init=T.initial_state(L.sine(), params, offset=(dx, 0.3), heading_error=0.2))
            for dx in np.linspace(-0.5, 0.5, 16)
        ]
    )
    cfg = T.TrackConfig(dt=0.02, horizon=4.0, window=1.0)
    a, b = _both(jax.vmap(lambda s: T.simulate(s, cfg)), sc)
    np.testing.assert_array_equal(b.status, a.status)
    _assert_close(a.metrics, b.metrics, *TOL["float64"])

    omap = to_obstacle_map(list(PARALLEL.values()))
    ps = stack([run_params((x, y, 0.0), 1, (1.0,)) for x in (-0.6, -0.4) for y in (0.4, 0.6)])
    a, b = _both(jax.vmap(lambda p: run(p, omap, ParkingConfig())), ps)
    _assert_close(a, b, *TOL["float64"])


#: Every program pfjax compiles with the wide-vector option, and the tests that check it both against
#: the same program at XLA's default width (float64) and against an independent NumPy/SciPy
#: computation. A new ``compiler.jit`` program without an entry here fails
#: :func:`test_every_wide_program_is_audited`.
AUDITED = {
    "pfjax.sim.simulate._simulate_vmapped": (
        "test_slip_simulator_agrees_with_and_without_wide_vectors",
        "tests/test_sim_reference.py (solve_ivp of an independent closed loop)",
    ),
    "pfjax.tracking.simulate._simulate_vmapped": (
        "test_tracking_and_parking_simulators_agree_with_and_without_wide_vectors",
        "tests/test_tracking.py::test_simulation_matches_solve_ivp",
    ),
    "pfjax.parking.simulate.run": (
        "test_tracking_and_parking_simulators_agree_with_and_without_wide_vectors",
        "tests/test_parking_control.py::test_switched_run_against_solve_ivp",
    ),
    "pfjax.parking.simulate.run_recorded": (
        "test_tracking_and_parking_simulators_agree_with_and_without_wide_vectors",
        "tests/test_parking_control.py (case A's first leg against its closed form)",
    ),
    "pfjax.sim.dynamic._simulate_vmapped": (
        "test_dynamic_vehicle_and_minimal_benchmark_agree_with_and_without_wide_vectors",
        "tests/test_sim_dynamic.py (steady cornering against geometry; the kinematic limit at high friction)",
    ),
    "pfjax.bench.minimal._batch": (
        "test_dynamic_vehicle_and_minimal_benchmark_agree_with_and_without_wide_vectors",
        "tests/test_bench.py::test_minimal_jax_reference_agrees_with_numpy",
    ),
    "pfjax.bench.run._grad.<locals>.loss": (
        "test_slip_simulator_agrees_with_and_without_wide_vectors (the program it wraps)",
        "tests/test_bench.py::test_quick_bench_contract_and_agreement (NumPy, Numba and SciPy references)",
    ),
}


def test_dynamic_vehicle_and_minimal_benchmark_agree_with_and_without_wide_vectors():
    from functools import partial

    from pfjax import controllers as C
    from pfjax import paths
    from pfjax.bench import minimal as M
    from pfjax.bench import problem as P
    from pfjax.models import single_track as st
    from pfjax.sim import SimConfig, stack
    from pfjax.sim import dynamic as dyn

    with jax.enable_x64(True):
        e = paths.entry("sine")
        ctrl, gains = C.REGISTRY["stanley"][0], C.REGISTRY["stanley"][1]()
        sc = stack(
            [
                dyn.DynamicScenario(
                    pose0=e.start_pose,
                    vehicle=st.robot_params()._replace(mu=mu),
                    v_ref=1.0,
                    path=e.build(),
                    gains=gains,
                )
                for mu in (0.3, 0.6, 1.0)
            ]
        )
        cfg = SimConfig(dt=0.01, horizon=1.0, record=False)
        a, b = _both(jax.vmap(lambda s: dyn.simulate(ctrl, s, cfg)), sc)
        np.testing.assert_array_equal(b.status, a.status)
        _assert_close(a.metrics, b.metrics, *TOL["float64"])

        runs = M.runs(P.random_batch(16, 2), np.float64)
        a, b = _both(jax.vmap(partial(M._run, n_steps=100)), runs)
        _assert_close(a, b, *TOL["float64"])


def test_every_wide_program_is_audited():
    from importlib import import_module

    for m in (
        "pfjax.sim.simulate",
        "pfjax.sim.dynamic",
        "pfjax.tracking.simulate",
        "pfjax.parking.simulate",
        "pfjax.bench.run",
        "pfjax.bench.minimal",
    ):
        import_module(m)
    wide = {p for p in compiler.PROGRAMS if not p.startswith(("tests.", "test_"))}
    names = {p.replace("value_and_grad.<locals>.", "") for p in wide}
    missing = sorted(n for n in names if n not in AUDITED and not n.startswith("pfjax.numerics.autodiff"))
    assert not missing, f"wide-vector programs without an audit entry: {missing}"
    here = {n for n in globals() if n.startswith("test_")}
    for name, (same_program, _) in AUDITED.items():
        assert same_program.split(" ")[0] in here, name
