"""Forward- and reverse-mode value_and_grad agree with jax.grad, and the projection's one-step
derivative is the implicit-function derivative of the closest point (finite differences)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from pfjax.numerics import autodiff
from pfjax.paths import shapes
from pfjax.paths.geometry import closest_parameter


def _loss(p, w):
    return jnp.sum(jnp.sin(p["a"] * w) ** 2) + p["b"][0] * jnp.cos(p["b"][1]), p["a"][0]


@pytest.mark.parametrize("mode", ["forward", "reverse", "auto"])
def test_value_and_grad_modes_agree_with_jax_grad(mode):
    p = {"a": jnp.array([0.3, -1.2, 0.7]), "b": jnp.array([2.0, 0.4])}
    w = jnp.array([1.0, 2.0, 3.0])
    (v, aux), g = jax.jit(autodiff.value_and_grad(_loss, mode=mode, has_aux=True))(p, w)
    (v_ref, aux_ref), g_ref = jax.value_and_grad(_loss, has_aux=True)(p, w)
    assert float(v) == float(v_ref) and float(aux) == float(aux_ref)
    for k in p:  # the same derivative, summed in another order: rounding only
        np.testing.assert_allclose(np.asarray(g[k]), np.asarray(g_ref[k]), rtol=1e-14, atol=1e-15)
    v2, g2 = jax.vmap(autodiff.value_and_grad(lambda q: _loss(q, w)[0], mode=mode))(
        jax.tree_util.tree_map(lambda a: jnp.stack([a, 2 * a]), p)
    )
    assert v2.shape == (2,) and g2["a"].shape == (2, 3)
    np.testing.assert_allclose(np.asarray(g2["b"][0]), np.asarray(g_ref["b"]), rtol=1e-14)


@pytest.mark.parametrize("n", [1, 2, 3, 4])
@pytest.mark.parametrize("has_aux", [True, False])
def test_forward_mode_nested_and_batched_tangents_agree_with_jax_grad(n, has_aux):
    # up to NESTED_MAX parameters one jvp per direction, nested; above it the directions batched
    assert autodiff.NESTED_MAX == 2
    w = jnp.linspace(0.5, 2.0, 5)

    def loss(p, w):
        y = jnp.sum(jnp.sin(jnp.outer(w, p["k"])) ** 2) * jnp.exp(-p["k"][0] * p["k"][-1])
        return (y, {"first": p["k"][0], "n": jnp.int32(n)}) if has_aux else y

    p = {"k": jnp.linspace(0.2, 0.9, n)}
    got = jax.jit(autodiff.value_and_grad(loss, mode="forward", has_aux=has_aux))(p, w)
    ref = jax.value_and_grad(loss, has_aux=has_aux)(p, w)
    (v, g), (v_ref, g_ref) = got, ref
    if has_aux:
        (v, aux), (v_ref, aux_ref) = v, v_ref
        assert float(aux["first"]) == float(aux_ref["first"]) and int(aux["n"]) == n
    assert float(v) == float(v_ref)
    assert g["k"].shape == (n,)
    np.testing.assert_allclose(np.asarray(g["k"]), np.asarray(g_ref["k"]), rtol=1e-13, atol=1e-15)
    # under vmap (the falsifier's per-run gradients)
    ps = {"k": jnp.stack([p["k"], 1.5 * p["k"]])}
    out = jax.vmap(autodiff.value_and_grad(lambda q: loss(q, w), mode="forward", has_aux=has_aux))(ps)
    out_ref = jax.vmap(jax.value_and_grad(lambda q: loss(q, w), has_aux=has_aux))(ps)
    np.testing.assert_allclose(np.asarray(out[1]["k"]), np.asarray(out_ref[1]["k"]), rtol=1e-13, atol=1e-15)


@pytest.mark.parametrize("n", [1, 2, 3, 4])
def test_forward_mode_keeps_aux_leaves_that_are_not_arrays_and_nests_up_to_nested_max(n, monkeypatch):
    """An aux's names, Python numbers and ``None`` come back as they are, nested or batched, as
    ``jax.value_and_grad`` gives them; the tangents are nested exactly up to ``NESTED_MAX``."""
    calls: list = []
    nested = autodiff._nested_jvp
    monkeypatch.setattr(autodiff, "_nested_jvp", lambda *a: calls.append(1) or nested(*a))

    def loss(p):
        return jnp.sum(jnp.sin(p) ** 2), {
            "name": "iae",
            "count": n,
            "none": None,
            "cos": jnp.cos(p),
            "labels": np.array(["a", "b"]),
            "numpy": np.float64(0.5),
        }

    p = jnp.linspace(0.2, 0.9, n)
    (v, aux), g = autodiff.value_and_grad(loss, mode="forward", has_aux=True)(p)
    (v_ref, aux_ref), g_ref = jax.value_and_grad(loss, has_aux=True)(p)
    assert aux["name"] == "iae" and aux["count"] == n and aux["none"] is None
    assert aux["labels"].tolist() == ["a", "b"] and float(aux["numpy"]) == 0.5
    np.testing.assert_array_equal(np.asarray(aux["cos"]), np.asarray(aux_ref["cos"]))
    assert float(v) == float(v_ref)
    np.testing.assert_allclose(np.asarray(g), np.asarray(g_ref), rtol=1e-13)
    assert len(calls) == (1 if n <= autodiff.NESTED_MAX else 0)


@pytest.mark.parametrize("n", [2, 3])
def test_forward_mode_gives_each_leaf_its_dtype_and_refuses_what_jax_grad_refuses(n):
    """float64 and float32 parameters into a float32 value: the gradient in each leaf's dtype, as
    ``jax.grad``'s; a vector or integer value and integer parameters: a ``TypeError``."""

    def loss(p):
        return jnp.sum(jnp.sin(p["a"].astype(jnp.float32))) + 2.0 * p["b"]

    p = {"a": jnp.linspace(0.1, 0.4, n - 1, dtype=jnp.float64), "b": jnp.asarray(0.3, jnp.float32)}
    v, g = autodiff.value_and_grad(loss, mode="forward")(p)
    v_ref, g_ref = jax.value_and_grad(loss)(p)
    assert v.dtype == v_ref.dtype == jnp.float32 and float(v) == float(v_ref)
    assert g["a"].dtype == g_ref["a"].dtype == jnp.float64 and g["b"].dtype == jnp.float32
    np.testing.assert_allclose(np.asarray(g["a"]), np.asarray(g_ref["a"]), rtol=1e-6)
    assert float(g["b"]) == float(g_ref["b"]) == 2.0
    q = jnp.linspace(0.1, 0.4, n)
    for bad, match in (
        (lambda q: jnp.sin(q[:1]), "scalar-output"),
        (lambda q: jnp.sum(q > 0), "real-valued output"),
    ):
        for vg in (autodiff.value_and_grad(bad, mode="forward"), jax.value_and_grad(bad)):
            with pytest.raises(TypeError, match=match):
                vg(q)
    for vg in (autodiff.value_and_grad(lambda k: 1.0 * jnp.sum(k), mode="forward"), jax.grad(jnp.sum)):
        with pytest.raises(TypeError, match="real- or complex-valued inputs"):
            vg(jnp.arange(n))
    # complex parameters: jax.value_and_grad's (conjugate) gradient, not the real axis's derivative
    z = jnp.arange(1.0, n + 1) * (1 + 2j)
    loss = lambda z: jnp.sum(jnp.abs(z) ** 2)
    np.testing.assert_array_equal(
        np.asarray(autodiff.value_and_grad(loss, mode="forward")(z)[1]), np.asarray(jax.value_and_grad(loss)(z)[1])
    )


