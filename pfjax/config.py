"""The configuration schema family: every config pfjax reads is a pydantic model validated the same way.

A config is a TOML file (or a dict) validated by a :class:`ConfigModel` subclass (unknown keys,
wrong types and out-of-range values refused), with ``--set key=value`` overrides (the value parsed as
TOML; list items written ``name[index]``). :func:`load_model` reads, overrides and validates; its errors
are :class:`ConfigError` with one line naming the dotted key, the value and what was expected (and a
"did you mean" for near-miss keys). The validated config's canonical JSON is hashed (SHA-256,
:func:`pfjax.provenance.config_hash`) and stamped on every output.

The Monte Carlo study (:class:`pfjax.montecarlo.config.StudySpec`) and the study scripts' configs
(paper reproduction, tuning, parking, vehicle tracking, kinematic versus dynamic) are members of the
family: the same loader, the same override syntax, the same errors.
"""

from __future__ import annotations

import copy
import difflib
import math
import re
import tomllib
from collections.abc import Sequence
from pathlib import Path
from typing import Annotated, Any, ClassVar, TypeVar

from pydantic import AfterValidator, BaseModel, ConfigDict, ValidationError, model_validator

from pfjax import errors
from pfjax.errors import MAX_MAGNITUDE, MIN_POSITIVE, InputError


class ConfigError(InputError):
    """A configuration error; the message is one line and names the key."""


def _short(value, limit: int = 60) -> str:
    """``repr(value)``, cut to ``limit`` characters (a 400-digit number stays one readable line)."""
    text = repr(value)
    return text if len(text) <= limit else f"{text[: limit - 15]}... ({len(text)} characters)"


#: One part of a ``--set`` key: a name, optionally a list index (``controllers[0]``).
KEY_PART = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*(\[-?[0-9]{1,9}\])?$")


def parse_override(text: str) -> dict:
    """``"a.b=3"`` -> ``{"a": {"b": 3}}``; the value is parsed as TOML (bare words as strings).
    Keys are dotted names, list items written ``name[index]`` (``controllers[0].gains.k``)."""
    if not isinstance(text, str) or "=" not in text:
        raise ConfigError(f"--set: expected key=value, got {text!r}")
    key, raw = (s.strip() for s in text.split("=", 1))
    if not key:
        raise ConfigError(f"--set: empty key in {text!r}")
    bad = next((p for p in key.split(".") if not KEY_PART.match(p)), None)
    if bad is not None:
        raise ConfigError(f"--set: malformed key {key!r} at {bad!r} (expected dotted names, list items as name[0])")
    try:
        parsed = tomllib.loads(f"v = {raw}")
    except tomllib.TOMLDecodeError:
        parsed = {"v": raw}
    except RecursionError:
        raise ConfigError(f"--set: {key}: the value is nested too deeply") from None
    if set(parsed) != {"v"}:  # "16\nseed=5" would set a second key unseen
        raise ConfigError(f"--set: {key}: expected one value, got {raw!r}")
    return nested(key, parsed["v"])


def nested(key: str, value) -> dict:
    """``("a.b", 3)`` -> ``{"a": {"b": 3}}`` (list items written ``name[index]``); ConfigError for a
    malformed key."""
    bad = next((p for p in key.split(".") if not KEY_PART.match(p)), None)
    if not key or bad is not None:
        raise ConfigError(f"{key}: malformed key (expected dotted names, list items as name[0])")
    out: dict = {}
    node = out
    parts = key.split(".")
    for p in parts[:-1]:
        node = node.setdefault(p, {})
    node[parts[-1]] = value
    return out


def read_text(path: str | Path, key: str = "config") -> str:
    """A UTF-8 text file's contents (a leading byte-order mark, which some editors write, dropped);
    ConfigError (one line naming ``key``) if it is missing, not a file, unreadable or not UTF-8."""
    p = Path(path)
    if not p.is_file():
        raise ConfigError(f"{key}: file not found: {p}" if not p.exists() else f"{key}: {p} is not a file")
    try:
        return p.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError as e:
        raise ConfigError(f"{key}: {p} is not UTF-8 text (byte {e.start}: {e.reason})") from None
    except OSError as e:
        raise ConfigError(f"{key}: {p} cannot be read ({e.strerror})") from None


def read_toml(path: str | Path, key: str = "config") -> dict:
    """A TOML file as a dict; ConfigError (one line) if it is missing, unreadable, not UTF-8 or not
    valid TOML."""
    text = read_text(path, key)
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise ConfigError(f"{key}: {path}: invalid TOML ({e})") from None
    except RecursionError:
        raise ConfigError(f"{key}: {path}: invalid TOML (nested too deeply)") from None


# ------------------------------------------------------------------------------ the schema family


def _real(v: float) -> float:
    if not math.isfinite(v):
        raise ValueError(f"expected a finite number, got {v}")
    if abs(v) > MAX_MAGNITUDE:
        raise ValueError(f"expected a magnitude <= {MAX_MAGNITUDE:g}, got {v:g}")
    return v


