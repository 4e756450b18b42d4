"""The house's shape, checked from the source (AST, nothing imported): the command line is on top
and imported by nothing in the library, and the library's modules import one another without
circles (an import inside a function counts: it is still a dependency).

A ``from pfjax.pkg import name`` of a name a package re-exports is followed to the module that
defines it, so a package's ``__init__`` is not mistaken for a dependency on all its modules.
"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1] / "pfjax"


def _modules() -> dict[str, Path]:
    out = {}
    for f in ROOT.rglob("*.py"):
        rel = f.relative_to(ROOT.parent).with_suffix("")
        parts = list(rel.parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = f
    return out


MODULES = _modules()


def _imports(path: Path) -> list[tuple[str, list[str]]]:
    """``(module, [names])`` of every pfjax import in the file (names empty for ``import x``)."""
    out = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            out += [(a.name, []) for a in node.names if a.name.startswith("pfjax")]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0 and node.module.startswith("pfjax"):
            out.append((node.module, [a.name for a in node.names]))
    return out


def _reexports(package: str) -> dict[str, str]:
    """name -> defining module, for the names a package's ``__init__`` imports from its modules."""
    path = MODULES.get(package)
    if path is None or path.name != "__init__.py":
        return {}
    out = {}
    for mod, names in _imports(path):
        for n in names:
            target = f"{mod}.{n}" if f"{mod}.{n}" in MODULES else mod
            out[n] = _reexports(mod).get(n, target) if MODULES.get(mod, Path()).name == "__init__.py" else target
    return out


def _edges() -> dict[str, set[str]]:
    graph = {m: set() for m in MODULES}
    for m, path in MODULES.items():
        for mod, names in _imports(path):
            if not names:
                graph[m].add(mod)
                continue
            for n in names:
                if f"{mod}.{n}" in MODULES:
                    graph[m].add(f"{mod}.{n}")
                else:
                    graph[m].add(_reexports(mod).get(n, mod))
    for m in graph:  # a package's __init__ depends on what it re-exports; the rest is not a cycle
        graph[m].discard(m)
    return {m: {t for t in ts if t in MODULES} for m, ts in graph.items()}


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index, low, stack, on, out, counter = {}, {}, [], set(), [], [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_nothing_in_the_library_imports_the_command_line():
    graph = _edges()
    offenders = sorted(
        m
        for m, ts in graph.items()
        if not m.startswith("pfjax.cli") and any(t == "pfjax.cli" or t.startswith("pfjax.cli.") for t in ts)
    )
    assert not offenders, offenders


def test_the_domain_does_not_import_the_api_layer():
    """``pfjax.api`` is the Python entry layer over the domain packages (as the command line is
    over it): only the package's top, the API and the command line import it."""
    graph = _edges()
    offenders = sorted(
        m
        for m, ts in graph.items()
        if m != "pfjax"
        and not m.startswith(("pfjax.api", "pfjax.cli"))
        and any(t == "pfjax.api" or t.startswith("pfjax.api.") for t in ts)
    )
    assert not offenders, offenders


def test_the_library_has_no_import_circles():
    graph = _edges()
    library = {m: {t for t in ts if not t.startswith("pfjax.cli")} for m, ts in graph.items()}
    assert _cycles(library) == []


def test_the_analysis_finds_a_circle_when_there_is_one():
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}
    assert _cycles(graph) == [["a", "b", "c"]]


def test_a_simulation_does_not_import_the_host_side_statistics_stack():
    """``pfjax simulate`` starts fast: the simulator, the controllers, the paths and the command line's
    simulate command import neither pandas nor SciPy nor cvxpy nor matplotlib (0.6 s and more of
    every command's start-up); the robustness statistics load them on first use."""
    import subprocess
    import sys

    code = (
        "import sys, pfjax.sim, pfjax.sim.simulate, pfjax.sim.scenario, pfjax.controllers, pfjax.paths, "
        "pfjax.metrics, pfjax.cli.simulate; "
        "print(','.join(m for m in ('pandas', 'scipy', 'cvxpy', 'matplotlib') if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip()
    assert out == "", f"imported at start-up: {out}"
    # and the lazily re-exported statistics are still there
    import pfjax.metrics as metrics
    from pfjax.metrics import margins, robustness

    assert metrics.slip_margin is margins.slip_margin and metrics.clopper_pearson is robustness.clopper_pearson
    assert set(robustness.__all__) - {"check_open_unit"} <= set(dir(metrics))


def test_a_design_once_made_is_read_back_without_cvxpy(tmp_path):
    """The mixed and integral LMI designs are kept on disk (pfjax.cache.memoized_design): a second
    process gets the same gains without importing cvxpy (seconds); another argument is a new design."""
    import json
    import subprocess
    import sys

    code = (
        "import sys, json; from pfjax.controllers.designs import DESIGNS; "
        "g = [DESIGNS[n].make(1.0, 0.2) for n in ('lmi', 'integral_lmi')]; "
        "print(json.dumps([g, 'cvxpy' in sys.modules]))"
    )
    env = {**__import__("os").environ, "PFJAX_CACHE_DIR": str(tmp_path / "xla")}
    run = lambda: json.loads(
        subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True).stdout
    )
    first, second = run(), run()
    assert first[1] and not second[1]
    assert first[0] == second[0]  # exactly: floats round-trip through JSON
    assert sorted(p.name.split("-")[0] for p in (tmp_path / "designs").iterdir()) == ["integral_lmi", "lmi"]
    from pfjax.synthesis import mixed_h2_hinf, slip_design_plant

    K = mixed_h2_hinf(slip_design_plant(1.0, 0.2), alpha=10.0, beta=1.0).K.ravel()
    assert first[0][0] == {"k_d": float(K[0]), "k_theta": float(K[1])}


def test_no_module_imports_another_modules_private_names():
    """Each module keeps its ``_private`` names to itself: no ``from pfjax.x import _name`` in the
    library, the studies or the notebooks (a name another module needs is public in its home)."""
    import ast
    import json
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    sources = {p: p.read_text() for d in ("pfjax", "studies") for p in (root / d).rglob("*.py")}
    for nb in (root / "notebooks").glob("*.ipynb"):
        cells = json.loads(nb.read_text())["cells"]
        code = "\n".join("".join(c["source"]) for c in cells if c["cell_type"] == "code")
        sources[nb] = "\n".join(line for line in code.splitlines() if not line.lstrip().startswith(("%", "!")))
    bad = []
    for path, text in sources.items():
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("pfjax"):
                bad += [
                    f"{path.relative_to(root)}: {node.module}.{a.name}"
                    for a in node.names
                    if a.name.startswith("_") and not a.name.startswith("__")
                ]
    assert not bad, bad
