"""LMI state-feedback synthesis and system norms (cvxpy/Clarabel; NumPy in, NumPy out).

Never imported by jitted code: designs are computed once, at the edges, and their gains passed
to the simulator as plain arrays.
"""

from pfjax.synthesis.dynamic_plant import OutputFeedbackDesign, dynamic_design_plant, dynamic_mixed
from pfjax.synthesis.lmi import (
    Design,
    SynthesisError,
    h2_state_feedback,
    hinf_state_feedback,
    mixed_bounds_for_gain,
    mixed_h2_hinf,
    synthesize,
)
from pfjax.synthesis.norms import closed_loop, h2_norm, hinf_norm, is_hurwitz
from pfjax.synthesis.plant import Plant, slip_design_plant
from pfjax.synthesis.regions import PoleRegion, region_contains
from pfjax.synthesis.robust import (
    RobustDesign,
    integral_mixed,
    integral_plant,
    operating_point_plant,
    polytope_vertices,
    polytopic_mixed,
    robust_mixed,
)

__all__ = [
    "Design",
    "OutputFeedbackDesign",
    "Plant",
    "PoleRegion",
    "RobustDesign",
    "SynthesisError",
    "closed_loop",
    "dynamic_design_plant",
    "dynamic_mixed",
    "h2_norm",
    "h2_state_feedback",
    "hinf_norm",
    "hinf_state_feedback",
    "integral_mixed",
    "integral_plant",
    "is_hurwitz",
    "mixed_bounds_for_gain",
    "mixed_h2_hinf",
    "operating_point_plant",
    "polytope_vertices",
    "polytopic_mixed",
    "region_contains",
    "robust_mixed",
    "slip_design_plant",
    "synthesize",
]
