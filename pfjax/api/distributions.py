"""Distributions for :func:`pfjax.scenarios`: each a study config's ``{"dist": ...}`` table, validated."""

from __future__ import annotations

from pfjax import errors


def uniform(low: float, high: float):
    """A uniform distribution on ``[low, high]`` (for :func:`scenarios`)."""
    from pfjax.montecarlo.config import Dist

    return _dist(Dist, dist="uniform", low=low, high=high)


def normal(mean: float, std: float):
    """A normal distribution (for :func:`scenarios`)."""
    from pfjax.montecarlo.config import Dist

    return _dist(Dist, dist="normal", mean=mean, std=std)


def truncnormal(mean: float, std: float, low: float, high: float):
    """A normal distribution truncated to ``[low, high]`` (for :func:`scenarios`)."""
    from pfjax.montecarlo.config import Dist

    return _dist(Dist, dist="truncnormal", mean=mean, std=std, low=low, high=high)


def choice(values):
    """A uniform choice among ``values``, a non-empty list (tuple, 1-D array) of numbers (for :func:`scenarios`)."""
    import numpy as np

    from pfjax.montecarlo.config import Dist

    # checked as a study config's list is (numbers only: no strings, no booleans)
    listed = (
        values.tolist() if isinstance(values, np.ndarray) else list(values) if isinstance(values, tuple) else values
    )
    return _dist(Dist, dist="choice", values=listed)


def _dist(cls, **kw):
    from pydantic import ValidationError

    try:
        return cls.model_validate(kw)
    except ValidationError as e:
        from pfjax.config import format_error

        # a check of the whole table (low < high) names no key of its own: the function names it
        message = format_error(e, cls).removeprefix("config: ")
        raise errors.InputError(f"{kw['dist']}: {message}", kw["dist"]) from None
