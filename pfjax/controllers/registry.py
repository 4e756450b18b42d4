"""The controller registry: one entry per controller kind, carrying everything the rest of pfjax
needs of it (the command line's name and gain order, the study config's type, the tuning box, the
plot style). Config literals, command-line choices, tuning boxes and report colours are read from
here, so adding a controller is its own module plus one :func:`register` call.

An entry unpacks into its first two fields as ``controller, make_params = entry[:2]``.
"""

from __future__ import annotations

import inspect
import re
from collections.abc import Callable, Mapping
from typing import Any, NamedTuple

from pfjax import errors, plugins
from pfjax.controllers.base import Controller
from pfjax.tables import unit_powers


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
        box: tuning box ``(fields, lower, upper)`` (bounds flat, in field order, in the gains' units;
            checked by :func:`check_box`) or None (not tunable).
        style: plot style (matplotlib keywords ``color``, ``lw``, ``ls`` and a ``label``).
        labels: names of a vector field's elements (``{"K": ("k_d", "k_theta")}``).
        module: the module that registered it (:func:`pfjax.plugins.registrant`), the only one that
            may register its name again; ``pfjax.*`` for pfjax's own controllers.
        units: each scalar gain's unit by its name (``{"kp_d": "rad/m", ...}``; names of
            :func:`gain_names`); what outputs record as the gains' units (:func:`gain_units`). A
            gain without one is recorded as :data:`UNSTATED`.
    """

    controller: Controller
    make_params: CheckedFactory
    name: str
    gains: tuple[str, ...]
    cli_name: str
    box: tuple | None
    style: dict
    labels: dict  # vector field -> names of its elements (K -> k_d, k_theta): the scalar gains
    module: str
    units: dict  # scalar gain -> its unit


#: The unit recorded for a gain whose controller was registered without one (``register(units=...)``).
UNSTATED = "not stated (registered without units)"

#: name -> entry.
REGISTRY: dict[str, ControllerEntry] = {}

#: name or command-line name -> what takes it outside the registry (:func:`reserve`).
RESERVED: dict[str, str] = {}

#: A controller's functions -> the arguments pfjax calls them with (:mod:`pfjax.controllers.base`).
_CALLS = {
    "init": ("params",),
    "output": ("params", "c", "obs"),
    "rate": ("params", "c", "obs", "delta_cmd", "delta_applied"),
}

#: A registry name: a lower-case ASCII identifier; a command-line name: the same with ``-``.
_NAME = re.compile(r"[a-z][a-z0-9_]*")
_CLI = re.compile(r"[a-z][a-z0-9-]*")


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
    units: Mapping[str, str] | None = None,
) -> ControllerEntry:
    """Add a controller kind and return its entry.

    A name belongs to the module that registered it (the ``__name__`` of the module whose code
    calls ``register``: :func:`pfjax.plugins.registrant`): registering it again from that module
    replaces its entry (re-running a notebook cell, :func:`importlib.reload`); from any other module,
    and for pfjax's own controllers (``pi``, ``stanley``, ...), it is refused.

    Args:
        controller: the controller (a :class:`~pfjax.controllers.base.Controller`) whose functions
            take the positional arguments pfjax calls them with: ``init(params)``,
            ``output(params, c, obs)``, ``rate(params, c, obs, delta_cmd, delta_applied)``
            (checked when the signature can be read).
        factory: keyword gains -> parameter pytree (its parameters name the gain fields, in order).
        name: registry name, a lower-case ASCII identifier (a letter, then letters, digits, ``_``;
            default ``controller.name``); not a name of pfjax's own controllers or of another
            module's.
        defaults: default gains the factory does not have itself (keys: its parameters).
        cli_name: command-line name, lower-case ASCII letters, digits and ``-`` after a letter
            (default the name with ``_`` → ``-``). Neither ``name`` nor ``cli_name`` may be a name
            or command-line name of another entry (one of the same name registered by this module
            is replaced, its names with it) or of a design (``lmi``, ``mixed``, ...;
            :func:`reserve`): the new controller could not be reached by it.
        box: tuning box ``(fields, lower, upper)``, or None (not tunable): distinct gain fields
            and their flat bounds, in the gains' own units (:func:`check_box`).
        style: plot style, a mapping of matplotlib keywords (``color``, ``lw``, ``ls``, ``label``;
            default grey, the name as label).
        labels: names of a vector field's elements (``{"K": ("k_d", "k_theta")}``); a field
            without labels is a scalar.
        gains: the scalar gains ``--gains`` takes in order (default all of them).
        units: each scalar gain's unit by its name (``{"k": "1/s", "k_soft": "m/s"}``; a vector
            field's elements by their ``labels``), which outputs record beside the gains; a gain
            left out is recorded as :data:`UNSTATED`.

    Raises:
        InputError: an argument that is not as described, naming it (``box.lower[1]: ...``,
            ``name: 'pi' is taken by pfjax's controller 'pi'; choose another``,
            ``controller.output: expected output(params, c, obs), got (p, obs)``).
    """
    module = plugins.registrant(__name__)
    if not isinstance(controller, Controller):
        raise errors.InputError(f"controller: expected a pfjax Controller, got {type(controller).__name__}")
    for field, args in _CALLS.items():
        plugins.check_call(f"controller.{field}", getattr(controller, field), args)
    if not callable(factory):
        raise errors.InputError(f"factory: expected a callable (keyword gains -> parameters), got {factory!r}")
    name = _spelling(
        "name", controller.name if name is None else name, _NAME, "identifier (a letter, then letters, digits, _)"
    )
    cli_name = _spelling(
        "cli_name",
        name.replace("_", "-") if cli_name is None else cli_name,
        _CLI,
        "command-line name (a letter, then letters, digits, -)",
    )
    taken = _taken(name, module)  # a second owner of a spelling would never be reached by it
    for key, spelling in (("name", name), ("cli_name", cli_name)):
        if spelling in taken:
            raise errors.InputError(f"{key}: {spelling!r} is taken by {taken[spelling]}; choose another", key)
    if style is not None and not isinstance(style, Mapping):
        raise errors.InputError(
            f"style: expected a mapping of matplotlib keywords (color, lw, ls, label), got {style!r}", "style"
        )
    make = checked_factory(name, factory, defaults)
    for k in defaults or {}:
        _field("defaults", k, make)
    labels = dict(labels or {})
    for k, names in labels.items():
        _field("labels", k, make)
        if not isinstance(names, (tuple, list)) or not names or not all(isinstance(n, str) for n in names):
            raise errors.InputError(f"labels.{k}: expected a non-empty tuple of gain names, got {names!r}")
    flat = tuple(scalar_names(labels, make.gain_names))
    for k in gains or ():
        if k not in flat:
            raise errors.InputError(f"gains: unknown gain {k!r} of {name!r}; expected one of {', '.join(flat)}")
    units = _units(units, name, flat)
    entry = ControllerEntry(
        controller,
        make,
        name,
        tuple(gains or flat),
        cli_name,
        None if box is None else check_box(box, make, labels),
        {"color": "#7f7f7f", "lw": 1.0, "label": name, **(style or {})},
        labels,
        module,
        units,
    )
    REGISTRY[name] = entry
    return entry


def _units(units, name: str, flat: tuple[str, ...]) -> dict[str, str]:
    """``register``'s ``units`` as a dict, checked: a mapping from scalar gains of ``name`` (``flat``)
    to non-empty strings; an :class:`~pfjax.errors.InputError` naming ``units`` or ``units.<gain>``
    otherwise."""
    if units is None:
        return {}
    if not isinstance(units, Mapping):
        raise errors.InputError(f"units: expected a mapping of gain name -> unit, got {units!r}", "units")
    for k, u in units.items():
        if k not in flat:
            raise errors.InputError(f"units.{k}: unknown gain of {name!r}; expected one of {', '.join(flat)}", "units")
        if not isinstance(u, str) or not u.strip():
            raise errors.InputError(f"units.{k}: expected a unit (a non-empty string), got {u!r}", "units")
        if unit_powers(u) is None:  # the Froude scaling reads it, outputs record it
            raise errors.InputError(
                f"units.{k}: expected a product of m, s, rad and 1 with powers, over one such product "
                f"(rad/(m s), 1/m^2), got {u!r}",
                "units",
            )
    return dict(units)


def check_box(box, make: CheckedFactory, labels: Mapping[str, tuple], key: str = "box") -> tuple:
    """``box = (fields, lower, upper)`` as tuples, checked against a controller's gain fields.

    ``fields`` are distinct gain fields of ``make`` (the factory's parameters); ``lower`` and
    ``upper`` are flat bounds of ``D`` finite numbers each, ``D`` the fields' total size (a field
    with ``labels`` has one element per label, any other is a scalar), with ``lower < upper``
    elementwise: the box ``lower <= theta <= upper`` that tuning searches
    (:class:`pfjax.tuning.cost.Tunable` writes ``theta`` into the fields). An
    :class:`~pfjax.errors.InputError` naming ``key`` (``box.fields``, ``box.lower[i]``, ...) otherwise.
    """
    import numpy as np

    if not isinstance(box, (tuple, list)) or len(box) != 3:
        raise errors.InputError(f"{key}: expected (fields, lower, upper), got {box!r}", key)
    fields, lower, upper = box
    if isinstance(fields, str) or not isinstance(fields, (tuple, list)) or not fields:
        raise errors.InputError(f"{key}.fields: expected a non-empty tuple of gain fields, got {fields!r}")
    for f in fields:
        _field(f"{key}.fields", f, make)
    errors.unique(f"{key}.fields", fields)
    size = len(scalar_names(labels, fields))
    lo, hi = (_bounds(f"{key}.{side}", b, size, fields) for side, b in (("lower", lower), ("upper", upper)))
    if not np.all(lo < hi):
        i = int(np.argmin(lo < hi))
        raise errors.InputError(f"{key}.lower[{i}]: must be < {key}.upper[{i}] = {hi[i]:g}, got {lo[i]:g}")
    return tuple(fields), tuple(lo.tolist()), tuple(hi.tolist())


def _bounds(key: str, value, size: int, fields) -> Any:
    """``value`` as a float array of shape ``(size,)`` of finite numbers; InputError naming ``key``."""
    import numpy as np

    a = None if value is None else np.asarray(errors.numbers(key, value), dtype=float)
    if a is None or a.shape != (size,):
        raise errors.InputError(
            f"{key}: expected {size} numbers (the flat elements of {', '.join(fields)}), got {value!r}", key
        )
    return a


def _field(key: str, name, make: CheckedFactory) -> None:
    """InputError naming ``key`` unless ``name`` is one of the gain fields of ``make``."""
    if name not in make.gain_names:
        raise errors.InputError(
            f"{key}: unknown gain field {name!r} of {make.name!r}; expected one of {', '.join(make.gain_names)}", key
        )


def _spelling(key: str, value, pattern: re.Pattern, rule: str) -> str:
    """``value`` if it is a string matching ``pattern`` (``rule`` describes it); InputError naming
    ``key`` otherwise."""
    if not isinstance(value, str) or not pattern.fullmatch(value):
        raise errors.InputError(f"{key}: expected a lower-case ASCII {rule}, got {value!r}", key)
    return value


def reserve(spellings, owner: str) -> None:
    """Keep ``spellings`` (names and command-line names resolved before the registry's, such as the
    designs' ``lmi`` and ``mixed``: :mod:`pfjax.controllers.designs`) from :func:`register`;
    ``owner`` says what takes them in its error (``"the lmi design"``)."""
    for n in spellings:
        RESERVED[n] = owner


def _taken(name: str, module: str) -> dict[str, str]:
    """spelling -> what takes it, for every name and command-line name :func:`register` must not
    give the entry ``name`` registered by ``module`` (the entry ``name`` that ``module`` registered
    is replaced, so its names are free)."""
    out = dict(RESERVED)
    for e in REGISTRY.values():
        if e.name == name and e.module == module:
            continue
        what = (
            f"pfjax's controller {e.name!r}"
            if plugins.is_builtin(e.module)
            else f"controller {e.name!r} of module {e.module!r} (only that module may register it again)"
        )
        out.update({e.name: what, e.cli_name: what})
    return out


def flat_gains(e: ControllerEntry, params=None, key: str = "gains") -> dict[str, float]:
    """A parameter pytree as scalar gains (vector fields split by ``e.labels``); default: the
    controller's default gains. What outputs record and ``--gains`` names. A field with another
    number of elements than its labels raises :class:`~pfjax.errors.InputError` naming ``key``."""
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
            raise errors.InputError(
                f"{key}: the {e.name} controller's {field} takes {len(names)} values ({', '.join(names)}), got {v.size}",
                key,
            )
        out.update({n: float(x) for n, x in zip(names, v)})
    return out


def params_from_flat(e: ControllerEntry, flat: Mapping[str, Any], key: str = "gains") -> Any:
    """The parameter pytree from scalar gains ``{name: value}`` (the others at their defaults); an
    unknown name, or a value that is not one finite number, raises
    :class:`~pfjax.errors.InputError` naming ``<key>.<name>``."""
    check_gain_names(e, flat, key)
    default = flat_gains(e)
    for k, v in flat.items():
        _scalar(f"{key}.{k}", v)
    merged = {**default, **flat}
    fields = {}
    for field in e.make_params.gain_names:
        names = e.labels.get(field)
        fields[field] = [merged[n] for n in names] if names else merged[field]
    return e.make_params(**fields)


def scalar_names(labels: Mapping, fields) -> list[str]:
    """The scalar gains of gain ``fields`` by name, in field order: a vector field by its ``labels``
    (``K`` as ``k_d``, ``k_theta``), a scalar one by its own name."""
    return [n for f in fields for n in labels.get(f, (f,))]


def gain_names(e: ControllerEntry, fields=None) -> list[str]:
    """Every scalar gain of the controller by name (:func:`flat_gains`' names: every field, vector
    fields by their labels), without building its parameters, or those of ``fields`` only (a
    tuning box's, in its order); ``e.gains``, those ``--gains`` takes by position, are some of them."""
    return scalar_names(e.labels, e.make_params.gain_names if fields is None else fields)


def gain_units(e: ControllerEntry) -> dict[str, str]:
    """Every scalar gain's unit by its name (:func:`gain_names`' order): what outputs record beside
    :func:`flat_gains`; :data:`UNSTATED` for a gain the registration gives none."""
    return {n: e.units.get(n, UNSTATED) for n in gain_names(e)}


def box_units(e: ControllerEntry, fields) -> list[str]:
    """The unit of each element of a tuning box over ``fields`` (gain fields of ``e``), flat in field
    order (a vector field by its ``labels``): the units of a box's bounds and of a point in it."""
    units = gain_units(e)
    return [units[n] for n in gain_names(e, fields)]


def check_gain_names(e: ControllerEntry, names, key: str = "gains", called: str | None = None) -> None:
    """:class:`~pfjax.errors.InputError` naming ``<key>.<name>`` for the first of ``names`` that is
    not one of the controller's scalar gains (:func:`gain_names`); nothing is built (a study config
    checks its gains' names as it loads). ``called``: the name the caller gave, when it is a design
    of ``e`` (``lmi``, a ``state_feedback`` design), which the message then names first."""
    known = gain_names(e)
    shown = repr(e.name) if called in (None, e.name) else f"{called!r} (a {e.name} design)"
    for k in names:
        if k not in known:
            raise errors.InputError(
                f"{key}.{k}: unknown gain for controller {shown}; expected one of {', '.join(known)}", key
            )


def _scalar(key: str, value) -> None:
    """InputError naming ``key`` unless ``value`` is one finite real number (a Python or NumPy
    scalar, a 0-d NumPy or JAX array): the gains are the same for every run, not one per run."""
    shape = (len(value),) if isinstance(value, (list, tuple)) else getattr(value, "shape", ())
    if shape:
        raise errors.InputError(
            f"{key}: expected a number (one gain for all runs), got an array of shape {tuple(shape)}", key
        )
    if hasattr(value, "shape"):  # a NumPy or JAX scalar, traced or not
        errors.numbers(key, value)
    else:
        errors.number(key, value)


def entry(name: str, key: str = "controller") -> ControllerEntry:
    """The entry of ``name`` (registry or command-line name); :class:`~pfjax.errors.InputError` naming
    ``key`` if there is none."""
    found = REGISTRY.get(name) or next((e for e in REGISTRY.values() if e.cli_name == name), None)
    if found is None:
        raise errors.InputError(f"{key}: unknown controller {name!r}; expected one of {', '.join(REGISTRY)}", key)
    return found
