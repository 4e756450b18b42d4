"""Study configuration: TOML merged onto typed defaults, ``--set key=value`` overrides, hashing.

A study declares its defaults as a nested dict; the user's TOML and overrides may only use
keys that exist there, with values of the same type (ints are accepted where floats are
expected). Errors are :class:`ConfigError` with one line naming the dotted key, the value
and what was expected (and a "did you mean" for near-miss keys). The merged config's
canonical JSON is hashed (SHA-256) and stamped on every output.
"""

from __future__ import annotations

import copy
import difflib
import re
import tomllib
from collections.abc import Sequence
from pathlib import Path

from pfjax import errors
from pfjax.errors import InputError


class ConfigError(InputError):
    """A configuration error; the message is one line and names the key."""


def _type_name(v) -> str:
    return {
        bool: "a boolean",
        int: "an integer",
        float: "a number",
        str: "a string",
        list: "a list",
        dict: "a table",
    }.get(type(v), type(v).__name__)


def _short(value, limit: int = 60) -> str:
    """``repr(value)``, cut to ``limit`` characters (a 400-digit number stays one readable line)."""
    text = repr(value)
    return text if len(text) <= limit else f"{text[: limit - 15]}... ({len(text)} characters)"


def _check(key: str, value, default):
    if isinstance(default, bool):
        ok = isinstance(value, bool)
    elif isinstance(default, float):
        ok = isinstance(value, (int, float)) and not isinstance(value, bool)
        if ok:
            try:
                value = errors.number(key, value)  # finite, within pfjax's magnitude bounds
            except InputError as e:
                raise ConfigError(str(e)) from None
    elif isinstance(default, int):
        ok = isinstance(value, int) and not isinstance(value, bool)
        if ok and abs(value) > errors.MAX_SEED:
            raise ConfigError(
                f"{key}: expected an integer of magnitude <= 2**63 - 1, got one of {len(str(abs(value)))} digits"
            )
    elif isinstance(default, list):
        ok = isinstance(value, list) and (not default or len(value) == len(default))
        if ok and default:
            value = [_check(f"{key}[{i}]", v, d) for i, (v, d) in enumerate(zip(value, default))]
    else:
        ok = isinstance(value, type(default))
    if not ok:
        extra = f" of length {len(default)}" if isinstance(default, list) and default else ""
        raise ConfigError(f"{key}: expected {_type_name(default)}{extra}, got {_short(value)}")
    return value


def _merge(base: dict, update: dict, prefix: str = "") -> dict:
    out = copy.deepcopy(base)
    for k, v in update.items():
        key = f"{prefix}{k}"
        if k not in base:
            hint = difflib.get_close_matches(k, list(base), n=1)
            raise ConfigError(f"{key}: unknown key" + (f" (did you mean {prefix + hint[0]!r}?)" if hint else ""))
        if isinstance(base[k], dict):
            if not isinstance(v, dict):
                raise ConfigError(f"{key}: expected a table, got {v!r}")
            out[k] = _merge(base[k], v, f"{key}.")
        else:
            out[k] = _check(key, v, base[k])
    return out


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
        value = tomllib.loads(f"v = {raw}")["v"]
    except tomllib.TOMLDecodeError:
        value = raw
    return nested(key, value)


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
    """A UTF-8 text file's contents; ConfigError (one line naming ``key``) if it is missing, not a
    file, unreadable or not UTF-8."""
    p = Path(path)
    if not p.is_file():
        raise ConfigError(f"{key}: file not found: {p}" if not p.exists() else f"{key}: {p} is not a file")
    try:
        return p.read_text(encoding="utf-8")
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


def load(defaults: dict, path: str | Path | None = None, overrides: Sequence[str] = ()) -> dict:
    """Defaults <- TOML file <- ``--set`` overrides, each checked against the defaults."""
    cfg = copy.deepcopy(defaults)
    if path is not None:
        cfg = _merge(cfg, read_toml(path))
    for text in overrides:
        cfg = _merge(cfg, parse_override(text))
    return cfg
