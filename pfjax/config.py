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
import hashlib
import json
import math
import tomllib
from pathlib import Path


class ConfigError(ValueError):
    """A configuration error; the message is one line and names the key."""


def _type_name(v) -> str:
    return {bool: "a boolean", int: "an integer", float: "a number", str: "a string", list: "a list", dict: "a table"}.get(
        type(v), type(v).__name__
    )


def _check(key: str, value, default):
    if isinstance(default, bool):
        ok = isinstance(value, bool)
    elif isinstance(default, float):
        ok = isinstance(value, (int, float)) and not isinstance(value, bool)
        if ok:
            value = float(value)
            if not math.isfinite(value):
                raise ConfigError(f"{key}: expected a finite number, got {value}")
    elif isinstance(default, int):
        ok = isinstance(value, int) and not isinstance(value, bool)
    elif isinstance(default, list):
        ok = isinstance(value, list) and (not default or len(value) == len(default))
        if ok and default:
            value = [_check(f"{key}[{i}]", v, d) for i, (v, d) in enumerate(zip(value, default))]
    else:
        ok = isinstance(value, type(default))
    if not ok:
        extra = f" of length {len(default)}" if isinstance(default, list) and default else ""
        raise ConfigError(f"{key}: expected {_type_name(default)}{extra}, got {value!r}")
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


def parse_override(text: str) -> dict:
    """``"a.b=3"`` -> ``{"a": {"b": 3}}``; the value is parsed as TOML (bare words as strings)."""
    if "=" not in text:
        raise ConfigError(f"--set: expected key=value, got {text!r}")
    key, raw = (s.strip() for s in text.split("=", 1))
    if not key:
        raise ConfigError(f"--set: empty key in {text!r}")
    try:
        value = tomllib.loads(f"v = {raw}")["v"]
    except tomllib.TOMLDecodeError:
        value = raw
    out: dict = {}
    node = out
    parts = key.split(".")
    for p in parts[:-1]:
        node = node.setdefault(p, {})
    node[parts[-1]] = value
    return out


def read_toml(path: str | Path) -> dict:
    """A TOML file as a dict; ConfigError (one line) if it is missing or not valid TOML."""
    p = Path(path)
    if not p.is_file():
        raise ConfigError(f"config: file not found: {p}")
    try:
        return tomllib.loads(p.read_text())
    except tomllib.TOMLDecodeError as e:
        raise ConfigError(f"config: {p}: invalid TOML ({e})") from None


def load(defaults: dict, path: str | Path | None = None, overrides: list[str] = ()) -> dict:
    """Defaults <- TOML file <- ``--set`` overrides, each checked against the defaults."""
    cfg = copy.deepcopy(defaults)
    if path is not None:
        cfg = _merge(cfg, read_toml(path))
    for text in overrides:
        cfg = _merge(cfg, parse_override(text))
    return cfg


def config_hash(cfg: dict) -> str:
    """SHA-256 of the canonical JSON of ``cfg``."""
    return hashlib.sha256(json.dumps(cfg, sort_keys=True, separators=(",", ":")).encode()).hexdigest()
