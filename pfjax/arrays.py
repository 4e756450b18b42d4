"""Type aliases for the leaves of pfjax's pytrees.

A parameter or scenario pytree holds JAX arrays inside a jitted program, NumPy arrays when it is
built, stacked or indexed on the host (one batch row, a batch before it is placed on the devices),
and Python numbers as its defaults.
"""

import numpy as np
from jax import Array

Leaf = Array | np.ndarray
"""An array leaf: a JAX array, or a NumPy array on the host."""

FloatLeaf = Leaf | float
"""A real-valued leaf (scalar or batched), or a Python float default."""

IntLeaf = Leaf | int
"""An integer-valued leaf (a code such as a sign convention), or a Python int default."""
