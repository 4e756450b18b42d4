"""Every notebook in notebooks/ runs top to bottom without a cell error.

Each notebook is executed in a fresh ``python3`` kernel with the notebooks directory as its working
directory; the executed copy stays in memory (nothing is written back to disk). New notebooks are
picked up by the glob. Each notebook is stored without outputs and starts with a parameters cell
(tagged ``parameters``, for papermill) holding the sizes it uses. Every figure a notebook shows is
checked as it is shown (:func:`figure_problems`): labelled axes, every line named in a legend in
view at its end, every filled contour computed over the whole view.
"""

import inspect
from pathlib import Path

import pytest

nbformat = pytest.importorskip("nbformat")
nbclient = pytest.importorskip("nbclient")

NB_DIR = Path(__file__).resolve().parents[1] / "notebooks"
NOTEBOOKS = sorted(NB_DIR.glob("*.ipynb"))
CELL_TIMEOUT_S = 600


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.name for p in NOTEBOOKS])
def test_notebook_is_valid_with_unique_cell_ids(path: Path):
    """nbformat 4.5 or later, every cell with its own id, and valid against nbformat's schema. A
    missing id is only a warning in today's nbformat (it adds one on reading), a hard error in a
    later one."""
    import json
    import warnings

    raw = json.loads(path.read_text())
    assert (raw["nbformat"], raw["nbformat_minor"]) >= (4, 5), path.name
    ids = [c.get("id") for c in raw["cells"]]
    assert None not in ids, f"{path.name}: cell {ids.index(None)} has no id"
    assert len(set(ids)) == len(ids), f"{path.name}: repeated cell ids"
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        nbformat.validate(nbformat.reads(path.read_text(), as_version=4))


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.name for p in NOTEBOOKS])
def test_notebook_layout(path: Path):
    """Stored without outputs; the first code cell is the parameters cell (tagged ``parameters`` for
    papermill: plain assignments, after a markdown cell saying how to run bigger); the next one
    imports pfjax before anything else; no cell turns the compilation cache on by hand
    (``import pfjax`` does) or reaches for a private pfjax name."""
    import re

    nb = nbformat.read(path, as_version=4)
    code = [i for i, c in enumerate(nb.cells) if c.cell_type == "code"]
    for i in code:
        assert not nb.cells[i].outputs and nb.cells[i].execution_count is None, f"{path.name}: cell {i} has outputs"
    params = nb.cells[code[0]]
    assert "parameters" in params.metadata.get("tags", []), f"{path.name}: the first code cell is not tagged parameters"
    assert code[0] > 0 and nb.cells[code[0] - 1].cell_type == "markdown", (
        f"{path.name}: no markdown before the parameters"
    )
    assert not re.search(r"^\s*(import|from) ", params.source, re.M), f"{path.name}: the parameters cell imports"
    setup = [ln for ln in nb.cells[code[1]].source.splitlines() if ln.startswith(("import ", "from "))]
    assert setup and re.match(r"import pfjax\b", setup[0]), f"{path.name}: pfjax is not imported first"
    src = "\n".join(nb.cells[i].source for i in code)
    assert "pfjax.cache" not in src, f"{path.name}: pfjax.cache (import pfjax enables the cache)"
    src = re.sub(r"#[^\n]*", "", src)  # comments (a "#" in a string only hides code from the check)
    private = re.findall(r"from pfjax[\w.]* import (?:\([^)]*|[^\n]*)\b_(?!_)\w+|\bpfjax(?:\.\w+)*\._(?!_)\w+", src)
    assert not private, f"{path.name}: private pfjax names {private}"


def figure_problems(fig) -> list[str]:
    """What makes a figure wrong or unreadable, one line each (empty: none found).

    - an axes that shows data without an x or a y label (the label says the quantity and its unit;
      an axis shared with a labelled one, an axis whose ticks are named (categories), an inset and
      a colour bar need none);
    - a line named in the legend whose last point lies outside the view: the reader looks for it
      and finds its end clipped (a start clipped to zoom on the steady state is fine);
    - a filled contour whose grid does not cover the view: part of the view is shaded as if the
      field were zero there.
    """
    import numpy as np
    from matplotlib.contour import ContourSet

    problems = []
    insets = {child for ax in fig.axes for child in ax.child_axes}
    title = fig.get_suptitle() if hasattr(fig, "get_suptitle") else ""
    for i, ax in enumerate(fig.axes):
        if ax in insets or not ax.axison or not ax.get_visible() or ax.get_label() == "<colorbar>":
            continue
        if not (ax.lines or ax.collections or ax.images or ax.patches):
            continue
        name = " / ".join(t for t in (title, ax.get_title(), f"axes {i}") if t)
        for axis, label, shared, ticks in (
            ("x", ax.get_xlabel, ax.get_shared_x_axes(), ax.xaxis),
            ("y", ax.get_ylabel, ax.get_shared_y_axes(), ax.yaxis),
        ):
            names = [t.get_text() for t in ticks.get_ticklabels()]
            if any(any(c.isalpha() for c in n) and not n.startswith("$") for n in names):
                continue  # named ticks (categories; "$...$" is a number in mathtext): the names say what each is
            getter = "get_xlabel" if axis == "x" else "get_ylabel"
            if not label().strip() and not any(getattr(a, getter)().strip() for a in shared.get_siblings(ax)):
                problems.append(f"{name}: no {axis} label")
        (x0, x1), (y0, y1) = sorted(ax.get_xlim()), sorted(ax.get_ylim())
        tx, ty = 1e-9 * (x1 - x0), 1e-9 * (y1 - y0)
        for line in ax.lines:
            if line.get_label().startswith("_") or line.get_transform() != ax.transData:
                continue  # not in the legend, or not in data coordinates (axhline, axvline)
            x, y = (np.asarray(v, dtype=float).ravel() for v in line.get_data())
            ok = np.isfinite(x) & np.isfinite(y)
            if ok.any() and not (x0 - tx <= x[ok][-1] <= x1 + tx and y0 - ty <= y[ok][-1] <= y1 + ty):
                problems.append(
                    f"{name}: the line {line.get_label()!r} ends at ({x[ok][-1]:.4g}, {y[ok][-1]:.4g}), "
                    f"outside the view x [{x0:.4g}, {x1:.4g}], y [{y0:.4g}, {y1:.4g}]"
                )
        for coll in ax.collections:
            if isinstance(coll, ContourSet) and coll.filled:
                box = coll.get_datalim(ax.transData)
                if box.x0 > x0 + tx or box.x1 < x1 - tx or box.y0 > y0 + ty or box.y1 < y1 - ty:
                    problems.append(
                        f"{name}: a filled contour computed on x [{box.x0:.4g}, {box.x1:.4g}], "
                        f"y [{box.y0:.4g}, {box.y1:.4g}] does not cover the view x [{x0:.4g}, {x1:.4g}], "
                        f"y [{y0:.4g}, {y1:.4g}]"
                    )
    return problems


