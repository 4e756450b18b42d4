"""pfjax.report.document: the one report writer (Markdown and self-contained HTML from the same blocks)."""

from __future__ import annotations

import base64
import html
import re

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

from pfjax.report import document as D
from pfjax.report.markdown import split_row


def _doc():
    return D.Document(
        "Study <x>",
        "pfjax, config `abc123`",
        [
            D.Heading("Verdict"),
            D.Paragraph("**PI** succeeds in 99.5 % of runs; |d| < 3 mm.", style="verdict"),
            D.Bullets(["first *item*", "see [the docs](https://example.org/a_b)"], swatches=["#1f77b4"]),
            D.Heading("Numbers", 3),
            D.Table(["controller", "rate | %"], [["pi", D.Cell("99.5", cls="good", swatch="#f00")], ["a|b", None]]),
            D.Figure("fig1", "A figure"),
            D.Code("pfjax study x.toml"),
        ],
    )


def test_markdown_carries_every_block_and_escapes_pipes():
    md = D.to_markdown(_doc())
    assert md.startswith("# Study <x>\n\npfjax, config `abc123`\n\n## Verdict\n\n> **PI** succeeds")
    rows = [line for line in md.splitlines() if line.startswith("|")]
    assert split_row(rows[0]) == ["controller", "rate | %"]
    assert split_row(rows[2]) == ["pi", "99.5"]
    assert split_row(rows[3]) == ["a|b", "—"]  # the pipe stays inside its cell; None is a dash
    assert "![A figure](figures/fig1.png)" in md
    assert "```\npfjax study x.toml\n```" in md
    assert "- first *item*\n- see [the docs](https://example.org/a_b)" in md


def test_html_is_escaped_self_contained_and_has_the_same_text(tmp_path):
    (tmp_path / "figures").mkdir()
    fig, ax = plt.subplots(figsize=(1, 1))
    ax.plot([0, 1])
    fig.savefig(tmp_path / "figures" / "fig1.png")
    plt.close(fig)
    paths = D.write(_doc(), tmp_path)
    assert [p.name for p in paths] == ["report.md", "report.html"]
    page = (tmp_path / "report.html").read_text()
    assert "<title>Study &lt;x&gt;</title>" in page and "<x>" not in page  # escaped, never markup
    png = base64.b64encode((tmp_path / "figures" / "fig1.png").read_bytes()).decode()
    assert f"data:image/png;base64,{png}" in page  # embedded: the page stands alone
    assert '<nav><a href="#verdict">Verdict</a></nav>' in page  # level-2 headings only
    assert '<div class="verdict"><p><b>PI</b> succeeds in 99.5 % of runs; |d| &lt; 3 mm.</p></div>' in page
    assert '<td class="good"><span class="sw" style="background:#f00"></span>99.5</td>' in page
    assert '<a href="https://example.org/a_b">the docs</a>' in page
    # every table cell's text of the Markdown appears, unescaped, in the HTML
    text = html.unescape(re.sub(r"<[^>]+>", " ", page))
    for cell in ("rate | %", "a|b", "—", "pfjax study x.toml", "first item"):
        assert cell in " ".join(text.split()), cell


def test_figures_not_written_are_linked_not_embedded(tmp_path):
    page = D.to_html(_doc(), tmp_path)
    assert '<img src="figures/fig1.png"' in page


def test_inline_markdown_cannot_inject_markup():
    assert D.inline_html("<script>alert(1)</script> **b<i>**") == (
        "&lt;script&gt;alert(1)&lt;/script&gt; <b>b&lt;i&gt;</b>"
    )
    assert D.inline_html("[x](javascript:alert(1))") == "[x](javascript:alert(1))"
    assert D.inline_html('[x](figures/a"b.svg)') == '<a href="figures/a&quot;b.svg">x</a>'
    assert D.inline_html("`a*b*c`") == "<code>a*b*c</code>"
