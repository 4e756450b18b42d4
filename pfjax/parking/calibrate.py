"""Calibration of a_f, the reach of the robot rectangle ahead of the wheel axle (docs/reproductions/parking.md §3, derived).

Source fact: in case A (start (−0.4, 0.5, 0°), forward, α = 1, k₁ = 32, k₂ = 8) the first switch
happens when the rectangle's right front corner reaches an obstacle with the robot at
(x, y) = (0.074, 0.047). Before that switch the loop is linear in the x time scale
(``z₁'' + k₂ z₁' + k₁ z₁ = 0``, roots −4 ± 4i), so with u = x − x₀:

    y(x) = e^{−4u} (y₀ cos 4u + y₀ sin 4u),    tan θ(x) = −8 y₀ e^{−4u} sin 4u

(for y₀ = 0.5, θ₀ = 0). The right front corner is ``(x + a_f cos θ + (L₁/2) sin θ,
y + a_f sin θ − (L₁/2) cos θ)``; a_f is the smallest reach for which it touches an obstacle
edge at that pose: the kerb ``y = −0.2`` or the car ahead ``x = 0.5``. The closed form also
checks the model: it predicts y at x = 0.074 independently of a_f, to compare with the source's
0.047. :func:`pfjax.parking.simulate.simulated_first_switch` then confirms where the sampled
(0.1 s) detection switches.
"""

from __future__ import annotations

import math

from pfjax.parking.defaults import K1, K2, L1_WIDTH
from pfjax.parking.maps import PARALLEL
from pfjax.parking.schedules import CASES

SOURCE_SWITCH = (0.074, 0.047)  # m, robot position at case A's first switch (source)


_CASE_A_X0, _CASE_A_Y0, _ = CASES["A"]["x0"]
#: m, the kerb's top edge and the car ahead's rear edge on the parallel map
KERB_Y = max(y for _, y in PARALLEL["kerb"])
CAR_X = min(x for x, _ in PARALLEL["car_ahead"])


def case_a_pose(x: float, x0=_CASE_A_X0, y0=_CASE_A_Y0, k1=K1, k2=K2) -> tuple[float, float]:
    """Closed-form (y, θ) on case A's first leg at position x (α = 1, θ₀ = 0, underdamped roots)."""
    sr, si = -k2 / 2, math.sqrt(k1 - k2**2 / 4)
    u = x - x0
    # z1 = e^{sr u}(A cos si u + B sin si u), z1(0) = y0, z1'(0) = 0
    a, b = y0, -sr * y0 / si
    e = math.exp(sr * u)
    z1 = e * (a * math.cos(si * u) + b * math.sin(si * u))
    z2 = e * ((sr * a + si * b) * math.cos(si * u) + (sr * b - si * a) * math.sin(si * u))
    return z1, math.atan(z2)


def calibrate_front(switch_xy=SOURCE_SWITCH, width=L1_WIDTH, kerb_y=KERB_Y, car_x=CAR_X) -> dict:
    """a_f from the source's first-switch position of case A (closed form; see module docstring)."""
    x, y_src = switch_xy
    y, th = case_a_pose(x)
    w = width / 2
    reach = {
        "kerb": (kerb_y - y + w * math.cos(th)) / math.sin(th),
        "car_ahead": (car_x - x - w * math.sin(th)) / math.cos(th),
    }
    valid = {k: v for k, v in reach.items() if v > 0}
    which = min(valid, key=lambda k: valid[k])
    return {
        "a_f": valid[which],
        "obstacle": which,
        "reach_per_obstacle": reach,
        "theta_deg_at_switch": math.degrees(th),
        "y_closed_form_at_switch_x": y,
        "y_source": y_src,
        "switch_x": x,
    }


#: The calibrated reach (m) used by default everywhere in pfjax.parking.
A_F = calibrate_front()["a_f"]