#: A number as every config key takes it: finite, magnitude at most :data:`pfjax.errors.MAX_MAGNITUDE`
#: (booleans and strings are not numbers: the schema is strict).
Real = Annotated[float, AfterValidator(_real)]
#: A positive step, length or tolerance: at least :data:`pfjax.errors.MIN_POSITIVE`.
POSITIVE = MIN_POSITIVE


def _label(v: str) -> str:
    if not v.strip():
        raise ValueError(f"expected a name shown in tables and reports, got {v!r}")
    if len(v) > 100 or any(ord(c) < 32 or ord(c) == 127 for c in v):
        raise ValueError(f"expected one line of at most 100 characters (a label in tables and reports), got {v[:40]!r}")
    return v


#: A label in outputs (a controller's or a path's name): not blank, one line, at most 100 characters.
Label = Annotated[str, AfterValidator(_label)]


class ConfigModel(BaseModel):
    """Base of every config model: unknown keys refused, values immutable, types strict (an integer
    is accepted where a number is expected, nothing else converts)."""

    model_config = ConfigDict(extra="forbid", frozen=True, strict=True)
    #: old key -> new key: an old spelling is read for one release, with a deprecation warning
    RENAMED: ClassVar[dict[str, str]] = {}

    @model_validator(mode="before")
    @classmethod
    def _renamed(cls, data):
        if cls.RENAMED and isinstance(data, dict) and any(k in data for k in cls.RENAMED):
            data = dict(data)
            for old, new in cls.RENAMED.items():
                if old in data:
                    if new in data:
                        raise ValueError(f"{old}: the old name of {new}; give only {new}")
                    errors.deprecated(old, new)
                    data[new] = data.pop(old)
        return data


M = TypeVar("M", bound=BaseModel)

#: union members pydantic names in an error's location (a distribution's tag): not part of the key
_TAGS = ("constant", "uniform", "normal", "truncnormal", "choice", "function-after[_check(), Dist]")


def _loc(loc) -> str:
    out = ""
    for part in loc:
        if isinstance(part, int):
            out += f"[{part}]"
        elif part in _TAGS:
            continue
        else:
            out += ("." if out else "") + str(part)
    return out


def _model_at(root: type[BaseModel], loc) -> type[BaseModel] | None:
    model: Any = root
    for part in loc:
        if isinstance(part, int):
            continue
        field = getattr(model, "model_fields", {}).get(part)
        if field is None:
            return model
        ann = field.annotation
        args = getattr(ann, "__args__", ())
        nxt = next((a for a in (ann, *args) if isinstance(a, type) and issubclass(a, BaseModel)), None)
        if nxt is None:
            return model
        model = nxt
    return model


_BOUNDS = {
    "greater_than": (">", "gt"),
    "greater_than_equal": (">=", "ge"),
    "less_than": ("<", "lt"),
    "less_than_equal": ("<=", "le"),
}


def format_error(err: ValidationError, root: type[BaseModel]) -> str:
    """The first error of a validation of ``root`` as one line: ``dotted.key: what was wrong (got value)``."""
    e = err.errors()[0]
    loc = [p for p in e["loc"] if not (isinstance(p, str) and ("[" in p or p in _TAGS))]
    key = _loc(loc) or "config"
    if e["type"] == "extra_forbidden":
        parent = _model_at(root, loc[:-1])
        names = list(getattr(parent, "model_fields", {}))
        hint = difflib.get_close_matches(str(loc[-1]), names, n=1)
        prefix = _loc(loc[:-1])
        sug = f" (did you mean '{(prefix + '.') if prefix else ''}{hint[0]}'?)" if hint else ""
        return f"{key}: unknown key{sug}"
    msg = e["msg"].removeprefix("Value error, ")
    # model-level checks name their field first ("speed: must be ..."): join it to the key
    head, sep, rest = msg.partition(": ")
    if e["type"] == "value_error" and sep and " " not in head and "'" not in head:
        key = head if key == "config" else f"{key}{'' if head.startswith('[') else '.'}{head}"
        msg = rest
    if e["type"] == "missing":
        return f"{key}: required key is missing"
    bound = _BOUNDS.get(e["type"])
    value = e.get("input")
    if bound is not None and isinstance(value, float) and math.isnan(value):  # NaN fails every bound
        return f"{key}: expected a finite number, got nan"
    if bound is not None:  # pydantic writes 1e-12 as 0.000000000001
        limit = e["ctx"][bound[1]]
        msg = f"must be {bound[0]} {limit:g}" if isinstance(limit, float) else f"must be {bound[0]} {limit}"
        if bound[0] == ">=" and limit == POSITIVE and isinstance(value, (int, float)) and value <= 0:
            msg = "must be > 0"  # a positive setting, as errors.number words it (at least 1e-12 above 0)
    return f"{key}: {msg} (got {_short(e.get('input'))})" if e["type"] != "value_error" else f"{key}: {msg}"


