"""Running metrics against NumPy recomputations from recorded trajectories, and against
closed-form trapezoid sums for a hand-made sequence.

Tolerance 1e-12 relative: the running sums and ``np.trapezoid`` add the same terms in a
different order (rounding ~N eps ~ 1e-13 for N ~ 10^3 samples).
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from pfjax import controllers as C
from pfjax.metrics import running
from pfjax.paths import sine
from pfjax.sim import SimConfig, Status, constant_slip, simulate_batch, stack
from pfjax.sim.scenario import make_scenario

DEG = math.pi / 180
CFG = SimConfig(dt=0.01, horizon=12.0, steady_window=4.0, settle_band=0.1, d_fail=2.5)
RTOL = 1e-12


def _scenarios():
    sf = C.state_feedback_params()
    return [
        # the source's sine test (slip 5 deg)
        make_scenario(sine(), (0.0, -0.2, math.pi / 4), sf, slip=constant_slip(5 * DEG, 5 * DEG)),
        # far off and heading away: saturates, overshoots
        make_scenario(sine(), (1.0, 2.5, 2.0), sf, slip=constant_slip(2 * DEG, -3 * DEG)),
        # a larger, faster sine with the Lenain convention and a 20 deg steering limit
        make_scenario(
            sine(amplitude=1.5, omega=1.3),
            (0.5, 0.3, 0.0),
            sf,
            slip=constant_slip(-4 * DEG, 3 * DEG),
            delta_max_deg=20.0,
            convention="lenain",
        ),
        # destabilising gains with a 3 deg limit: DIVERGED (|d| > 2.5 m)
        make_scenario(
            sine(),
            (0.0, -0.2, math.pi / 4),
            C.state_feedback_params(K=(2.7, 2.0)),
            slip=constant_slip(0.0, 0.0),
            delta_max_deg=3.0,
        ),
    ]


@pytest.fixture(scope="module")
def res():
    return jax.device_get(simulate_batch(stack(_scenarios()), controller=C.state_feedback, config=CFG))


def reference_metrics(tr, dmax, horizon, window, band, success_from=None, success_band=None, ok=True):
    """Every metric from the recorded samples, written independently of pfjax.metrics."""
    t, d, te, delta, cmd = tr.t, tr.d, tr.theta_e, tr.delta, tr.delta_cmd
    ad = np.abs(d)
    win = t >= horizon - window - 1e-9
    out_band = np.nonzero(ad > band)[0]
    if out_band.size == 0:
        settling = 0.0
    elif out_band[-1] == t.size - 1:
        settling = np.nan
    else:
        settling = t[out_band[-1] + 1]
    return dict(
        iae=np.trapezoid(ad, t),
        ise=np.trapezoid(d * d, t),
        itae=np.trapezoid(t * ad, t),
        max_abs_d=ad.max(),
        steady_abs_d=np.trapezoid(ad[win], t[win]) / (t[win][-1] - t[win][0]),
        steady_abs_theta_e_rad=np.trapezoid(np.abs(te[win]), t[win]) / (t[win][-1] - t[win][0]),
        settling_time=settling,
        overshoot=max(0.0, np.max(-np.sign(d[0]) * d)),
        steer_energy=np.trapezoid(delta * delta, t),
        steer_tv=np.sum(np.abs(np.diff(delta))),
        sat_fraction=np.trapezoid((np.abs(cmd) > dmax).astype(float), t) / horizon,
        late_max_abs_d=ad[t >= success_from - 1e-9].max(),
        success=bool(ok and ad[t >= success_from - 1e-9].max() <= success_band),
    )


@pytest.mark.parametrize("i", [0, 1, 2])
def test_metrics_equal_numpy_recomputation_from_the_trajectory(res, i):
    """record=True: every metric recomputed from the trajectory (np.trapezoid for the integrals,
    sample max, trapezoid time-mean over the steady window, settling time as the sample after the
    last one outside the band, overshoot, total variation, saturated fraction of time)."""
    tr = jax.tree_util.tree_map(lambda a: a[i], res.trajectory)
    assert int(res.status[i]) == Status.OK
    dmax = float(_scenarios()[i].params.delta_max)
    ref = reference_metrics(
        tr, dmax, CFG.horizon, CFG.steady_window, CFG.settle_band, CFG.success_start, CFG.success_band
    )
    got = jax.tree_util.tree_map(lambda a: a[i], res.metrics)._asdict()
    assert set(ref) == set(got) == set(running.METRIC_NAMES)
    for name, value in ref.items():
        np.testing.assert_allclose(got[name], value, rtol=RTOL, atol=1e-15, err_msg=name)


def test_the_runs_exercise_every_metric(res):
    """The recomputation above is not vacuous: saturation, overshoot, settling (and a run that
    never settles within the band) all occur."""
    m = res.metrics
    assert m.sat_fraction[1] > 0.01 and m.overshoot[1] > 0.01 and m.overshoot[0] > 0
    assert np.all(np.isfinite(m.settling_time[:2])) and np.all(m.settling_time[:2] > 0.1)
    assert np.isnan(m.settling_time[2])
    assert np.all(m.steady_abs_theta_e_rad[:3] > 0.01)  # slip: the heading error settles away from 0


def test_metrics_stop_at_the_failure(res):
    """A failed run's metrics cover the samples before the failing one (trapezoid weights, the
    failing sample and everything after it weighted 0), its maxima exclude the failing sample,
    and the steady-state errors and settling time are NaN."""
    i = 3
    assert int(res.status[i]) == Status.DIVERGED
    tr = jax.tree_util.tree_map(lambda a: a[i], res.trajectory)
    k = int(round(res.fail_time[i] / CFG.dt))
    assert abs(tr.d[k]) > CFG.d_fail >= np.abs(tr.d[:k]).max()
    w = np.ones(k)
    w[0] = 0.5
    t, ad, delta = tr.t[:k], np.abs(tr.d[:k]), tr.delta[:k]
    m = jax.tree_util.tree_map(lambda a: a[i], res.metrics)
    dt = CFG.dt
    np.testing.assert_allclose(m.iae, dt * np.sum(w * ad), rtol=RTOL)
    np.testing.assert_allclose(m.ise, dt * np.sum(w * ad**2), rtol=RTOL)
    np.testing.assert_allclose(m.itae, dt * np.sum(w * t * ad), rtol=RTOL)
    np.testing.assert_allclose(m.steer_energy, dt * np.sum(w * delta**2), rtol=RTOL)
    np.testing.assert_allclose(m.steer_tv, np.sum(np.abs(np.diff(delta))), rtol=RTOL, atol=1e-15)
    np.testing.assert_allclose(m.max_abs_d, ad.max(), rtol=RTOL)
    sat = (np.abs(tr.delta_cmd[:k]) > 3 * DEG).astype(float)
    np.testing.assert_allclose(m.sat_fraction, np.sum(w * sat) / np.sum(w), rtol=RTOL)
    assert np.isnan(m.steady_abs_d) and np.isnan(m.steady_abs_theta_e_rad) and np.isnan(m.settling_time)


# ------------------------------------------------------------------------- a hand-computed case


def _feed(t, d, te, delta, sat, weight, *, band, steady_from):
    """Run init/update/finalize over the given samples (jitted scan)."""
    dt, horizon = float(t[1] - t[0]), float(t[-1])

    def go(t, d, te, delta, sat, weight):
        acc0 = running.init(d[0], delta[0])
        body = lambda acc, x: (
            running.update(
                acc,
                x[0],
                dt,
                x[5],
                x[1],
                x[2],
                x[3],
                x[4],
                band=band,
                steady_from=steady_from,
                success_from=steady_from,
            ),
            None,
        )
        acc, _ = jax.lax.scan(body, acc0, jnp.stack([t, d, te, delta, sat, weight], axis=1))
        return running.finalize(acc, horizon, weight[-1] == 0, band)

    return jax.device_get(jax.jit(go)(*(jnp.asarray(a) for a in (t, d, te, delta, sat, weight))))


def test_hand_computed_exponential_decay():
    """d_k = exp(-t_k), theta_e = 0.5 exp(-2 t), delta = 0.2 exp(-t/2), saturated for t < 1 s,
    h = 0.01, T = 10: the trapezoid sums in closed form (geometric series, r = e^-h):

        IAE  = h [ (1 - r^(N+1)) / (1 - r) - (1 + r^N) / 2 ]
        ITAE = h^2 [ r (1 - (N+1) r^N + N r^(N+1)) / (1 - r)^2 - N r^N / 2 ]

    and within the trapezoid error h^2 T max|f''| / 12 of the exact integrals 1 - e^-T etc."""
    h, N = 0.01, 1000
    T = N * h
    t = np.arange(N + 1) * h
    w = np.ones(N + 1)
    w[[0, -1]] = 0.5
    d, te, delta, sat = np.exp(-t), 0.5 * np.exp(-2 * t), 0.2 * np.exp(-t / 2), (t < 1.0).astype(float)
    m = _feed(t, d, te, delta, sat, w, band=0.05, steady_from=T - 4.0)

    def geo(r, k0=0):  # trapezoid sum h * sum_{k=k0}^{N} w_k r^k with half weights at k0 and N
        return h * ((r**k0 - r ** (N + 1)) / (1 - r) - 0.5 * (r**k0 + r**N))

    r = math.exp(-h)
    itae = h * h * (r * (1 - (N + 1) * r**N + N * r ** (N + 1)) / (1 - r) ** 2 - 0.5 * N * r**N)
    np.testing.assert_allclose(m.iae, geo(r), rtol=RTOL)
    np.testing.assert_allclose(m.ise, geo(r * r), rtol=RTOL)
    np.testing.assert_allclose(m.itae, itae, rtol=RTOL)
    np.testing.assert_allclose(m.steer_energy, 0.04 * geo(r), rtol=RTOL)
    # The exact integrals, to the trapezoid rule's error bound.
    assert abs(m.iae - (1 - math.exp(-T))) < h * h * T / 12
    assert abs(m.ise - (1 - math.exp(-2 * T)) / 2) < h * h * T * 4 / 12
    assert abs(m.itae - (1 - (T + 1) * math.exp(-T))) < h * h * T * 2 / 12 + 1e-15
    # Steady window [6, 10]: trapezoid time-mean; exact mean (e^-6 - e^-10) / 4.
    k0 = N - 400
    np.testing.assert_allclose(m.steady_abs_d, geo(r, k0) / 4.0, rtol=RTOL)
    np.testing.assert_allclose(m.steady_abs_theta_e_rad, 0.5 * geo(r * r, k0) / 4.0, rtol=RTOL)
    assert abs(m.steady_abs_d - (math.exp(-6) - math.exp(-10)) / 4) < h * h / 12 * math.exp(-6)
    # exp(-t) > 0.05 up to t = ln 20 = 2.9957: the last sample out of the band is t = 2.99.
    np.testing.assert_allclose(m.settling_time, 3.0, rtol=RTOL)
    assert m.max_abs_d == 1.0 and m.overshoot == 0.0
    np.testing.assert_allclose(m.steer_tv, 0.2 * (1 - math.exp(-T / 2)), rtol=RTOL)
    np.testing.assert_allclose(m.sat_fraction, h * 99.5 / T, rtol=RTOL)  # k = 0 (half) .. 99


def test_hand_computed_overshoot_and_unsettled():
    """d = exp(-t) cos(2 t) crosses zero: overshoot is the largest sample of -d; a run that ends
    outside the band has no settling time."""
    h, N = 0.01, 500
    t = np.arange(N + 1) * h
    w = np.ones(N + 1)
    w[[0, -1]] = 0.5
    d = np.exp(-t) * np.cos(2 * t)
    z = np.zeros_like(t)
    m = _feed(t, d, z, z, z, w, band=0.05, steady_from=t[-1] - 1.0)
    # Continuous maximum of -d at tan(2t) = -1/2, t* = (pi - atan(1/2)) / 2; the samples lie within h.
    ts = (math.pi - math.atan(0.5)) / 2
    assert m.overshoot == np.max(-d)
    assert abs(m.overshoot - (-math.exp(-ts) * math.cos(2 * ts))) < h * h * 5
    m2 = _feed(t, d + 0.1, z, z, z, w, band=0.05, steady_from=t[-1] - 1.0)
    assert np.isnan(m2.settling_time)


def test_hand_computed_failure_stops_accumulating():
    """Weight 0 from sample 300 on (as after a failure), with NaN samples there: the metrics are the
    sums over the samples before, the maxima ignore the rest, nothing becomes NaN."""
    h, N, kf = 0.01, 1000, 300
    t = np.arange(N + 1) * h
    w = np.ones(N + 1)
    w[0] = 0.5
    w[kf:] = 0.0
    d = np.exp(-t)
    d[kf:] = np.nan
    delta = np.where(t < kf * h, 0.1, np.nan)
    z = np.zeros_like(t)
    m = _feed(t, d, z, delta, z, w, band=0.05, steady_from=t[-1] - 4.0)
    r = math.exp(-h)
    np.testing.assert_allclose(m.iae, h * ((1 - r**kf) / (1 - r) - 0.5), rtol=RTOL)
    np.testing.assert_allclose(m.steer_energy, h * (kf - 0.5) * 0.01, rtol=RTOL)
    assert m.max_abs_d == 1.0 and m.steer_tv == 0.0 and m.sat_fraction == 0.0
    for name in ("iae", "ise", "itae", "max_abs_d", "overshoot", "steer_energy", "steer_tv", "sat_fraction"):
        assert np.isfinite(getattr(m, name)), name
    assert np.isnan(m.steady_abs_d) and np.isnan(m.settling_time)


def test_a_run_failed_at_its_first_sample_has_no_maxima():
    """Weight 0 from sample 0 on (the run starts beyond d_fail): the integrals over no time are 0, the
    maxima and the saturated fraction over no samples NaN (not 0: a 3 m start is not a 0 m error)."""
    h, N = 0.01, 100
    t = np.arange(N + 1) * h
    d = np.full(N + 1, 3.0)
    z = np.zeros_like(t)
    m = _feed(t, d, z, z + 0.1, z, np.zeros(N + 1), band=0.05, steady_from=0.5)
    for name in ("iae", "ise", "itae", "steer_energy", "steer_tv"):
        assert getattr(m, name) == 0.0, name
    for name in ("max_abs_d", "late_max_abs_d", "overshoot", "sat_fraction", "steady_abs_d", "settling_time"):
        assert np.isnan(getattr(m, name)), name
    assert not bool(m.success)
    # end to end: a start 3 m off the line with d_fail = 1 m fails at t = 0
    import pfjax

    sc = pfjax.scenarios("line", 2, lateral_offset=[0.5, 3.0], beta_r_deg=0, beta_f_deg=0)
    tab = pfjax.simulate(sc, "pi", config={"horizon": 1.0, "dt": 0.01, "d_fail": 1.0}).table
    assert list(tab.status) == ["ok", "diverged"] and tab.fail_time[1] == 0.0
    assert np.isnan(tab.max_abs_d[1]) and tab.iae[1] == 0.0 and 0.45 < tab.max_abs_d[0] <= 0.5


def test_success_window_hand_computed():
    """late_max_abs_d is the max |d| from success_from on (exp(-6) for a decreasing exp(-t));
    success needs it within the band and no failure."""
    h, N = 0.01, 1000
    t = np.arange(N + 1) * h
    w = np.ones(N + 1)
    w[[0, -1]] = 0.5
    d = np.exp(-t)
    z = np.zeros_like(t)
    m = _feed(t, d, z, z, z, w, band=0.05, steady_from=6.0)
    np.testing.assert_allclose(m.late_max_abs_d, math.exp(-6.0), rtol=1e-12)
    assert bool(m.success)
    m = _feed(t, d, z, z, z, w, band=1e-3, steady_from=6.0)  # exp(-6) = 2.5e-3 > 1e-3
    assert not bool(m.success)
    w_failed = w.copy()
    w_failed[-100:] = 0.0  # failed near the end: never a success
    m = _feed(t, d, z, z, z, w_failed, band=0.05, steady_from=6.0)
    assert not bool(m.success)


def test_a_run_failed_before_the_success_window_has_no_late_max():
    """late_max_abs_d over no sample of the success window (the run failed before success_from) is
    NaN, not 0 (an unfinished run is no small late error); a run failed inside the window has the max
    over its samples there; neither is a success."""
    h, N = 0.01, 1000
    t = np.arange(N + 1) * h
    d = np.exp(-t)
    z = np.zeros_like(t)
    for k_fail, late in ((300, math.nan), (700, math.exp(-6.0))):  # success window from t = 6 (k = 600)
        w = np.ones(N + 1)
        w[0] = 0.5
        w[k_fail:] = 0.0
        m = _feed(t, d, z, z, z, w, band=0.05, steady_from=6.0)
        np.testing.assert_allclose(m.late_max_abs_d, late, rtol=1e-12)
        assert np.isfinite(m.max_abs_d) and not bool(m.success)
