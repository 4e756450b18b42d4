"""The controller registry: one entry per controller kind, carrying everything the rest of pfjax
needs of it (the command line's name and gain order, the study config's type, the tuning box, the
plot style). Config literals, command-line choices, tuning boxes and report colours are read from
here, so adding a controller is its own module plus one :func:`register` call.

An entry unpacks into its first two fields as ``controller, make_params = entry[:2]``.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable, Mapping
from typing import Any, NamedTuple

from pfjax import errors
from pfjax.controllers.base import Controller


class ControllerEntry(NamedTuple):
    """One controller kind.

    Attributes:
        controller: the :class:`~pfjax.controllers.base.Controller`.
        make_params: keyword gains -> its parameter pytree, checked (:func:`checked_factory`):
            an unknown gain or a gain that is not a finite number raises an
            :class:`~pfjax.errors.InputError` naming ``gains.<name>``.
        name: the config and Python name (snake_case): a study's ``controllers[i].type``,
            ``pfjax tune --controller`` after ``-`` → ``_``.
        gains: the scalar gains ``--gains`` takes in order (names of :func:`flat_gains`).
        cli_name: the command-line name (kebab-case).
        box: tuning box ``(fields, lower, upper)`` (flat, in field order) or None (not tunable).
        style: plot style (matplotlib keywords ``color``, ``lw``, ``ls`` and a ``label``).
    """

    controller: Controller
    make_params: CheckedFactory
    name: str
    gains: tuple[str, ...]
    cli_name: str
    box: tuple | None
    style: dict
    labels: dict  # vector field -> names of its elements (K -> k_d, k_theta): the scalar gains


#: name -> entry.
REGISTRY: dict[str, ControllerEntry] = {}


class CheckedFactory:
    """A parameter factory (keyword gains -> parameter pytree) with its arguments checked: an unknown
    gain name or a gain that is not a finite number raises :class:`~pfjax.errors.InputError` naming
    ``gains.<name>``. ``defaults`` are used for the gains not given; ``gain_names`` are the factory's
    keyword names, in order."""

    def __init__(self, name: str, factory: Callable[..., Any], defaults: dict | None = None):
        self.name, self.factory, self.defaults = name, factory, dict(defaults or {})
        self.gain_names: tuple[str, ...] = tuple(inspect.signature(factory).parameters)
        self.__doc__ = factory.__doc__

    def __call__(self, **gains) -> Any:
        for k, v in gains.items():
            if k not in self.gain_names:
                raise errors.InputError(
                    f"gains.{k}: unknown gain for controller {self.name!r}; expected one of "
                    f"{', '.join(self.gain_names)}",
                    "gains",
                )
            errors.numbers(f"gains.{k}", v)
        return self.factory(**{**self.defaults, **gains})


def checked_factory(name: str, factory: Callable[..., Any], defaults: dict | None = None) -> CheckedFactory:
    """``factory`` with its arguments checked (:class:`CheckedFactory`)."""
    return CheckedFactory(name, factory, defaults)


def register(
    controller: Controller,
    factory,
    *,
    name: str | None = None,
    defaults: dict | None = None,
    cli_name: str | None = None,
    box: tuple | None = None,
    style: dict | None = None,
    labels: dict | None = None,
    gains: tuple | None = None,
) -> ControllerEntry:
    """Add a controller kind (replacing one of the same name) and return its entry.

    Args:
        controller: the controller.
        factory: keyword gains -> parameter pytree (its parameters name the fields, in order).
        name: registry name (default ``controller.name``).
        defaults: default gains the factory does not have itself.
        cli_name: command-line name (default the name with ``_`` → ``-``).
        box: tuning box ``(fields, lower, upper)``.
        style: plot style (default grey, the name as label).
        labels: names of a vector field's elements (``{"K": ("k_d", "k_theta")}``).
        gains: the scalar gains ``--gains`` takes in order (default all of them).
    """
    name = name or controller.name
    make = checked_factory(name, factory, defaults)
    labels = dict(labels or {})
    flat = tuple(n for f in make.gain_names for n in labels.get(f, (f,)))
    entry = ControllerEntry(
        controller,
        make,
        name,
        tuple(gains or flat),
        cli_name or name.replace("_", "-"),
        box,
        {"color": "#7f7f7f", "lw": 1.0, "label": name, **(style or {})},
        labels,
    )
    REGISTRY[name] = entry
    return entry


def flat_gains(e: ControllerEntry, params=None) -> dict[str, float]:
    """A parameter pytree as scalar gains (vector fields split by ``e.labels``); default: the
    controller's default gains. What outputs record and ``--gains`` names."""
    import jax
    import numpy as np

    if params is None:
        with jax.enable_x64(True):  # the defaults as written, not rounded to float32
            params = jax.tree_util.tree_map(np.asarray, e.make_params())
    out = {}
    for field, value in params._asdict().items():
        v = np.ravel(np.asarray(value, dtype=float))
        names = e.labels.get(field, (field,))
        if len(names) != v.size:
            raise ValueError(f"{e.name}: field {field} has {v.size} elements, labels {names}")
        out.update({n: float(x) for n, x in zip(names, v)})
    return out


def params_from_flat(e: ControllerEntry, flat: Mapping[str, Any], key: str = "gains") -> Any:
    """The parameter pytree from scalar gains ``{name: value}`` (the others at their defaults); an
    unknown name raises :class:`~pfjax.errors.InputError` naming ``<key>.<name>``."""
    default = flat_gains(e)
    for k, v in flat.items():
        if k not in default:
            raise errors.InputError(
                f"{key}.{k}: unknown gain for controller {e.name!r}; expected one of {', '.join(default)}", key
            )
        errors.numbers(f"{key}.{k}", v)
    merged = {**default, **flat}
    fields = {}
    for field in e.make_params.gain_names:
        names = e.labels.get(field)
        fields[field] = [merged[n] for n in names] if names else merged[field]
    return e.make_params(**fields)


def entry(name: str, key: str = "controller") -> ControllerEntry:
    """The entry of ``name`` (registry or command-line name); :class:`~pfjax.errors.InputError` naming
    ``key`` if there is none."""
    found = REGISTRY.get(name) or next((e for e in REGISTRY.values() if e.cli_name == name), None)
    if found is None:
        raise errors.InputError(f"{key}: unknown controller {name!r}; expected one of {', '.join(REGISTRY)}", key)
    return found
