"""Import structure of the project's own modules (``lit3d`` and ``datamodules``).

1. No import cycle between modules. The graph is grimp's (the library under ``lint-imports``): one
   edge per import statement of a project module, function-local imports included, so a cycle
   hidden behind a function-local import counts. No edge is left out: grimp records
   ``from a.b import c`` as an edge to ``a.b`` only (not to the package ``a``'s ``__init__``,
   which Python also runs), so package re-exports make no false cycles.
2. No function-local import of a project module (``lit3d.*``, ``datamodules.*`` or a relative
   import) outside the allowed places: ``lit3d/cli/**`` (start-up time of the console scripts),
   ``lit3d/__init__.py`` (the lazy API behind ``import lit3d``) and :data:`ALLOWED_LOCAL_IMPORTS`,
   each with its reason. :data:`TEMPORARY_LOCAL_IMPORTS` and :data:`TEMPORARY_CYCLES` hold what
   work in progress still has; they only shrink.

Each test reports every offender at once, with file and line.
"""
from __future__ import annotations

import ast
import re
import sys
import tomllib
import warnings
from pathlib import Path

import pytest
from tests.helpers.paths import REPO as ROOT

grimp = pytest.importorskip("grimp")

PACKAGES = ("lit3d", "datamodules")
# where a function-local import of a project module is fine (paths relative to the checkout)
# (the console scripts and the runtime below them import heavy modules late: a bad command line is answered fast)
ALLOWED_PLACES = ("lit3d/cli/", "lit3d/runtime/", "lit3d/__init__.py")
# (file, imported module, reason): function-local imports that must stay
ALLOWED_LOCAL_IMPORTS: tuple[tuple[str, str, str], ...] = (
    ("lit3d/reconstruct/pipeline.py", "lit3d.completion.module",
     "start-up time: Lightning and the nets load when a checkpoint is loaded, not for --help or a bad path"),
    ("lit3d/reconstruct/pipeline.py", "lit3d.canonical.module", "start-up time, as above"),
    ("lit3d/reconstruct/pipeline.py", "lit3d.canonical.checkpoint_upgrade", "start-up time, as above"),
    ("lit3d/reconstruct/pipeline.py", "lit3d.completion.checkpoint_upgrade", "start-up time, as above"),
    ("lit3d/reconstruct/pipeline.py", "datamodules.completion.voxel_cache",
     "start-up time: torch loads when a shape is completed"),
    ("lit3d/reconstruct/figure.py", "lit3d.render.shaded", "start-up time: the renderer loads for --figure only"),
)
TEMPORARY_LOCAL_IMPORTS: dict[str, str] = {}
TEMPORARY_CYCLES: tuple[frozenset[str], ...] = ()


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _imported(node: ast.Import | ast.ImportFrom, module: str, is_package: bool) -> list[str]:
    """Absolute names of the modules an import statement names (relative imports resolved)."""
    if isinstance(node, ast.Import):
        return [a.name for a in node.names]
    if not node.level:
        return [node.module or ""]
    base = module.split(".") if is_package else module.split(".")[:-1]
    base = base[: len(base) - (node.level - 1)]
    return [".".join(base + ([node.module] if node.module else []))]


def function_local_imports() -> list[tuple[str, int, str]]:
    """``[(file, line, imported module)]``: every import of a project module inside a function
    (at any depth: methods, nested functions, branches of a function body)."""
    found = []
    for pkg in PACKAGES:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            rel = path.relative_to(ROOT).as_posix()
            module, is_package = _module_name(path), path.name == "__init__.py"

            def visit(node: ast.AST, in_function: bool) -> None:
                for child in ast.iter_child_nodes(node):
                    if in_function and isinstance(child, (ast.Import, ast.ImportFrom)):
                        for name in _imported(child, module, is_package):
                            if name.split(".")[0] in PACKAGES:
                                found.append((rel, child.lineno, name))
                    visit(child, in_function or isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef,
                                                                   ast.Lambda)))

            visit(ast.parse(path.read_text(encoding="utf-8"), rel), False)
    return found


