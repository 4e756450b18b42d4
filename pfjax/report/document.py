"""The one report writer: a report is a :class:`Document` of blocks, rendered to Markdown and to HTML.

Every study report is built the same way: the study reads its ``summary.json`` and tables, builds a
:class:`Document` (headings, paragraphs, bullet lists, tables, figures, code), and :func:`write`
renders it to ``report.md`` (GitHub-flavoured Markdown, figures linked from ``figures/``) and
``report.html`` (one self-contained page: inline CSS, figures embedded as base64 PNG). The two files
carry the same text, numbers and figures; only the presentation differs (the HTML adds colour
swatches, cell colours and a section index).

Text in paragraphs, list items and table cells is *inline Markdown*: ``**bold**``, ``*italic*``,
```code```, ``[text](url)`` and ``<sub>``/``<sup>``-free plain text. The HTML renderer escapes
everything else, so a study's text cannot inject markup; the Markdown renderer escapes ``|`` in table
cells (:func:`pfjax.report.markdown.cell`).

    from pfjax.report import document as D

    doc = D.Document("Parking study", "pfjax 0.x, config 1a2b3c", [
        D.Heading("Verdict"),
        D.Paragraph("**Case A** converges in 31.2 s.", style="verdict"),
        D.Table(["case", "time [s]"], [["A", D.Cell("31.2", cls="good")]], caption="Cases"),
        D.Figure("cases", "Trajectories of the four cases"),
    ])
    D.write(doc, out_dir)          # out_dir/report.md and out_dir/report.html
"""

from __future__ import annotations

import base64
import html
import re
from collections.abc import Sequence
from pathlib import Path
from typing import Any, Literal, NamedTuple

from pfjax.report.markdown import cell as md_cell
from pfjax.report.markdown import table as md_table

__all__ = [
    "Bullets",
    "Cell",
    "Code",
    "Document",
    "Figure",
    "Heading",
    "Paragraph",
    "Table",
    "inline_html",
    "to_html",
    "to_markdown",
    "write",
]

Style = Literal["", "verdict", "note", "warning"]


class Heading(NamedTuple):
    """A section heading; level 2 headings make the HTML page's section index."""

    text: str
    level: int = 2
    anchor: str = ""  #: the HTML id (default: from the text)


class Paragraph(NamedTuple):
    """A paragraph of inline Markdown; ``style`` frames it (verdict box, small note, warning box)."""

    text: str
    style: Style = ""


class Bullets(NamedTuple):
    """A bullet list; each item inline Markdown, optionally with a colour swatch (``swatches[i]``)."""

    items: Sequence[str]
    swatches: Sequence[str | None] = ()
    style: Style = ""


class Cell(NamedTuple):
    """A table cell with presentation: ``cls`` one of ``good``, ``warn``, ``bad``, ``total``, ``left``
    (HTML colour/weight), ``swatch`` a CSS colour drawn before the text (HTML only)."""

    text: Any
    cls: str = ""
    swatch: str | None = None


class Table(NamedTuple):
    """A table: a header and rows of cells (plain values or :class:`Cell`); floats are written with
    ``repr``, so format numbers before (``pfjax.report.format``)."""

    header: Sequence[str]
    rows: Sequence[Sequence[Any]]
    caption: str = ""


class Figure(NamedTuple):
    """A figure written beforehand as ``figures/<name>.png`` (and ``.svg``) in the output directory."""

    name: str
    caption: str


class Code(NamedTuple):
    """A preformatted block (a command, a config excerpt)."""

    text: str


Block = Heading | Paragraph | Bullets | Table | Figure | Code


class Document(NamedTuple):
    """A report: a title, a subtitle line (what ran, version, config hash) and its blocks in order."""

    title: str
    subtitle: str
    blocks: Sequence[Block]


# ----------------------------------------------------------------------------------- Markdown


def _cell_value(c):
    return c.text if isinstance(c, Cell) else c


def _block_md(b: Block) -> str:
    if isinstance(b, Heading):
        return f"{'#' * b.level} {b.text}"
    if isinstance(b, Paragraph):
        prefix = {"verdict": "> ", "warning": "> **Warning.** ", "note": "", "": ""}[b.style]
        return prefix + " ".join(b.text.splitlines())
    if isinstance(b, Bullets):
        return "\n".join(f"- {' '.join(str(i).splitlines())}" for i in b.items)
    if isinstance(b, Table):
        text = md_table(b.header, [[_cell_value(c) for c in r] for r in b.rows])
        return (f"**{b.caption}**\n\n" if b.caption else "") + text
    if isinstance(b, Figure):
        return f"![{b.caption}](figures/{b.name}.png)\n\n*{b.caption}* (figures/{b.name}.png, .svg)"
    if isinstance(b, Code):
        return f"```\n{b.text.rstrip()}\n```"
    raise TypeError(f"not a report block: {type(b).__name__}")


