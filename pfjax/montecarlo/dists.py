"""Distributions of a Monte Carlo study's uncertain quantities: every such key of the config is a
bare number (constant) or a table ``{dist = "uniform", low = -10, high = 10}`` (uniform, normal,
truncated normal, choice), validated here; :func:`nominal` is a distribution's centre."""

from __future__ import annotations

import math
from typing import Any, Literal

from pydantic import Field, model_validator

from pfjax.config import ConfigModel, Real


class Dist(ConfigModel):
    """A distribution of one scalar (see module docstring)."""

    dist: Literal["constant", "uniform", "normal", "truncnormal", "choice"]
    value: Real | None = None
    low: Real | None = None
    high: Real | None = None
    mean: Real | None = None
    std: Real | None = None
    values: list[Real] | None = None

    @model_validator(mode="after")
    def _check(self):
        need = {
            "constant": ("value",),
            "uniform": ("low", "high"),
            "normal": ("mean", "std"),
            "truncnormal": ("mean", "std", "low", "high"),
            "choice": ("values",),
        }[self.dist]
        for f in need:
            if getattr(self, f) is None:
                raise ValueError(f"dist '{self.dist}' needs '{f}'")
        for f in ("value", "low", "high", "mean", "std", "values"):
            if f not in need and getattr(self, f) is not None:
                raise ValueError(f"dist '{self.dist}' does not use '{f}' (it takes {', '.join(need)})")
        for f in ("value", "low", "high", "mean", "std"):
            v = getattr(self, f)
            if v is not None and not math.isfinite(v):
                raise ValueError(f"'{f}' must be finite, got {v}")
        if self.low is not None and self.high is not None and not self.low < self.high:
            raise ValueError(f"needs low < high, got low={self.low:g}, high={self.high:g}")
        if self.std is not None and not self.std > 0:
            raise ValueError(f"needs std > 0, got {self.std:g}")
        if self.dist == "truncnormal" and not self.low <= self.mean <= self.high:
            raise ValueError(
                f"needs low <= mean <= high (the mean of the normal it truncates), got mean={self.mean:g} "
                f"outside [{self.low:g}, {self.high:g}]"
            )
        if self.values is not None and (not self.values or not all(math.isfinite(v) for v in self.values)):
            raise ValueError("'values' must be a non-empty list of finite numbers")
        return self

    def number(self, name: str) -> float:
        """The parameter ``name`` (``value``, ``low``, ``high``, ``mean`` or ``std``) of a distribution that
        uses it (the validator guarantees it is set)."""
        v = getattr(self, name)
        if v is None:
            raise ValueError(f"dist '{self.dist}' has no '{name}'")
        return float(v)

    def numbers(self) -> dict:
        """The parameters its kind uses, by name (``value``, ``low``, ``high``, ``mean``, ``std``:
        floats; ``values``: a list)."""
        return {k: v for k, v in self.model_dump(exclude={"dist"}).items() if v is not None}

    def bounds(self) -> tuple[float, float]:
        """Support of the distribution (inf for the normal)."""
        if self.dist == "constant":
            return self.number("value"), self.number("value")
        if self.dist == "choice":
            values = self.values or []
            return min(values), max(values)
        if self.dist == "normal":
            return -math.inf, math.inf
        return self.number("low"), self.number("high")


def as_dist(v: Any):
    if isinstance(v, bool):
        raise ValueError("expected a number or a distribution table")
    if isinstance(v, (int, float)):
        from pfjax.errors import number

        try:
            number("value", v)
        except ValueError as e:
            raise ValueError(str(e).removeprefix("value: ")) from None
        return Dist(dist="constant", value=float(v))
    return v


def dist_field(default: float, description: str | None = None):
    return Field(default_factory=lambda: Dist(dist="constant", value=default), description=description)


def nominal(d: Dist) -> float:
    """A distribution's nominal value: its value, mean, midpoint or the mean of its choices."""
    if d.dist == "constant":
        return d.number("value")
    if d.mean is not None:
        return float(d.mean)
    if d.dist == "choice" and d.values:
        return float(sum(d.values) / len(d.values))
    return 0.5 * (d.number("low") + d.number("high"))


#: How far the Ornstein-Uhlenbeck slip term is taken to reach when the total slip is checked: its
#: stationary std times this (a 6-sigma excursion has probability about 2e-9 per sample).