def import_cycles(graph) -> list[list[str]]:
    """Strongly connected components of more than one module (each holds a cycle), sorted."""
    modules = sorted(graph.modules)
    edges = {m: sorted(graph.find_modules_directly_imported_by(m)) for m in modules}
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    components = []
    for start in modules:  # iterative Tarjan (no recursion limit on long chains)
        if start in index:
            continue
        work = [(start, 0)]
        while work:
            v, i = work.pop()
            if i == 0:
                index[v] = low[v] = len(index)
                stack.append(v)
                on_stack.add(v)
            targets = edges.get(v, [])
            if i < len(targets):
                work.append((v, i + 1))
                w = targets[i]
                if w not in index:
                    work.append((w, 0))
                elif w in on_stack:
                    low[v] = min(low[v], index[w])
                continue
            if low[v] == index[v]:
                comp = []
                while True:
                    w = stack.pop()
                    on_stack.discard(w)
                    comp.append(w)
                    if w == v:
                        break
                if len(comp) > 1:
                    components.append(sorted(comp))
            if work:  # propagate to the parent
                parent = work[-1][0]
                low[parent] = min(low[parent], low[v])
    return sorted(components)


def _describe(graph, component: list[str]) -> str:
    lines = []
    for a in component:
        for b in sorted(set(graph.find_modules_directly_imported_by(a)) & set(component)):
            at = sorted({d["line_number"] for d in graph.get_import_details(importer=a, imported=b)})
            lines.append(f"    {a} -> {b} (line {', '.join(map(str, at))})")
    return "\n".join(lines)


def test_no_import_cycle_between_project_modules():
    graph = grimp.build_graph(*PACKAGES, cache_dir=None)
    cycles = import_cycles(graph)
    new = [c for c in cycles if frozenset(c) not in TEMPORARY_CYCLES]
    for gone in set(TEMPORARY_CYCLES) - {frozenset(c) for c in cycles}:
        warnings.warn(f"TEMPORARY_CYCLES: {sorted(gone)} is no longer a cycle; remove its entry", stacklevel=1)
    assert not new, "import cycles between project modules (cut each by a third module both sides import):\n" + \
        "\n".join(f"  {' <-> '.join(c)}\n{_describe(graph, c)}" for c in new)


def test_tarjan_finds_a_hidden_cycle():
    """The cycle finder on a toy graph: a -> b -> c -> a (c's import is the function-local one) and d alone."""

    class Toy:
        modules = {"a", "b", "c", "d"}
        _edges = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}

        def find_modules_directly_imported_by(self, m):
            return self._edges.get(m, set())

    assert import_cycles(Toy()) == [["a", "b", "c"]]


def test_no_function_local_import_of_a_project_module():
    allowed = {(f, m) for f, m, _ in ALLOWED_LOCAL_IMPORTS}
    found = function_local_imports()
    offenders = [(f, line, m) for f, line, m in found
                 if not f.startswith(ALLOWED_PLACES) and (f, m) not in allowed and f not in TEMPORARY_LOCAL_IMPORTS]
    used = {(f, m) for f, _, m in found}
    stale = sorted(allowed - used)
    for f in sorted(set(TEMPORARY_LOCAL_IMPORTS) - {f for f, _, _ in found}):
        warnings.warn(f"TEMPORARY_LOCAL_IMPORTS: {f} has no function-local project import left; remove its entry",
                      stacklevel=1)
    assert not stale, f"ALLOWED_LOCAL_IMPORTS entries that match no import any more (remove them): {stale}"
    assert not offenders, (
        "function-local imports of project modules (move them to the top of the file; if one must stay, "
        "add (file, module, reason) to ALLOWED_LOCAL_IMPORTS):\n"
        + "\n".join(f"  {f}:{line}: {m}" for f, line, m in offenders))