def test_auto_mode_picks_by_parameter_count_and_bad_mode_is_named():
    assert autodiff.resolve_mode("auto", autodiff.FORWARD_MAX) == "forward"
    assert autodiff.resolve_mode("auto", autodiff.FORWARD_MAX + 1) == "reverse"
    with pytest.raises(ValueError, match="^mode: "):
        autodiff.value_and_grad(lambda x: x, mode="sideways")


def test_projection_derivative_is_the_implicit_derivative():
    """d u*/d(qx, qy, amplitude) of the warm-started projection (3 Newton steps, derivative of the
    last only) against central finite differences of a projection converged by 30 Newton steps
    (float64, h = 1e-6: truncation ~1e-12, rounding ~1e-10 relative), and d u*/d u_guess = 0."""
    rng = np.random.default_rng(3)
    for _ in range(8):
        A, u_true = rng.uniform(0.5, 1.5), rng.uniform(0.0, 20.0)
        path = shapes.sine(amplitude=A)
        px, py = path.point(jnp.asarray(u_true))
        nx, ny = -float(path.d1(jnp.asarray(u_true))[1]), 1.0
        off = rng.uniform(-0.3, 0.3) / np.hypot(nx, ny)
        qx, qy = float(px) + off * nx, float(py) + off * ny
        guess = u_true + rng.uniform(-0.01, 0.01)

        def u_of(qx, qy, A, guess, iters=3):
            return closest_parameter(shapes.sine(amplitude=A), qx, qy, guess, iters)

        grad = jax.grad(u_of, argnums=(0, 1, 2, 3))(qx, qy, A, guess)
        conv = lambda *a: float(u_of(*a, guess, 30))
        h = 1e-6
        fd = [
            (conv(qx + h, qy, A) - conv(qx - h, qy, A)) / (2 * h),
            (conv(qx, qy + h, A) - conv(qx, qy - h, A)) / (2 * h),
            (conv(qx, qy, A + h) - conv(qx, qy, A - h)) / (2 * h),
        ]
        np.testing.assert_allclose(np.asarray(grad[:3], float), fd, rtol=1e-7, atol=1e-8)
        assert float(grad[3]) == 0.0


