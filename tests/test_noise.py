"""The sensor-noise model (:class:`pfjax.sim.simulate.SensorNoise`): the sensor measures the pose, and
every controller of the registry sees the one noisy measurement.

The measured pose is the true one displaced by ``e_d = sigma_d n0`` along the path's left normal at
the closest point and rotated by ``e_theta = sigma_theta_e n1``; its errors against the path are
``d + e_d`` and ``theta_e + e_theta``. Runs are float64 (tests/conftest.py).
"""

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from pfjax import controllers as C
from pfjax.controllers.base import Observation
from pfjax.models.slip import Pose
from pfjax.numerics.random import step_normals
from pfjax.paths import shapes
from pfjax.paths.geometry import closest_parameter, curvature, global_parameter, measure, wrap_angle
from pfjax.sim import SensorNoise, SimConfig, simulate_batch, stack
from pfjax.sim.scenario import paper_scenario
from pfjax.sim.simulate import noisy_observation

CFG = SimConfig(horizon=4.0, record=False)
SIGMA_D, SIGMA_THETA = 0.05, math.radians(5.0)
#: three starts near the sine path (x, y, theta): m, m, rad
STARTS = ((0.0, -0.2, math.pi / 4), (0.5, 0.7, 0.6), (1.0, 0.6, 0.2))
NAMES = sorted(C.REGISTRY)


def _gains(name):
    """The controller's default gains; the state feedback with the source's K."""
    factory = C.REGISTRY[name][1]
    return factory(K=C.PAPER_K) if name == "state_feedback" else factory()


def _noise(sd, st, seed):
    return SensorNoise(jnp.asarray(sd, float), jnp.asarray(st, float), jax.random.PRNGKey(seed))


@functools.cache
def _runs(name):
    """Metrics of the three sine-path runs without noise, and of the same runs with sigma = 0 noise
    (first three) and with sigma_d = 0.05 m, sigma_theta_e = 5 deg (last three)."""
    controller, g = C.REGISTRY[name][0], _gains(name)
    base = [paper_scenario("sine", g, pose0=p) for p in STARTS]
    noisy = [sc._replace(noise=_noise(0.0, 0.0, i)) for i, sc in enumerate(base)] + [
        sc._replace(noise=_noise(SIGMA_D, SIGMA_THETA, i)) for i, sc in enumerate(base)
    ]
    run = lambda scs: jax.device_get(simulate_batch(stack(scs), controller=controller, config=CFG))
    return run(base), run(noisy)


@pytest.mark.parametrize("name", NAMES)
def test_every_controller_sees_the_noise(name):
    """sigma_d = 0.05 m, sigma_theta_e = 5 deg change every run's metrics, whatever the controller
    reads (d and theta_e, or the pose: Stanley, pure pursuit), and no run fails."""
    free, noisy = _runs(name)
    assert free.metrics.iae.dtype == np.float64
    assert np.all(free.status == 0) and np.all(noisy.status == 0), (free.status, noisy.status)
    n = len(STARTS)
    for field in ("iae", "ise", "steer_energy"):
        a, b = getattr(free.metrics, field), getattr(noisy.metrics, field)[n:]
        assert np.all(np.abs(b - a) > 1e-6 * np.abs(a)), (field, a, b)
    # the steering's total variation: white noise makes the command jitter
    assert np.all(noisy.metrics.steer_tv[n:] > 1.5 * free.metrics.steer_tv), (
        free.metrics.steer_tv,
        noisy.metrics.steer_tv,
    )


@pytest.mark.parametrize("name", NAMES)
def test_zero_sigma_noise_equals_no_noise(name):
    """Noise with sigma_d = sigma_theta_e = 0 (a different program: the draws are made and multiplied by
    0) gives the noise-free runs' metrics to 1e-12 (float64)."""
    free, noisy = _runs(name)
    n = len(STARTS)
    for field, a in free.metrics._asdict().items():
        b = getattr(noisy.metrics, field)[:n]
        np.testing.assert_allclose(b, a, rtol=1e-12, atol=1e-12, err_msg=field)
    np.testing.assert_array_equal(noisy.status[:n], free.status)


@jax.jit
def _exact_observation(path, pose, u_guess, v=1.0, L=0.2, delta_max=math.radians(30.0)):
    """The noise-free observation of ``pose`` (its closest point converged by Newton from ``u_guess``)."""
    u = closest_parameter(path, pose.x, pose.y, u_guess, iters=30)
    pr = measure(path, pose.x, pose.y, pose.theta, u)
    f = lambda a: jnp.asarray(a, float)
    return Observation(
        d=pr.d,
        theta_e=pr.theta_e,
        kappa=pr.kappa,
        s=pr.s,
        u=pr.u,
        pose=pose,
        v=f(v),
        L=f(L),
        delta_max=f(delta_max),
        path=path,
    )


