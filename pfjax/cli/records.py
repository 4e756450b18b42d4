"""What a command's JSON output records beside its result (``pfjax <command> --json``).

A command that computes a result without a config of its own (``simulate``, ``synth``, ``tune``,
``parking``, ``parking-search``, ``track``) declares the unit of each number it prints
(``set_defaults(units=...)`` on its parser), and prints its result with:

* ``units``: the unit of each number, by its dotted key (``"final.theta": "rad"``; the arguments'
  as ``"arguments.speed": "m/s"``, by the table's ``"arguments.*"``), from that
  table (a key ``"<parent>.*"`` gives the unit of every number under ``<parent>`` by its name, e.g.
  the metrics by :data:`pfjax.tables.COLUMNS`) and the provenance record's (``seed``, ``cpu_settings``:
  :data:`pfjax.provenance.STAMP_UNITS`);
* ``arguments``: every argument the command ran with, defaults filled in (run it again with them);
  a flag the run does not read is null (``pfjax tune``'s GA sizes with the gradient tuner,
  ``--n-runs`` with a paper set), so it does not enter the hash;
* the provenance record of a study's ``summary.json`` (:func:`pfjax.provenance.stamp`): pfjax's
  version, ``config_sha256`` (over ``arguments``: the same arguments, the same hash), the seed where
  the command takes one, the machine and the CPU settings.

Commands with a config of their own (``study``, ``report``, ``rare-event``, ``bench``) carry
their own ``config_sha256``; listings (``examples``) are printed as they are.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

#: The keys :func:`stamped` adds to a result (where the result has no key of that name).
RECORD = ("units", "arguments", "pfjax_version", "config_sha256", "seed", "machine", "cpu_settings")

#: Attributes of the parsed arguments that are the command's machinery, not its input.
_INTERNAL = {"func", "human", "failure", "json", "units", "command"}


def _jsonable(v):
    if isinstance(v, Path):
        return str(v)
    if isinstance(v, (list, tuple)):
        return [_jsonable(x) for x in v]
    return v


def arguments(args) -> dict:
    """The command's arguments (the parsed ``args``, defaults filled in) as a JSON-able dict."""
    return {k: _jsonable(v) for k, v in sorted(vars(args).items()) if k not in _INTERNAL}


def units(out: Mapping, table: Mapping) -> dict[str, str]:
    """``{dotted key: unit}`` for every value of ``out`` (numbers, lists of numbers; a list of
    records by its fields, ``switch_log.t``) whose key ``table`` gives a unit: ``table[key]``, else
    ``table["<parent>.*"][name]``. Text and codes (unit ``""``) are left out."""
    found: dict[str, str] = {}

    def walk(d: Mapping, prefix: str) -> None:
        by_name = table.get(f"{prefix}*", {})
        for name, value in d.items():
            key = f"{prefix}{name}"
            if isinstance(value, Mapping):
                walk(value, f"{key}.")
                continue
            if isinstance(value, list) and value and all(isinstance(v, Mapping) for v in value):
                for item in value:  # a list of records (a log): one unit per field
                    walk(item, f"{key}.")
                continue
            unit = table.get(key, by_name.get(name) if isinstance(by_name, Mapping) else by_name)
            if isinstance(unit, str) and unit and not isinstance(value, str):  # text has no unit
                found[key] = unit

    walk(out, "")
    return found


def stamped(out, args):
    """``out`` with its ``units``, ``arguments`` and provenance (module docstring); unchanged if the
    command declares no units, ``out`` is not a dict or it carries a ``config_sha256`` of its own.
    Keys of ``out`` win over the record's."""
    from pfjax import provenance

    table = getattr(args, "units", None)
    if table is None or not isinstance(out, dict) or "config_sha256" in out:
        return out
    given = arguments(args)
    stamp = provenance.stamp(given, given.get("seed"))
    stamp_units = {k: u for k, u in provenance.STAMP_UNITS.items() if {**stamp, **out}[k] is not None}
    # the arguments' units by the table's "arguments.*" (every number a flag took)
    ran = {k: v for k, v in given.items() if v is not None}  # a flag the run did not read has no unit
    record = {"units": {**stamp_units, **units({**out, "arguments": ran}, table)}, "arguments": given, **stamp}
    return {**out, **{k: v for k, v in record.items() if k not in out}}