def test_reverse_mode_carries_small_scenario_leaves_run_by_run():
    """Reverse mode through the simulator accumulates the cotangent of every loop-invariant input in
    the backward loop's carry, one update per step. A per-run input with a short trailing axis (the
    gain ``K``, ``(2,)`` per run; the slip's (rear, front) pairs) must be carried as ``(runs,)``
    arrays: XLA's CPU backend does not vectorise a ``(runs, 2)`` update over the runs (one such
    kernel was 29 % of the benchmark's backward step; README, Performance). The compiled program's
    backward loop must carry no ``(runs, 2)`` array, and the split must not change the gradient
    (checked against forward mode)."""
    import re

    from pfjax import controllers as C
    from pfjax.paths import sine
    from pfjax.sim import SimConfig, constant_slip, simulate_batch, stack
    from pfjax.sim.scenario import make_scenario

    n = 5  # runs: a size no other axis of the program has
    rows = [
        make_scenario(
            sine(), (0.0, 0.1 * i, 0.0), C.state_feedback_params(K=C.PAPER_K), slip=constant_slip(0.02 * i, -0.01 * i)
        )
        for i in range(n)
    ]
    batch = stack(rows)
    cfg = SimConfig(dt=0.01, horizon=0.5, record=False)

    def loss(p):
        sc = batch._replace(gains=batch.gains._replace(K=p["K"]), slip=batch.slip._replace(constant=p["slip"]))
        return jnp.sum(simulate_batch(sc, controller=C.state_feedback, config=cfg).metrics.iae)

    p = {"K": batch.gains.K, "slip": batch.slip.constant}
    assert p["K"].shape == (n, 2) and p["slip"].shape == (n, 2)
    hlo = jax.jit(jax.grad(loss)).lower(p).compile().as_text()
    backward = [line for line in hlo.split("\n") if " while(" in line and "transpose(" in line]
    assert backward, "no backward loop found in the compiled program"
    for line in backward:
        carry = line.split(" while(")[0]
        assert not re.search(rf"\[{n},2\]", carry), f"a ({n}, 2) cotangent in the backward loop's carry: {carry[:300]}"
    g_rev = jax.jit(jax.grad(loss))(p)
    _, g_fwd = jax.jit(autodiff.value_and_grad(loss, mode="forward"))(p)
    for k in p:
        assert np.all(np.asarray(g_rev[k]) != 0)
        np.testing.assert_allclose(np.asarray(g_rev[k]), np.asarray(g_fwd[k]), rtol=1e-9, atol=1e-12)


def test_as_scalars_round_trips_and_keeps_large_leaves_whole():
    from pfjax.numerics.layout import SCALAR_LEAF_MAX, as_scalars

    tree = {
        "K": jnp.array([[1.0, 2.0]]),
        "key": jnp.array([3, 4], jnp.uint32),
        "v": 0.5,
        "none": None,
        "seq": jnp.zeros((SCALAR_LEAF_MAX + 1,)),
        "empty": jnp.zeros((0,)),
    }
    parts, join = as_scalars(tree)
    flat = jax.tree_util.tree_leaves(tree)
    kinds = [type(p) for p in parts]
    assert len(parts) == len(flat) and kinds.count(tuple) == 2  # K and key split; v, seq and empty whole
    back = jax.jit(join)(parts)
    assert jax.tree_util.tree_structure(back) == jax.tree_util.tree_structure(tree)
    for a, b in zip(jax.tree_util.tree_leaves(back), flat):
        assert jnp.shape(a) == jnp.shape(b) and jnp.result_type(a) == jnp.result_type(b)
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    again, _ = as_scalars(back)  # a loop carry: the same structure after a round trip
    assert jax.tree_util.tree_structure(again) == jax.tree_util.tree_structure(parts)


def test_first_true_and_all_true_equal_select_and_all_without_a_short_axis_reduction():
    """Every combination of 4 conditions (first true wins, default when none), under vmap, against
    jnp.select / jnp.all; and the compiled status check reduces over no stacked axis."""
    from pfjax.numerics.layout import all_true, first_true
    from pfjax.sim.status import classify

    combos = np.array(np.meshgrid(*[[False, True]] * 4, indexing="ij")).reshape(4, -1)  # (4, 16)
    conds = [jnp.asarray(c) for c in combos]
    got = first_true(conds, [1, 2, 3, 4], jnp.int32(0))
    want = jnp.select(conds, [1, 2, 3, 4], 0)
    assert got.dtype == jnp.int32
    np.testing.assert_array_equal(np.asarray(got), np.asarray(want))
    np.testing.assert_array_equal(np.asarray(all_true(conds)), combos.all(axis=0))

    f = jax.jit(jax.vmap(lambda fin, a, o, e: classify(fin, a, o, e, 10.0)))
    args = (
        jnp.asarray(combos[0]),
        jnp.asarray(np.where(combos[1], 11.0, 1.0)),
        jnp.asarray(np.where(combos[2], 0.0, 1.0)),
        jnp.asarray(combos[3]),
    )
    np.testing.assert_array_equal(
        np.asarray(f(*args)),
        np.asarray(jnp.select([~args[0], args[3], args[1] > 10.0, args[2] <= 1e-6], [1, 4, 2, 3], 0)),
    )
    hlo = f.lower(*args).compile().as_text()
    assert " reduce(" not in hlo and "argmax" not in hlo