def to_markdown(doc: Document) -> str:
    """The report as GitHub-flavoured Markdown (ends with one newline)."""
    parts = [f"# {doc.title}", doc.subtitle] if doc.subtitle else [f"# {doc.title}"]
    parts += [_block_md(b) for b in doc.blocks]
    return "\n\n".join(parts) + "\n"


# --------------------------------------------------------------------------------------- HTML

_INLINE = re.compile(
    r"`(?P<code>[^`]+)`"
    r"|\*\*(?P<bold>[^*]+)\*\*"
    r"|\*(?P<em>[^*\s][^*]*)\*"
    r"|\[(?P<ltext>[^\]]+)\]\((?P<url>[^)\s]+)\)"
)

#: link targets the HTML follows: web and mail addresses, anchors and relative paths
_SAFE_URL = re.compile(r"^(https?://|mailto:|#|(?![A-Za-z][A-Za-z0-9+.-]*:))")


def inline_html(text: Any) -> str:
    """Inline Markdown to escaped HTML: code, bold, italic and links; everything else is text."""
    text = "" if text is None else str(text)
    out, pos = [], 0
    for m in _INLINE.finditer(text):
        out.append(html.escape(text[pos : m.start()]))
        if m["code"] is not None:
            out.append(f"<code>{html.escape(m['code'])}</code>")
        elif m["bold"] is not None:
            out.append(f"<b>{inline_html(m['bold'])}</b>")
        elif m["em"] is not None:
            out.append(f"<i>{inline_html(m['em'])}</i>")
        elif _SAFE_URL.match(m["url"]):
            out.append(f'<a href="{html.escape(m["url"], quote=True)}">{inline_html(m["ltext"])}</a>')
        else:  # a scheme other than http(s)/mailto: shown as text, never followed
            out.append(html.escape(m.group(0)))
        pos = m.end()
    out.append(html.escape(text[pos:]))
    return "".join(out)


def _anchor(h: Heading) -> str:
    return h.anchor or re.sub(r"[^a-z0-9]+", "-", h.text.lower()).strip("-") or "section"


def _swatch(color: str | None) -> str:
    return f'<span class="sw" style="background:{html.escape(color, quote=True)}"></span>' if color else ""


def _td(c, tag: str = "td") -> str:
    if isinstance(c, Cell):
        cls = f' class="{html.escape(c.cls, quote=True)}"' if c.cls else ""
        return f"<{tag}{cls}>{_swatch(c.swatch)}{inline_html(_plain(c.text))}</{tag}>"
    return f"<{tag}>{inline_html(_plain(c))}</{tag}>"


def _plain(value) -> str:
    """A cell value as text, as the Markdown writer shows it (None and non-finite as an em dash)."""
    return md_cell(value).replace("\\|", "|")


def _figure_html(f: Figure, out_dir: Path | None) -> str:
    png = None if out_dir is None else Path(out_dir) / "figures" / f"{f.name}.png"
    if png is not None and png.is_file():
        src = "data:image/png;base64," + base64.b64encode(png.read_bytes()).decode("ascii")
    else:
        src = f"figures/{f.name}.png"
    cap = inline_html(f.caption)
    return (
        f'<figure id="fig-{html.escape(f.name, quote=True)}"><img src="{src}" alt="{html.escape(f.caption)}">'
        f'<figcaption>{cap} <span class="files">(figures/{html.escape(f.name)}.png, .svg)</span></figcaption></figure>'
    )


def _block_html(b: Block, out_dir: Path | None) -> str:
    if isinstance(b, Heading):
        return f'<h{b.level} id="{_anchor(b)}">{inline_html(b.text)}</h{b.level}>'
    if isinstance(b, Paragraph):
        body = "".join(f"<p>{inline_html(line)}</p>" for line in b.text.split("\n\n"))
        return {"verdict": f'<div class="verdict">{body}</div>', "warning": f'<div class="warnbox">{body}</div>'}.get(
            b.style, body.replace("<p>", '<p class="note">') if b.style == "note" else body
        )
    if isinstance(b, Bullets):
        sw = list(b.swatches) + [None] * (len(b.items) - len(b.swatches))
        items = "".join(f"<li>{_swatch(s)}{inline_html(i)}</li>" for i, s in zip(b.items, sw, strict=True))
        return f'<ul class="{b.style}">{items}</ul>' if b.style else f"<ul>{items}</ul>"
    if isinstance(b, Table):
        cap = f"<caption>{inline_html(b.caption)}</caption>" if b.caption else ""
        head = "".join(_td(h, "th") for h in b.header)
        rows = "\n".join("<tr>" + "".join(_td(c) for c in r) + "</tr>" for r in b.rows)
        return f"<table>{cap}<thead><tr>{head}</tr></thead><tbody>\n{rows}\n</tbody></table>"
    if isinstance(b, Figure):
        return _figure_html(b, out_dir)
    if isinstance(b, Code):
        return f"<pre><code>{html.escape(b.text.rstrip())}</code></pre>"
    raise TypeError(f"not a report block: {type(b).__name__}")


