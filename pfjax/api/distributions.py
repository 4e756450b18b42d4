"""Distributions for :func:`pfjax.scenarios`: each a study config's ``{"dist": ...}`` table, validated."""

from __future__ import annotations

from pfjax import errors
from pfjax.errors import arguments_checked


@arguments_checked
def uniform(low: float, high: float):
    """A uniform distribution on ``[low, high]`` (for :func:`scenarios`)."""
    from pfjax.montecarlo.config import Dist

    return _dist(Dist, dist="uniform", low=low, high=high)


@arguments_checked
def normal(mean: float, std: float):
    """A normal distribution (for :func:`scenarios`)."""
    from pfjax.montecarlo.config import Dist

    return _dist(Dist, dist="normal", mean=mean, std=std)


@arguments_checked
def truncnormal(mean: float, std: float, low: float, high: float):
    """A normal distribution truncated to ``[low, high]`` (for :func:`scenarios`)."""
    from pfjax.montecarlo.config import Dist

    return _dist(Dist, dist="truncnormal", mean=mean, std=std, low=low, high=high)


@arguments_checked
def choice(values):
    """A uniform choice among ``values``, a non-empty list (tuple, 1-D NumPy or JAX array) of numbers
    (for :func:`scenarios`)."""
    from pfjax.montecarlo.config import Dist

    # checked as a study config's list is (numbers only: no strings, no booleans)
    return _dist(Dist, dist="choice", values=list(values) if isinstance(values, tuple) else values)


def _dist(cls, **kw):
    """``kw`` validated as a study config's distribution table is (NumPy and JAX numbers read as
    Python's, :func:`pfjax.config.plain`); InputError naming the distribution otherwise."""
    from pydantic import ValidationError

    from pfjax.config import plain

    try:
        return cls.model_validate(plain(kw))
    except ValidationError as e:
        from pfjax.config import format_error

        # a check of the whole table (low < high) names no key of its own: the function names it
        message = format_error(e, cls).removeprefix("config: ")
        raise errors.InputError(f"{kw['dist']}: {message}", kw["dist"]) from None
