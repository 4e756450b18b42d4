"""MkDocs hooks: tables generated from the code at build time, so the docs cannot drift from it.

- ``<!-- config-reference -->``: every key of a study config (:class:`pfjax.montecarlo.config.StudySpec`)
  with its default and its description (units included), read from the pydantic schema;
  ``<!-- paper-config-reference -->`` and ``<!-- tracking-config-reference -->`` the same for the
  paper-reproduction and vehicle-tracking studies (:class:`pfjax.reproduce.paper_config.PaperStudy`,
  :class:`pfjax.tracking.study_config.TrackingStudy`);
- ``<!-- parking-config-reference -->``: the same for the parking study
  (:class:`pfjax.parking.study_config.ParkingStudy`); ``<!-- dynamic-study-config-reference -->`` for
  the kinematic-vs-dynamic study (:class:`pfjax.dynamic_study.config.KinematicVsDynamic`);
- ``<!-- tuning-config-reference -->``: the same for the tuning study
  (:class:`pfjax.tuning.study_config.TuningStudy`);
- ``<!-- column-reference -->``: every column of the run and margin tables with its unit and meaning
  (:data:`pfjax.tables.COLUMNS`, the same metadata the Parquet files carry);
- ``<!-- controller-reference -->`` and ``<!-- path-reference -->``: the registries.

The docstrings cross-reference in Sphinx's roles (``:func:`simulate```), which the API reference's
renderer shows as written; :func:`on_page_content` turns each into a link to the object where the
site documents it, else into plain code.
"""

from __future__ import annotations

import bisect
import html
import re
import typing


def _default(field) -> str:
    from pydantic_core import PydanticUndefined

    if field.default is PydanticUndefined and field.default_factory is None:
        return "required"
    value = field.get_default(call_default_factory=True)
    if hasattr(value, "dist"):  # a distribution: its constant value
        return f"`{value.value:g}`" if value.dist == "constant" else f"`{value.dist}`"
    if isinstance(value, list):
        return "`[" + ", ".join(f"{v:g}" if isinstance(v, float) else str(v) for v in value) + "]`" if value else "`[]`"
    if isinstance(value, dict):
        return "a table (see meaning)" if value else "`{}`"
    if isinstance(value, float):
        return f"`{value:g}`"
    return "none" if value is None else f"`{value}`"


def _rows(model, prefix=""):
    from pydantic import BaseModel

    for name, f in model.model_fields.items():
        sub = next(
            (
                a
                for a in (f.annotation, *typing.get_args(f.annotation))
                if isinstance(a, type) and issubclass(a, BaseModel) and a.__name__ != "Dist"
            ),
            None,
        )
        key = prefix + name
        if sub is not None:
            if typing.get_origin(f.annotation) is list:
                key += "[i]"
            yield from _rows(sub, key + ".")
        else:
            dist = " (a number or a distribution)" if "Dist" in str(f.annotation) else ""
            yield key, _default(f), (f.description or "") + dist


def _key_table(model) -> str:
    lines = ["| key | default | meaning and unit |", "|---|---|---|"]
    lines += [f"| `{k}` | {d} | {m.replace('|', '&#124;')} |" for k, d, m in _rows(model)]
    return "\n".join(lines)


def config_reference() -> str:
    from pfjax.montecarlo.config import StudySpec

    return _key_table(StudySpec)


def paper_config_reference() -> str:
    from pfjax.reproduce.paper_config import PaperStudy

    return _key_table(PaperStudy)


def tracking_config_reference() -> str:
    from pfjax.tracking.study_config import TrackingStudy

    return _key_table(TrackingStudy)


def parking_config_reference() -> str:
    from pfjax.parking.study_config import ParkingStudy

    return _key_table(ParkingStudy)


def dynamic_study_config_reference() -> str:
    from pfjax.dynamic_study.config import KinematicVsDynamic

    return _key_table(KinematicVsDynamic)


def tuning_config_reference() -> str:
    from pfjax.tuning.study_config import TuningStudy

    return _key_table(TuningStudy)


