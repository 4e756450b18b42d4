"""Distributions for :func:`pfjax.scenarios`: each a study config's ``{"dist": ...}`` table, validated."""

from __future__ import annotations

from pfjax import errors
from pfjax.errors import arguments_checked


@arguments_checked
def uniform(low: float, high: float):
    """A uniform distribution on ``[low, high]`` (for :func:`scenarios`).

    The numbers are in the unit of the quantity the distribution is given to (degrees for a
    ``*_deg`` argument of :func:`scenarios`, metres for ``lateral_offset``, ...).

    Args:
        low: the lower end, a finite number.
        high: the upper end, a finite number above ``low``.

    Returns:
        a ``Dist`` (:class:`pfjax.montecarlo.dists.Dist`), as a study config's
        ``{dist = "uniform", low, high}`` table holds it.

    Raises:
        pfjax.errors.InputError: ``uniform: ...`` naming the bad value: not a finite number
            (``uniform: low: ...``), or ``low >= high``.
    """
    from pfjax.montecarlo.config import Dist

    return _dist(Dist, dist="uniform", low=low, high=high)


@arguments_checked
def normal(mean: float, std: float):
    """A normal distribution (for :func:`scenarios`).

    The numbers are in the unit of the quantity the distribution is given to (degrees for a
    ``*_deg`` argument of :func:`scenarios`, metres for ``lateral_offset``, ...).

    Args:
        mean: its mean, a finite number.
        std: its standard deviation, a finite number above 0.

    Returns:
        a ``Dist`` (:class:`pfjax.montecarlo.dists.Dist`), as a study config's
        ``{dist = "normal", mean, std}`` table holds it.

    Raises:
        pfjax.errors.InputError: ``normal: ...`` naming the bad value: not a finite number, or
            ``std <= 0``.
    """
    from pfjax.montecarlo.config import Dist

    return _dist(Dist, dist="normal", mean=mean, std=std)


@arguments_checked
def truncnormal(mean: float, std: float, low: float, high: float):
    """A normal distribution truncated to ``[low, high]`` (for :func:`scenarios`).

    The numbers are in the unit of the quantity the distribution is given to (degrees for a
    ``*_deg`` argument of :func:`scenarios`, metres for ``lateral_offset``, ...).

    Args:
        mean: the mean of the normal it truncates, in ``[low, high]``.
        std: the standard deviation of the normal it truncates, above 0.
        low: the lower end, a finite number.
        high: the upper end, a finite number above ``low``.

    Returns:
        a ``Dist`` (:class:`pfjax.montecarlo.dists.Dist`), as a study config's
        ``{dist = "truncnormal", mean, std, low, high}`` table holds it.

    Raises:
        pfjax.errors.InputError: ``truncnormal: ...`` naming the bad value: not a finite number,
            ``std <= 0``, ``low >= high`` or ``mean`` outside ``[low, high]``.
    """
    from pfjax.montecarlo.config import Dist

    return _dist(Dist, dist="truncnormal", mean=mean, std=std, low=low, high=high)


@arguments_checked
def choice(values):
    """A uniform choice among ``values`` (for :func:`scenarios`).

    The numbers are in the unit of the quantity the distribution is given to (degrees for a
    ``*_deg`` argument of :func:`scenarios`, metres for ``lateral_offset``, ...).

    Args:
        values: a non-empty list (tuple, 1-D NumPy or JAX array) of finite numbers; no strings,
            no booleans.

    Returns:
        a ``Dist`` (:class:`pfjax.montecarlo.dists.Dist`), as a study config's
        ``{dist = "choice", values}`` table holds it.

    Raises:
        pfjax.errors.InputError: ``choice: ...``: ``values`` empty, or an item that is not a finite
            number (``choice: values[i]: ...``).
    """
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