def test_scanner_sees_nested_and_relative_imports(tmp_path, monkeypatch):
    """The function-local scan on a toy package: a method's relative import and a nested function's
    absolute import count; a module-level import and a third-party local import do not."""
    pkg = tmp_path / "lit3d" / "toy"
    pkg.mkdir(parents=True)
    (tmp_path / "lit3d" / "__init__.py").write_text("")
    (pkg / "__init__.py").write_text("")
    (pkg / "mod.py").write_text(
        "from lit3d.utils import io\n"
        "class A:\n"
        "    def f(self):\n"
        "        from . import other\n"
        "        import numpy\n"
        "def g():\n"
        "    def h():\n"
        "        from datamodules.cache import x\n"
    )
    (tmp_path / "datamodules").mkdir()
    monkeypatch.setattr(sys.modules[__name__], "ROOT", tmp_path)
    assert function_local_imports() == [("lit3d/toy/mod.py", 4, "lit3d.toy"),
                                        ("lit3d/toy/mod.py", 8, "datamodules.cache")]


MAX_LINES = 400  # small modules with one job


def test_no_python_file_over_400_lines():
    folders = ("lit3d", "datamodules", "scripts", "benchmarks", "tests", "studies")
    long = {str(p.relative_to(ROOT)): n for f in folders for p in (ROOT / f).rglob("*.py")
            if (n := len(p.read_text(encoding="utf-8").splitlines())) > MAX_LINES}
    assert not long, f"files over {MAX_LINES} lines (split them by job): {long}"


def test_the_package_never_imports_the_studies():
    """``studies/`` sits beside the package (research programs and their logs): the product does not depend on it.
    Neither an import statement nor a name the package resolves at run time: ``importlib.import_module("studies...")``
    or a Hydra ``_target_: studies...`` in the configs (``conf/``, ``sweeps/``) the wheel ships. (The import
    statements are also an import-linter contract in ``pyproject.toml``.)"""
    statement = re.compile(r"^\s*(?:from|import)\s+studies\b", re.MULTILINE)
    by_name = re.compile(r"""(?:import_module|__import__|import_object)\(\s*["']studies\b""")
    target = re.compile(r"_target_:\s*studies\.")
    found = [str(p.relative_to(ROOT)) for f in ("lit3d", "datamodules") for p in (ROOT / f).rglob("*.py")
             if statement.search(text := p.read_text(encoding="utf-8")) or by_name.search(text)]
    found += [str(p.relative_to(ROOT)) for f in ("conf", "sweeps") for p in (ROOT / f).rglob("*.yaml")
              if target.search(p.read_text(encoding="utf-8"))]
    assert not found, f"the package imports studies: {found}"


def console_script_files() -> set[str]:
    """The files of the console scripts in ``pyproject.toml``'s ``[project.scripts]`` (``lit3d/cli/train.py`` ...)."""
    scripts = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]["scripts"]
    return {target.split(":")[0].replace(".", "/") + ".py" for target in scripts.values()}


def package_programs(allowed: set[str]) -> list[str]:
    """Modules under ``lit3d/`` and ``datamodules/`` meant to be run with ``python -m``: an
    ``if __name__ == "__main__":`` block or a package ``__main__.py``, except the files in ``allowed``."""
    main = re.compile(r"^if __name__ == .__main__.:", re.MULTILINE)
    return sorted(rel for f in ("lit3d", "datamodules") for p in (ROOT / f).rglob("*.py")
                  if (rel := p.relative_to(ROOT).as_posix()) not in allowed
                  and (p.name == "__main__.py" or main.search(p.read_text(encoding="utf-8"))))


def test_no_program_in_the_package():
    """The package's only programs are its console scripts (``[project.scripts]``: ``lit3d-train`` ...,
    whose modules keep ``if __name__ == "__main__"`` for ``python -m lit3d.cli.score`` from a checkout). The
    quality demo's driver is ``scripts/demo_quality.py``; study programs live in ``studies/``; the canonical
    summaries are ``lit3d-summary --pooled`` and ``--over-runs``."""
    allowed = console_script_files()
    assert "lit3d/cli/train.py" in allowed and "lit3d/cli/summary.py" in allowed, allowed
    assert package_programs(allowed) == [], "programs inside the package (make them console-script options or move " \
                                            "them to scripts/ or studies/)"
    assert "lit3d/cli/train.py" in package_programs(set())  # the check sees a program where there is one
