"""The mixed H2/H-inf, integral and polytopic gains designed on the kinematic model and redesigned on
the dynamic model's linearised lateral-yaw dynamics (:mod:`pfjax.synthesis.dynamic_plant`) at the
robot scale: the study's speed range (the support of its distribution; the operating point at its
midpoint) and the dynamic arms' ``tau_delta_s`` (s), friction range ``[mu_low, mu_high]``."""

from __future__ import annotations

import math

import numpy as np

from pfjax.dynamic_study.arms import ROBOT_WHEELBASE
from pfjax.dynamic_study.config import KinematicVsDynamic
from pfjax.models import single_track as st


def _plants(p, tau: float, mus, speeds, integral: bool = False) -> list:
    """The design plants of the linearised lateral-yaw dynamics at every (mu, speed) corner."""
    from pfjax.synthesis import dynamic_design_plant

    out = []
    for mu in mus:
        for v in speeds:
            a, b = st.lateral_yaw_matrices(p._replace(mu=mu), v)
            out.append(dynamic_design_plant(a, b, v, p.l_r, ROBOT_WHEELBASE, tau, integral=integral))
    return out


def _redesign(plants: list, k0, w: dict) -> dict:
    """The dynamic design over ``plants`` started from the kinematic gain ``k0``
    (:func:`pfjax.synthesis.dynamic_mixed`) as a record: ``K``, ``K0``, the criteria, the norms, the
    largest pole real part and the evaluations; where ``k0`` does not stabilise every plant, no ``K``:
    ``K0``, ``criterion0`` = inf and the reason under ``failed``."""
    from pfjax.synthesis import dynamic_mixed

    try:
        return dynamic_mixed(plants, k0, **w).to_dict()
    except ValueError as e:
        return {"K0": np.asarray(k0, float).reshape(1, -1).tolist(), "criterion0": math.inf, "failed": str(e)}


def designs(config: KinematicVsDynamic) -> tuple[list[dict], dict]:
    """The kinematic and the dynamic designs as study controllers (``<design>-kin``,
    ``<design>-dyn``), and their records (operating point, gains, criteria). Each dynamic design
    starts from its own kinematic gain (the polytopic one over the corners of the friction and
    speed ranges); a dynamic design whose kinematic gain does not stabilise every one of its plants
    is no controller, and its record says why (:func:`_redesign`)."""
    from pfjax.synthesis import integral_mixed, mixed_h2_hinf, polytopic_mixed, slip_design_plant

    d = config.designs
    w: dict = {"alpha": d.alpha, "beta": d.beta}
    vehicle = config.dynamic_vehicle()
    v_lo, v_hi = vehicle.speed.bounds()  # any kind of distribution
    v0, mu0 = 0.5 * (v_lo + v_hi), 0.5 * (config.mu_low + config.mu_high)
    p, L = st.robot_params(), ROBOT_WHEELBASE
    tau = float(vehicle.tau_delta_s)
    kin = {
        "mixed": mixed_h2_hinf(slip_design_plant(v0, L), **w).K,
        "integral": integral_mixed(v0, L, **w).K,
        "polytopic": polytopic_mixed((v_lo, v_hi), d.polytope_slip_deg, L, **w).K,
    }
    corners = ([config.mu_low, config.mu_high], [v_lo, v_hi])
    dyn = {
        "mixed": _redesign(_plants(p, tau, [mu0], [v0]), kin["mixed"], w),
        "integral": _redesign(_plants(p, tau, [mu0], [v0], True), kin["integral"], w),
        "polytopic": _redesign(_plants(p, tau, *corners), kin["polytopic"], w),
    }
    controllers, record = [], {}
    for name in ("mixed", "integral", "polytopic"):
        typ = "integral" if name == "integral" else "state_feedback"
        for origin, K in (("kin", kin[name]), ("dyn", dyn[name].get("K"))):
            label = f"{name}-{origin}"
            if K is None:  # no dynamic design (its start does not stabilise every plant)
                record[label] = dyn[name]
                continue
            flat = [float(k) for k in np.ravel(K)]
            controllers.append({"name": label, "type": typ, "K": flat})
            record[label] = {**(dyn[name] if origin == "dyn" else {}), "K": flat}
    return controllers, {"operating_point": {"v": v0, "mu": mu0, "tau_delta_s": tau}, "gains": record}


__all__ = ["designs"]