def column_reference() -> str:
    from pfjax.tables import COLUMNS

    lines = ["| column | unit | meaning |", "|---|---|---|"]
    lines += [f"| `{c}` | {u or '—'} | {d.replace('|', '&#124;')} |" for c, (u, d) in COLUMNS.items()]
    return "\n".join(lines)


def controller_reference() -> str:
    from pfjax import controllers as C

    lines = ["| name | command line | gains (`--gains` order) | tuning box |", "|---|---|---|---|"]
    for n, e in C.REGISTRY.items():
        box = "—" if e.box is None else ", ".join(f"{f}" for f in e.box[0])
        lines.append(f"| `{n}` | `{e.cli_name}` | {', '.join(e.gains)} | {box} |")
    for n, d in C.DESIGNS.items():
        lines.append(f"| `{n}` (design) | `{d.cli_name}` | those of `{d.controller}` | — |")
    return "\n".join(lines)


def path_reference() -> str:
    from pfjax import paths

    lines = ["| kind | single-run start (x m, y m, θ rad) | max curvature, 1/m | description |", "|---|---|---|---|"]
    for n, e in paths.PATHS.items():
        start = "—" if e.start_pose is None else ", ".join(f"{v:.4g}" for v in e.start_pose)
        kmax = "from the config" if e.max_curvature is None else f"{e.max_curvature:g}"
        lines.append(f"| `{n}` | {start} | {kmax} | {e.description} |")
    return "\n".join(lines)


MARKERS = {
    "<!-- config-reference -->": config_reference,
    "<!-- parking-config-reference -->": parking_config_reference,
    "<!-- dynamic-study-config-reference -->": dynamic_study_config_reference,
    "<!-- tuning-config-reference -->": tuning_config_reference,
    "<!-- column-reference -->": column_reference,
    "<!-- paper-config-reference -->": paper_config_reference,
    "<!-- tracking-config-reference -->": tracking_config_reference,
    "<!-- controller-reference -->": controller_reference,
    "<!-- path-reference -->": path_reference,
}


def on_page_markdown(markdown: str, **kwargs) -> str:
    for marker, make in MARKERS.items():
        if marker in markdown:
            markdown = markdown.replace(marker, make())
    return markdown


#: A Sphinx role as the Markdown of a docstring renders it: ``:func:<code>~pfjax.simulate</code>``.
ROLE = re.compile(r":(?:func|class|mod|data|meth|attr|exc|obj):<code>(~?)([A-Za-z_][\w.]*)(\(\))?</code>")
#: An object's anchor on an API page (mkdocstrings: ``id="pfjax.api.simulate"``).
ANCHOR = re.compile(r'id="(pfjax[\w.]*)"')


def _target(name: str, context: str, ids: set[str]) -> str:
    """The anchor on this page that ``name`` (as a docstring writes it) means: itself, or the name
    relative to the documented object it appears in (``context``) or to one of its parents, or a
    name exported by ``pfjax`` at its home in ``pfjax.api``; else ``name`` (another page may have it)."""
    if name in ids:
        return name
    parts = context.split(".")
    for k in range(len(parts), 0, -1):
        candidate = ".".join(parts[:k]) + "." + name
        if candidate in ids:
            return candidate
    if name.startswith("pfjax.") and "pfjax.api." + name[6:] in ids:
        return "pfjax.api." + name[6:]
    return name


def on_page_content(content: str, **kwargs) -> str:
    """Each role as mkdocs-autorefs' optional reference (:func:`_target`): a link where the site
    documents the object, else plain code; ``~`` shows the name's last part."""
    anchors = [(m.start(), m.group(1)) for m in ANCHOR.finditer(content)]
    starts = [a for a, _ in anchors]
    ids = {name for _, name in anchors}

    def autoref(match: re.Match) -> str:
        tilde, name, call = match.groups()
        i = bisect.bisect_right(starts, match.start()) - 1
        target = _target(name, anchors[i][1] if i >= 0 else "", ids)
        shown = html.escape((name.rsplit(".", 1)[-1] if tilde else name) + (call or ""))
        return f'<autoref identifier="{html.escape(target)}" optional><code>{shown}</code></autoref>'

    return ROLE.sub(autoref, content)