@jax.jit
def _global_projection(path, pose):
    """``pose`` against its global closest point (dense search, then Newton to convergence)."""
    u = closest_parameter(path, pose.x, pose.y, global_parameter(path, pose.x, pose.y), iters=30)
    return measure(path, pose.x, pose.y, pose.theta, u)


def _poses(path):
    """Poses near the sine path, left and right of it, heading errors of both signs and near +-pi."""
    us = jnp.asarray([-1.0, 0.3, 1.4, 2.9, 4.6])
    d = jnp.asarray([0.15, -0.2, 0.05, -0.08, 0.25])
    te = jnp.asarray([0.3, -0.5, 3.1, -3.05, 0.0])
    px, py = path.point(us)
    dx, dy = path.d1(us)
    tp = jnp.arctan2(dy, dx)
    return us, Pose(px - d * jnp.sin(tp), py + d * jnp.cos(tp), tp + te)


@pytest.mark.parametrize("sigma_d", [1e-4, 0.05])
def test_measured_pose_is_consistent_with_the_measured_errors(sigma_d):
    """``noisy_observation`` against an independent computation with :mod:`pfjax.paths.geometry`: the measured
    d and theta_e are the true ones plus exactly e_d and e_theta; the measured pose is the true one
    moved by e_d along the left unit normal at the closest point (from the path's derivative) and
    turned by e_theta; projecting it onto the path again gives the same closest point, d + e_d and
    wrap(theta_e + e_theta) (exact for a displacement along the normal, here to 1e-9)."""
    path = shapes.sine()
    noise = _noise(sigma_d, math.radians(5.0), 7)
    us, poses = _poses(path)
    for k in (0, 1, 17, 4000):
        n = step_normals(noise.key, k, 2, jnp.float64)
        e_d, e_th = float(noise.sigma_d * n[0]), float(noise.sigma_theta_e * n[1])
        assert e_d != 0.0 and e_th != 0.0
        for i in range(len(us)):
            pose = Pose(*(a[i] for a in poses))
            obs = _exact_observation(path, pose, us[i])
            m = noisy_observation(obs, noise, k)
            # the errors, exactly as the controllers on (d, theta_e) see them
            assert float(m.d) == float(obs.d + e_d)
            assert float(m.theta_e) == float(wrap_angle(obs.theta_e + e_th))
            for field in ("kappa", "s", "u", "v", "L", "delta_max"):
                assert float(getattr(m, field)) == float(getattr(obs, field)), field
            # the pose: moved along the left normal (-t_y, t_x) of the closest point, turned by e_theta
            tx, ty = (np.asarray(a, float) for a in path.d1(obs.u))
            tx, ty = tx / math.hypot(tx, ty), ty / math.hypot(tx, ty)
            np.testing.assert_allclose(float(m.pose.x), float(pose.x) - e_d * ty, rtol=0, atol=1e-13)
            np.testing.assert_allclose(float(m.pose.y), float(pose.y) + e_d * tx, rtol=0, atol=1e-13)
            assert float(m.pose.theta) == float(pose.theta + e_th)
            # projecting the measured pose (global search, then Newton) gives the measured errors
            pr = _global_projection(path, m.pose)
            np.testing.assert_allclose(float(pr.u), float(obs.u), rtol=0, atol=1e-9)
            np.testing.assert_allclose(float(pr.d), float(obs.d) + e_d, rtol=0, atol=1e-9)
            np.testing.assert_allclose(float(wrap_angle(pr.theta_e - m.theta_e)), 0.0, rtol=0, atol=1e-9)
            assert abs(float(obs.d) + e_d) * abs(float(curvature(path, obs.u))) < 1.0  # inside the normal's range


@pytest.mark.parametrize("name", NAMES)
def test_every_controller_reads_the_measured_pose(name):
    """Each registry controller's command on the noisy observation equals its command on the exact
    observation of the measured pose (a fresh projection of it): the controllers on (d, theta_e) and
    those on the pose see one and the same measurement. Checked at a few poses and steps, to 1e-9 rad,
    and the noise changes every command."""
    path = shapes.sine()
    controller, g = C.REGISTRY[name][0], _gains(name)
    c = controller.init(g)
    noise = _noise(0.05, math.radians(5.0), 3)
    us, poses = _poses(path)
    out = jax.jit(lambda o: controller.output(g, c, o))
    for k in (0, 5):
        for i in range(len(us)):
            pose = Pose(*(a[i] for a in poses))
            obs = _exact_observation(path, pose, us[i])
            m = noisy_observation(obs, noise, k)
            remeasured = _exact_observation(path, m.pose, obs.u)
            np.testing.assert_allclose(
                float(out(m)), float(out(remeasured)), rtol=0, atol=1e-9, err_msg=f"{name}, pose {i}, step {k}"
            )
            assert float(out(m)) != float(out(obs)), (name, i, k)
