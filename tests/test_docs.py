"""The documentation: the site builds with ``mkdocs build --strict`` (broken links, missing pages,
unresolved API references and docstring warnings fail), has a page for each part a user needs, and
its generated tables come from the code; nothing in the repository speaks of how pfjax was made."""

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

PAGES = [
    "index",
    "getting-started",
    "concepts",
    "studies",
    "design-and-tuning",
    "reproductions/path-following",
    "reproductions/parking",
    "reproductions/vehicle-tracking",
    "verification",
    "performance",
    "extending",
    "api",
    "changelog",
]
NOTEBOOKS = sorted(p.stem for p in (ROOT / "notebooks").glob("*.ipynb"))


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    pytest.importorskip("mkdocs")
    out = tmp_path_factory.mktemp("site")
    env = {**os.environ, "PFJAX_DOCS_EXECUTE": "false", "NO_MKDOCS_2_WARNING": "1"}
    r = subprocess.run(
        # not -q: mkdocs's quiet mode hides the warnings that --strict turns into a failure
        [sys.executable, "-m", "mkdocs", "build", "--strict", "-d", str(out)],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-6000:]
    return out


def test_every_page_is_built(site):
    for page in PAGES:
        html = site / ("index.html" if page == "index" else f"{page}/index.html")
        assert html.is_file(), page
    for nb in NOTEBOOKS:
        assert (site / "notebooks" / nb / "index.html").is_file(), nb


def test_generated_tables_come_from_the_code(site):
    from pfjax import controllers as C
    from pfjax.tables import COLUMNS

    studies = (site / "studies" / "index.html").read_text()
    for key in ("initial.start_along_m", "sim.horizon", "margin.amplitudes_deg", "controllers[i].type"):
        assert f"<code>{key}</code>" in studies, key
    for column in COLUMNS:
        assert f"<code>{column}</code>" in studies, column
    for key in ("sim.scan_period", "assumptions.zones", "search.max_switches", "montecarlo.theta_scatter_deg"):
        assert f"<code>{key}</code>" in studies, key  # the parking study's schema
    for key in ("multistart.n_screen", "compare.ablation", "robust.heldout_runs", "gradient.table3_steps"):
        assert f"<code>{key}</code>" in studies, key  # the tuning study's schema
    concepts = (site / "concepts" / "index.html").read_text()
    for name in C.REGISTRY:
        assert f"<code>{name}</code>" in concepts, name


def test_api_reference_documents_the_public_api(site):
    import pfjax

    api = (site / "api" / "index.html").read_text()
    for name in ("design_mixed", "scenarios", "simulate", "success_rate", "run_study", "load_study", "tune", "falsify"):
        assert f'id="pfjax.api.{name}"' in api, name
    assert set(pfjax.__all__) >= {"design_mixed", "scenarios", "simulate", "run_study", "load_study", "tune", "falsify"}


def test_docstring_cross_references_are_links_not_roles(site):
    """A docstring's ``:func:`simulate``` is drawn as a link to the object on the site (resolved
    relative to the object it appears in: ``pfjax.api.simulate`` in the API's docstrings,
    ``pfjax.sim.simulate.simulate`` in its module's), or as plain code where the
    site does not document it; no role is shown as written."""
    import re

    api = (site / "api" / "index.html").read_text()
    assert not re.search(r":(func|class|mod|data|meth|attr|exc|obj):<code>", api)
    links = re.findall(r'<a class="autorefs autorefs-internal"[^>]*href="([^"]*)"[^>]*><code>simulate</code></a>', api)
    assert "#pfjax.api.simulate" in links and "#pfjax.sim.simulate.simulate" in links, links
    assert all(h.endswith(".simulate") and f'id="{h[1:]}"' in api for h in links), links
    assert re.search(r'href="[^"]*#pfjax\.errors\.InputError"[^>]*><code>InputError</code></a>', api)


# Development-process vocabulary, spelled in pieces so this file does not match itself.
PROCESS = [
    r"\bstop " + r"\d+",
    r"\bstops " + r"\d+",
    r"earlier " + "stops",
    r"\b(until|since|at) " + r"stop\b",
    r"this " + "sess" + "ion",
    r"\bissue " + r"\d+",
    r"the " + r"issue'?s?\b",
    r"\.\./" + "shared",
]


def _tracked_text_files():
    out = subprocess.run(
        ["git", "ls-files", "-co", "--exclude-standard"], cwd=ROOT, capture_output=True, text=True, check=True
    ).stdout.split()
    for name in out:
        p = ROOT / name
        if (
            p.suffix in (".py", ".md", ".toml", ".ipynb", ".cff", ".yml", ".j2", ".txt", ".cfg")
            and p.is_file()
            and name != "tests/test_docs.py"
        ):
            yield name, p.read_text(errors="replace")


def test_nothing_speaks_of_how_pfjax_was_made():
    found = []
    for name, text in _tracked_text_files():
        for pattern in PROCESS:
            for m in re.finditer(pattern, text, re.I):
                line = text[: m.start()].count("\n") + 1
                found.append(f"{name}:{line}: {text.splitlines()[line - 1].strip()[:120]}")
    assert not found, "\n".join(found[:40])


def test_readme_is_a_front_door():
    text = (ROOT / "README.md").read_text()
    assert len(text.splitlines()) <= 300
    assert "## Install and run" in text and "make study" in text and "make test" in text
    # every local link in the README resolves
    for target in re.findall(r"\]\(([^)#]+)\)", text):
        if "://" not in target:
            assert (ROOT / target).exists(), target
