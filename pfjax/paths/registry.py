"""The path registry: one entry per path kind, carrying what the rest of pfjax needs of it (the
builder, the nominal start, the curvature bound). The study config's ``paths[i].kind``, the
command line's ``--path`` choices, the tuning scenario sets and the source's test list are read
from here, so adding a path is its builder plus one :func:`register` call.

Two sorts of entry:

- *fixed* paths (``build`` is a function of no arguments): the source's line, parabola and sine,
  pfjax's circle of radius 2 m, and any path a user registers. A single run starts at
  ``start_pose``; a study's runs start ``start_along_m`` metres along the path from parameter
  ``start_u``, displaced by their lateral offset and heading error.
- *parametric* kinds (``parametric=True``): built per study from the path config's own fields
  (``circle`` with a drawn radius, ``random`` splines, user ``spline`` points) by
  :mod:`pfjax.montecarlo.sampling`; they have no single-run command-line form beyond the circle's
  default.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable
from typing import Any, NamedTuple

from pfjax import errors, plugins


class PathEntry(NamedTuple):
    """One path kind.

    Attributes:
        name: config and command-line name (``paths[i].kind``, ``--path``).
        build: ``() -> path`` (a :mod:`pfjax.paths.shapes` pytree), or None for a kind built only
            from a study's path config.
        start_pose: single runs' start ``(x, y, theta)`` (m, m, rad), or None.
        start_u: path parameter from which a study's ``start_along_m`` is measured.
        max_curvature: largest |curvature| over the path (1/m), or None when it depends on the
            study's path config (computed by :func:`pfjax.montecarlo.checks.path_max_curvature`).
        source: one of the source's three test paths.
        parametric: built from the study's path config (``circle``, ``random``, ``spline``).
        description: one line for reports.
        module: the module that registered it (:func:`pfjax.plugins.registrant`), the only one that
            may register its name again; ``pfjax.paths.registry`` for pfjax's own kinds.
    """

    name: str
    build: Callable | None
    start_pose: tuple[float, float, float] | None
    start_u: float
    max_curvature: float | None
    source: bool
    parametric: bool
    description: str
    module: str


#: name -> entry, in registration order.
PATHS: dict[str, PathEntry] = {}

#: A path kind's name: a lower-case ASCII identifier.
_NAME = re.compile(r"[a-z][a-z0-9_]*")

#: The parametric kinds: :mod:`pfjax.montecarlo.sampling` builds them from a study's path config.
PARAMETRIC = ("circle", "random", "spline")


def register(
    name: str,
    build: Callable | None = None,
    *,
    start_pose=None,
    start_u: float = 0.0,
    max_curvature: float | None = None,
    source: bool = False,
    parametric: bool = False,
    description: str = "",
) -> PathEntry:
    """Add a path kind and return its entry (see :class:`PathEntry`).

    ``build`` is called once here, so a builder that raises or returns no path is refused when it
    is registered rather than wherever the path is first used.

    A name belongs to the module that registered it (the ``__name__`` of the module whose code
    calls ``register``: :func:`pfjax.plugins.registrant`): registering it again from that module
    replaces its entry (re-running a notebook cell, :func:`importlib.reload`); from any other module,
    and for pfjax's own kinds (``line``, ``sine``, ``circle``, ...), it is refused.

    Args:
        name: the kind's config and command-line name, a lower-case ASCII identifier (a letter, then
            letters, digits and ``_``: ``paths[i].kind``, ``--path``); not a name of pfjax's own
            kinds or of another module's.
        build: ``() -> path``, a function of no arguments returning a :mod:`pfjax.paths.shapes`
            pytree (a curve ``p(u)`` in m: a ``NamedTuple`` with methods ``point``, ``d1``, ``d2``
            of ``u`` and scalar fields ``u_min < u_max``); None only for the parametric kinds (:data:`PARAMETRIC`), built from a
            study's path config.
        start_pose: single runs' start ``(x, y, theta)`` (m, m, rad), three finite numbers; needed
            with ``build``.
        start_u: path parameter ``u`` (m: ``x`` on a graph ``y = f(x)``, arc length on a circle,
            chord length on a spline) from which a study's ``start_along_m`` is measured.
        max_curvature: largest |curvature| over the path (1/m, >= 0), or None where it depends on
            the study's path config (:func:`pfjax.montecarlo.checks.path_max_curvature`).
        source: one of the source's three test paths (:func:`source_tests`).
        parametric: built per study from the path config's fields, only for :data:`PARAMETRIC`
            (``build``, if given, is the single runs' path).
        description: one line for reports (default the name).

    Raises:
        InputError: an argument that is not as described, naming it (``build: ...`` for a builder
            that takes arguments, raises or returns something that is not a path;
            ``name: 'sine' is taken by pfjax's path 'sine'; choose another``).
    """
    module = plugins.registrant(__name__)
    e = _entry(
        name,
        build,
        start_pose=start_pose,
        start_u=start_u,
        max_curvature=max_curvature,
        source=source,
        parametric=parametric,
        description=description,
        module=module,
    )
    old = PATHS.get(name)
    if old is not None and old.module != module:
        what = (
            f"pfjax's path {name!r}"
            if plugins.is_builtin(old.module)
            else f"path {name!r} of module {old.module!r} (only that module may register it again)"
        )
        raise errors.InputError(f"name: {name!r} is taken by {what}; choose another", "name")
    if build is not None:
        _check_build(name, build)
    PATHS[name] = e
    return e


def _entry(
    name,
    build,
    *,
    start_pose=None,
    start_u=0.0,
    max_curvature=None,
    source=False,
    parametric=False,
    description="",
    module: str,
) -> PathEntry:
    """The entry of :func:`register`'s arguments, each checked (its builder is not called), registered
    by ``module``."""
    if not isinstance(name, str) or not _NAME.fullmatch(name):
        raise errors.InputError(
            f"name: a path kind is a lower-case ASCII identifier (a letter, then letters, digits, _), got {name!r}",
            "name",
        )
    if build is not None and not callable(build):
        raise errors.InputError(f"build: expected a function () -> path, got {build!r}", "build")
    if build is not None:
        plugins.check_call("build", build, ())
    for key, flag in (("source", source), ("parametric", parametric)):
        if not isinstance(flag, bool):
            raise errors.InputError(f"{key}: expected True or False, got {flag!r}", key)
    if parametric and name not in PARAMETRIC:
        raise errors.InputError(
            f"parametric: only {', '.join(PARAMETRIC)} are built from a study's path config; {name!r} needs build",
            "parametric",
        )
    if build is None and not parametric:
        raise errors.InputError(f"build: path {name!r} needs a function () -> path", "build")
    if build is not None and start_pose is None:
        raise errors.InputError(
            f"start_pose: a fixed path ({name!r}) needs a single-run start pose (x, y, theta)", "start_pose"
        )
    if not isinstance(description, str):
        raise errors.InputError(f"description: expected a string, got {description!r}", "description")
    return PathEntry(
        name,
        build,
        None if start_pose is None else _pose("start_pose", start_pose),
        errors.number("start_u", start_u, unit=" m"),
        None if max_curvature is None else errors.number("max_curvature", max_curvature, nonnegative=True, unit=" 1/m"),
        source,
        parametric,
        " ".join(description.split()) or name,
        module,
    )


def _check_build(name: str, build: Callable) -> None:
    """Call ``build`` once: InputError naming ``build`` if it raises or returns no path (a
    ``NamedTuple`` with ``point``, ``d1``, ``d2`` giving ``(x, y)`` scalars at a scalar ``u``, and
    finite scalars ``u_min < u_max``). The methods are traced (:func:`jax.eval_shape`), not run."""
    import jax
    import jax.numpy as jnp
    import numpy as np

    def refuse(why: str):
        return errors.InputError(f"build: the builder of path {name!r} {why}", "build")

    try:
        path = build()
    except Exception as ex:  # a user's builder: any failure is bad input here
        raise refuse(f"raised {type(ex).__name__}: {ex}") from None
    expected = "expected a pfjax.paths.shapes pytree (Graph, Circle, Spline)"
    got = f"{type(path).__name__} {path!r}"[:80]
    if not (isinstance(path, tuple) and hasattr(path, "_fields")):
        raise refuse(f"returned {got}, not a path; {expected} or a NamedTuple with point, d1, d2")
    missing = [m for m in ("point", "d1", "d2") if not callable(getattr(path, m, None))]
    missing += [f for f in ("u_min", "u_max") if f not in path._fields]
    if missing:
        raise refuse(f"returned a {type(path).__name__} without {', '.join(missing)}; {expected}")
    try:
        lo, hi = (np.asarray(getattr(path, f), dtype=float) for f in ("u_min", "u_max"))
    except (TypeError, ValueError) as ex:
        raise refuse(f"returned u_min, u_max that are not numbers ({ex})") from None
    if lo.shape != () or hi.shape != ():
        raise refuse(f"returned u_min, u_max of shapes {lo.shape}, {hi.shape}; expected scalars")
    if not (np.isfinite(lo) and np.isfinite(hi) and lo < hi):
        raise refuse(f"returned u_min = {float(lo):g}, u_max = {float(hi):g}; expected finite u_min < u_max")
    shape: Any = path  # a NamedTuple with the methods checked above
    u = jax.ShapeDtypeStruct((), jnp.result_type(float))
    try:
        out = jax.eval_shape(lambda u: (shape.point(u), shape.d1(u), shape.d2(u)), u)
    except Exception as ex:  # a user's shape: its methods as the simulator traces them
        first = (str(ex).splitlines() or [""])[0]
        raise refuse(f"returned a {type(path).__name__} whose point/d1/d2 fail: {type(ex).__name__}: {first}") from None
    for m, xy in zip(("point", "d1", "d2"), out):
        if not (isinstance(xy, tuple) and len(xy) == 2 and all(getattr(c, "shape", None) == () for c in xy)):
            raise refuse(f"returned a {type(path).__name__} whose {m}(u) is not a pair (x, y) of scalars")


def _pose(key: str, value) -> tuple[float, float, float]:
    """``value`` as ``(x, y, theta)`` floats (m, m, rad); InputError naming ``key`` unless it is three
    finite numbers."""
    import numpy as np

    a = np.asarray(errors.numbers(key, value), dtype=float)
    if a.shape != (3,):
        raise errors.InputError(f"{key}: expected three numbers (x, y, theta) in m, m, rad, got {value!r}", key)
    x, y, theta = a.tolist()
    return x, y, theta


def entry(name: str, key: str = "path") -> PathEntry:
    """The entry of ``name``; :class:`~pfjax.errors.InputError` naming ``key`` if there is none."""
    if name not in PATHS:
        raise errors.InputError(f"{key}: unknown path {name!r}; expected one of {', '.join(PATHS)}", key)
    return PATHS[name]


def fixed_entry(name: str, key: str = "path") -> PathEntry:
    """The entry of ``name`` if a single run can use it (:func:`fixed_paths`); else
    :class:`~pfjax.errors.InputError` naming ``key`` and listing those paths (an unknown name, or a
    kind built only from a study config: ``random``, ``spline``)."""
    fixed = ", ".join(fixed_paths())
    if name not in PATHS:
        raise errors.InputError(f"{key}: unknown path {name!r}; expected one of {fixed}", key)
    if PATHS[name].build is None:
        raise errors.InputError(f"{key}: {name!r} is built only from a study config; expected one of {fixed}", key)
    return PATHS[name]


def fixed_paths() -> list[str]:
    """Names of the paths a single run can use (those with a builder and a start pose)."""
    return [n for n, e in PATHS.items() if e.build is not None]


def source_tests() -> tuple[str, ...]:
    """The source's test paths, in the source's order (line, parabola, sine)."""
    return tuple(n for n, e in PATHS.items() if e.source)


def _builtin(name: str, build: Callable | None = None, **kw) -> None:
    """Add one of pfjax's own kinds, its arguments checked as :func:`register` checks them but its
    builder not called: calling one would start JAX's runtime on ``import pfjax.paths``
    (tests/test_extension_audit.py checks each as :func:`register` would)."""
    PATHS[name] = _entry(name, build, module=__name__, **kw)


def _register_builtins() -> None:
    from pfjax.paths import shapes

    _builtin(
        "line",
        shapes.line,
        start_pose=(1.0, 0.0, math.pi / 2),
        max_curvature=0.0,
        source=True,
        description="the source's line y = x",
    )
    # y = x^2 peaks at curvature 2a = 2 at the vertex; runs start 2 m before it (x = -2)
    _builtin(
        "parabola",
        shapes.parabola,
        start_pose=(-2.0, 3.0, -math.pi / 2),
        start_u=-2.0,
        max_curvature=2.0,
        source=True,
        description="the source's parabola y = x^2",
    )
    # y = sin x: curvature at most A w^2 = 1
    _builtin(
        "sine",
        shapes.sine,
        start_pose=(0.0, -0.2, math.pi / 4),
        max_curvature=1.0,
        source=True,
        description="the source's sine y = sin x",
    )
    _builtin(
        "circle",
        lambda: shapes.circle(radius=2.0, cy=2.0),
        start_pose=(0.0, -0.3, 0.0),
        parametric=True,
        description="circle about (0, R) from the origin, counter-clockwise (pfjax's; single runs: R = 2 m)",
    )
    # random: 2 m of path behind the start
    _builtin("random", start_u=2.0, parametric=True, description="random smooth spline, one per run")
    _builtin("spline", parametric=True, description="natural cubic spline through the config's points")


_register_builtins()