def test_figure_problems_finds_what_it_names():
    """The figure check on figures with each defect, and on one without."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    try:
        fig, (a, b) = plt.subplots(1, 2, sharey=True)
        a.plot([0, 1, 2], [5.0, 1.0, 0.0], label="settles in view")
        a.axvline(1.5, label="a vertical line")  # axes coordinates in y: not checked
        a.set(xlabel="t [s]", ylabel="d [mm]")
        b.plot([0, 1], [0, 1])
        b.set_xlabel("t [s]")  # its y label is a's (shared)
        inset = a.inset_axes([0.5, 0.5, 0.4, 0.4])
        inset.plot([0, 1], [0, 1])
        bars = fig.add_axes([0.1, 0.1, 0.2, 0.2])
        bars.barh([0, 1], [0.5, 0.9])
        bars.set_yticks([0, 1], ["pi", "stanley"])  # named ticks, no y label needed
        bars.set_xlabel("success rate [%]")
        assert figure_problems(fig) == []
        a.plot([0, 1, 2], [0.0, -5.0, -9.0], label="ends below")
        a.set_ylim(-1, 6)
        b.set_xlabel("")
        x, y = np.meshgrid(np.linspace(0, 2, 5), np.linspace(-0.5, 6, 5))
        a.contourf(x, y, x > 1, levels=[0.5, 1.5])
        a.set_ylim(-1, 6)
        problems = "\n".join(figure_problems(fig))
        assert "'ends below' ends at (2, -9)" in problems
        assert "no x label" in problems and "a filled contour" in problems
        assert "'settles in view'" not in problems and "a vertical line" not in problems
    finally:
        plt.close("all")


#: Run first in every notebook's kernel: every figure the notebook shows is checked when the inline
#: backend displays it (a figure pfjax writes to a file, e.g. a study's report, is not shown).
FIGURE_CHECK = f"""
_NOTEBOOK_FIGURE_PROBLEMS = []
{inspect.getsource(figure_problems)}
import matplotlib_inline.backend_inline as _inline

_display = _inline.display


def _checked_display(*objs, **kwargs):
    for obj in objs:
        if hasattr(obj, "axes") and hasattr(obj, "canvas"):  # a matplotlib figure
            _NOTEBOOK_FIGURE_PROBLEMS.extend(figure_problems(obj))
    return _display(*objs, **kwargs)


_inline.display = _checked_display
"""
FIGURE_VERDICT = 'assert not _NOTEBOOK_FIGURE_PROBLEMS, "\\n".join(dict.fromkeys(_NOTEBOOK_FIGURE_PROBLEMS))'


@pytest.mark.slow
@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.name for p in NOTEBOOKS])
def test_notebook_runs(path: Path, tmp_path: Path, monkeypatch):
    """Every cell runs, and every figure passes :func:`figure_problems`. The kernel's temporary
    directory (``$TMPDIR``, which a notebook's study output goes to) is the test's own, so a run
    leaves nothing behind in the system's."""
    monkeypatch.setenv("TMPDIR", str(tmp_path))
    nb = nbformat.read(path, as_version=4)
    nb.cells.insert(0, nbformat.v4.new_code_cell(FIGURE_CHECK))
    nb.cells.append(nbformat.v4.new_code_cell(FIGURE_VERDICT))
    client = nbclient.NotebookClient(
        nb, timeout=CELL_TIMEOUT_S, kernel_name="python3", resources={"metadata": {"path": str(NB_DIR)}}
    )
    try:
        client.execute()
    except nbclient.exceptions.CellExecutionError as exc:
        pytest.fail(f"{path.name}: a cell raised\n{exc}", pytrace=False)
