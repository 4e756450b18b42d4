"""Every notebook in notebooks/ runs top to bottom without a cell error.

Each notebook is executed in a fresh ``python3`` kernel with the notebooks directory as its working
directory; the executed copy stays in memory (nothing is written back to disk). New notebooks are
picked up by the glob. Each notebook is stored without outputs and starts with a parameters cell
(tagged ``parameters``, for papermill) holding the sizes it uses.
"""

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


@pytest.mark.slow
@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.name for p in NOTEBOOKS])
def test_notebook_runs(path: Path):
    nb = nbformat.read(path, as_version=4)
    client = nbclient.NotebookClient(
        nb, timeout=CELL_TIMEOUT_S, kernel_name="python3", resources={"metadata": {"path": str(NB_DIR)}}
    )
    try:
        client.execute()
    except nbclient.exceptions.CellExecutionError as exc:
        pytest.fail(f"{path.name}: a cell raised\n{exc}", pytrace=False)