def field_limits(model: type[BaseModel], name: str) -> dict[str, float]:
    """The bounds a config model puts on its field ``name``, by their pydantic names (``ge``, ``gt``,
    ``le``, ``lt``; those it has): a function that takes the same setting as an argument checks it
    against these, not against a copy of them."""
    out: dict[str, float] = {}
    for m in model.model_fields[name].metadata:
        for bound in ("ge", "gt", "le", "lt"):
            if getattr(m, bound, None) is not None:
                out[bound] = getattr(m, bound)
    return out


def set_nested(d: dict, update: dict, prefix: str = "") -> dict:
    """Apply a nested override to a raw config dict in place (a distribution table replaces the old
    one whole; ``name[i]`` keys address list items); ConfigError for a missing list element, naming
    the whole dotted key (``prefix``: the keys above ``d``)."""
    for k, v in update.items():
        if "[" in k:  # controllers[0].gains.k style
            name, idx = k.split("[", 1)
            i = int(idx.rstrip("]"))
            lst = d.get(name)
            if not isinstance(lst, list) or not -len(lst) <= i < len(lst):
                key = f"{prefix}{k}"
                raise ConfigError(
                    f"{key}: no such list element" if isinstance(lst, list) else f"{key}: {prefix}{name} is not a list"
                )
            if isinstance(v, dict) and "dist" not in v and isinstance(lst[i], dict):
                set_nested(lst[i], v, f"{prefix}{k}.")
            else:
                lst[i] = v
        elif isinstance(v, dict) and "dist" in v:  # a new distribution replaces the old one whole
            d[k] = v
        elif isinstance(v, dict) and isinstance(d.get(k), dict):
            set_nested(d[k], v, f"{prefix}{k}.")
        else:
            d[k] = v
    return d


def plain(value):
    """``value`` with NumPy and JAX values as Python's, through dicts, lists and tuples: a NumPy
    scalar or a 0-d NumPy or JAX array as its Python ``int``, ``float``, ``bool`` (or ``complex``,
    ``str``, ``bytes``), a 1-D array as a list of them. Anything else is returned as it is. The
    schema judges the result as it judges Python values (a boolean stays a boolean, refused where
    a number is expected; a 2-D array is not a list)."""
    import sys

    import numpy as np

    if isinstance(value, dict):
        return {k: plain(v) for k, v in value.items()}
    if isinstance(value, list):
        return [plain(v) for v in value]
    if isinstance(value, tuple):
        return tuple(plain(v) for v in value)
    jax = sys.modules.get("jax")  # a JAX array exists only once JAX is imported
    if jax is not None and isinstance(value, jax.Array):
        if isinstance(value, jax.core.Tracer):  # no numbers yet (inside jit, grad or vmap)
            return value
        value = np.asarray(value)
    if isinstance(value, (np.ndarray, np.generic)) and value.ndim <= 1 and value.dtype.kind in "biufcSU":
        return value.tolist()
    return value


def load_model(
    model: type[M],
    path: str | Path | None = None,
    overrides: Sequence[str] = (),
    data: dict | None = None,
    values: dict | None = None,
    presets: Sequence[dict] = (),
) -> tuple[M, dict]:
    """Read, override and validate a config of schema ``model``. Returns ``(config, raw_dict)``;
    raises :class:`ConfigError` (one line naming the key).

    Args:
        model: the schema (a :class:`ConfigModel` subclass).
        path: a TOML file (else ``data``, a dict; else the schema's defaults).
        overrides: ``--set`` texts ``"key=value"`` (the value parsed as TOML), applied in order.
        data: the raw config as a dict, when there is no file.
        values: overrides as Python values by dotted key (``{"sim.horizon": 30}``), applied last.
            In ``data`` and ``values``, NumPy and JAX numbers and 1-D arrays are read as Python's
            (:func:`plain`).
        presets: nested dicts applied between the file and the overrides (a study's ``--quick`` sizes).
    """
    try:  # a Python value nested deeper than the interpreter's recursion limit: one line naming it
        raw: dict = {} if data is None else copy.deepcopy(plain(dict(data)))
    except RecursionError:
        raise ConfigError("config: the value is nested too deeply") from None
    if path is not None:
        raw = read_toml(path)
    for preset in presets:
        set_nested(raw, copy.deepcopy(preset))
    for text in overrides:
        set_nested(raw, parse_override(text))
    for key, value in (values or {}).items():
        try:
            set_nested(raw, nested(key, plain(value)))
        except RecursionError:
            raise ConfigError(f"{key}: the value is nested too deeply") from None
    try:
        config = model.model_validate(raw)
    except ValidationError as e:
        raise ConfigError(format_error(e, model)) from None
    except RecursionError:
        raise ConfigError("config: the value is nested too deeply") from None
    return config, raw