_CSS = """
body { font-family: system-ui, -apple-system, "Segoe UI", Roboto, sans-serif; color: #222; margin: 0 auto;
       max-width: 1250px; padding: 0 1.5em 3em; line-height: 1.45; }
h1 { margin-bottom: 0.1em; } h2 { border-bottom: 2px solid #ddd; padding-bottom: 0.2em; margin-top: 2em; }
h3 { margin-bottom: 0.3em; } .sub { color: #666; margin-top: 0; }
nav { font-size: 0.9em; margin: 0.8em 0 1.2em; } nav a { margin-right: 1em; color: #1f5f9f; text-decoration: none; }
.verdict { background: #f4f8fc; border-left: 4px solid #1f77b4; padding: 0.6em 1em; margin: 1em 0; }
.verdict p { margin: 0.4em 0; }
div.warnbox { border-left: 4px solid #9a6700; background: #fff8e1; padding: .3em 1em; margin: 1em 0; }
table { border-collapse: collapse; margin: 0.6em 0 1.2em; font-size: 0.9em; }
caption { text-align: left; font-weight: 600; padding-bottom: 0.3em; }
th, td { border: 1px solid #ddd; padding: 0.25em 0.6em; text-align: right; vertical-align: top; }
th { background: #f2f2f2; } td:first-child, th:first-child { text-align: left; }
td.total { font-weight: 600; } td.left { text-align: left; }
td.good { color: #1a7f37; } td.warn { color: #9a6700; } td.bad { color: #c62828; font-weight: 600; }
.sw { display: inline-block; width: 0.8em; height: 0.8em; border-radius: 2px; margin-right: 0.4em; vertical-align: -0.05em; }
figure { margin: 1em 0 1.6em; } figure img { max-width: 100%; height: auto; border: 1px solid #eee; }
figcaption { font-size: 0.88em; color: #444; } .files { color: #888; }
.note { font-size: 0.88em; color: #555; }
code { background: #f5f5f5; padding: 0 0.25em; border-radius: 3px; word-break: break-all; }
pre { background: #f5f5f5; padding: 0.6em 1em; overflow-x: auto; } pre code { background: none; padding: 0; }
"""


def to_html(doc: Document, out_dir: str | Path | None = None) -> str:
    """The report as one self-contained HTML page; figures found under ``out_dir/figures/`` are
    embedded as base64 PNG (otherwise linked)."""
    base = None if out_dir is None else Path(out_dir)
    nav = "".join(
        f'<a href="#{_anchor(b)}">{inline_html(b.text)}</a>'
        for b in doc.blocks
        if isinstance(b, Heading) and b.level == 2
    )
    body = "\n".join(_block_html(b, base) for b in doc.blocks)
    return (
        '<!DOCTYPE html>\n<html lang="en">\n<head>\n<meta charset="utf-8">\n'
        '<meta name="viewport" content="width=device-width, initial-scale=1">\n'
        f"<title>{html.escape(doc.title)}</title>\n<style>{_CSS}</style>\n</head>\n<body>\n"
        f"<h1>{inline_html(doc.title)}</h1>\n"
        + (f'<p class="sub">{inline_html(doc.subtitle)}</p>\n' if doc.subtitle else "")
        + (f"<nav>{nav}</nav>\n" if nav else "")
        + body
        + "\n</body>\n</html>\n"
    )


def write(doc: Document, out_dir: str | Path, formats: Sequence[str] = ("md", "html")) -> list[Path]:
    """Write ``out_dir/report.md`` and/or ``out_dir/report.html`` (UTF-8); returns the paths written.

    ``out_dir`` is the study's output (or staging) directory, which pfjax owns
    (:class:`pfjax.outputs.OutputDir`); figures must already be under ``out_dir/figures/``.
    """
    out = Path(out_dir)
    written = []
    for fmt in formats:
        if fmt not in ("md", "html"):
            raise ValueError(f"formats: expected 'md' or 'html', got {fmt!r}")
        path = out / f"report.{fmt}"
        path.write_text(to_markdown(doc) if fmt == "md" else to_html(doc, out), encoding="utf-8")
        written.append(path)
    return written
