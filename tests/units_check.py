"""Which numbers of a pfjax JSON output have no unit in its ``units`` map (by field name: a
number's own key, or the key of a block above it, as ``quantiles`` or ``gains``)."""

from __future__ import annotations

from collections.abc import Mapping

#: blocks whose numbers are described elsewhere: the config (its schema's descriptions)
SKIP = {"config"}


def numbers_without_units(out: Mapping) -> list[str]:
    """Dotted paths of the numbers in ``out`` (booleans aside) that neither their key nor any key
    above them names in ``out["units"]``."""
    units = out["units"]
    missing: list[str] = []

    def walk(value, path: list[str]) -> None:
        if path and path[-1] in SKIP:
            return
        if isinstance(value, Mapping):
            for k, v in value.items():
                walk(v, path + [str(k)])
        elif isinstance(value, list):
            for v in value:
                walk(v, path)
        elif isinstance(value, (int, float)) and not isinstance(value, bool) and not any(k in units for k in path):
            missing.append(".".join(path))

    walk({k: v for k, v in out.items() if k != "units"}, [])
    return sorted(set(missing))
