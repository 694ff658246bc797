"""The architecture docs follow the code: every code path that ``docs/design.md`` and
``docs/CONTRIBUTING_TASKS.md`` name exists.

Checked, in the prose, the code blocks and the backticks alike:

- file and folder paths under the checkout's top-level folders (``datamodules/completion/plan.py``,
  ``lit3d/sensing/``, ``tests/project/test_import_structure.py``, ``conf/``, ``.ci/run``...);
- top-level files named bare in backticks (``pyproject.toml``, ``Makefile``) and relative markdown
  links;
- dotted names of project code in backticks (``datamodules.cache.CacheBuilder``,
  ``lit3d.cli.evaluation.run_evaluation``): the longest importable module, then attributes.

Left out: templates (``lit3d/<task>/``, ``tests/normals/test_normals_*.py``) and the walkthrough's example
task ``normals``, which CONTRIBUTING_TASKS.md adds on paper only.
"""
from __future__ import annotations

import importlib
import re
from pathlib import Path

import pytest
from tests.helpers.paths import REPO as ROOT

DOCS = ("docs/design.md", "docs/CONTRIBUTING_TASKS.md")
TOP = ("lit3d", "datamodules", "tests", "conf", "scripts", "benchmarks", "sweeps", "docs", "studies", ".ci")
EXAMPLE_TASK = "normals"  # CONTRIBUTING_TASKS.md's walkthrough task: named, not built

PATH = re.compile(r"(?<![\w./-])((?:%s)/[\w./<>*{}-]*)" % "|".join(map(re.escape, TOP)))
# top-level files named bare (``pyproject.toml``); a bare ``nets.py`` is a file of the task being described
BACKTICK_FILE = re.compile(r"`((?:[\w-]+\.(?:toml|cfg))|Makefile|LICENSE)`")
LINK = re.compile(r"\]\(([^)#\s]+)(?:#[^)]*)?\)")
DOTTED = re.compile(r"`((?:lit3d|datamodules|studies)(?:\.\w+)+)")


def _placeholder(text: str) -> bool:
    return any(c in text for c in "<>*{}") or EXAMPLE_TASK in text


def named_paths(doc: str) -> list[str]:
    """Relative paths (to the checkout) that ``doc`` names, placeholders left out."""
    text = (ROOT / doc).read_text(encoding="utf-8")
    found = [p.rstrip(".,:;)") for p in PATH.findall(text)]
    found += BACKTICK_FILE.findall(text)
    for link in LINK.findall(text):
        if not re.match(r"[a-z]+:", link):  # http:, mailto: ...
            found.append((Path(doc).parent / link).as_posix())
    return sorted({p for p in found if not _placeholder(p)})


def named_objects(doc: str) -> list[str]:
    """Dotted project names in backticks (``datamodules.cache.CacheBuilder``)."""
    text = (ROOT / doc).read_text(encoding="utf-8")
    return sorted({d for d in DOTTED.findall(text) if not _placeholder(d)})


def _exists(rel: str) -> bool:
    path = (ROOT / rel).resolve()
    return path.exists() or (ROOT / rel.lstrip("/")).exists()


def _resolves(dotted: str) -> bool:
    parts = dotted.split(".")
    for i in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:i]))
        except ImportError:
            continue
        try:
            for attr in parts[i:]:
                obj = getattr(obj, attr)
        except AttributeError:
            return False
        return True
    return False


@pytest.mark.parametrize("doc", DOCS)
def test_every_path_a_doc_names_exists(doc):
    paths = named_paths(doc)
    assert any(p.startswith("datamodules/") for p in paths), f"{doc}: the path scan found no datamodules path"
    missing = [p for p in paths if not _exists(p)]
    assert not missing, f"{doc} names paths that do not exist: {missing}"


@pytest.mark.parametrize("doc", DOCS)
def test_every_dotted_name_a_doc_names_resolves(doc):
    missing = [d for d in named_objects(doc) if not _resolves(d)]
    assert not missing, f"{doc} names modules/objects that do not exist: {missing}"


def test_the_scan_sees_paths_and_skips_templates(tmp_path, monkeypatch):
    """The scanner on a toy doc: code-block, prose and backtick paths count; templates and the
    example task do not; trailing punctuation is not part of a path."""
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "x.md").write_text(
        "```\ndatamodules/completion/   plan\n```\nSee `lit3d/runtime/registry.py`, then datamodules/cache.py.\n"
        "Add `lit3d/<task>/evaluator.py` and `datamodules/normals/`; `pyproject.toml`; [a](other.md)\n"
        "`datamodules.cache.CacheBuilder` and `datamodules.normals.NormalsDataModule`; `.ci/run`, not x.ci/y\n")
    monkeypatch.setitem(globals(), "ROOT", tmp_path)
    assert named_paths("docs/x.md") == [".ci/run", "datamodules/cache.py", "datamodules/completion/", "docs/other.md",
                                        "lit3d/runtime/registry.py", "pyproject.toml"]
    assert named_objects("docs/x.md") == ["datamodules.cache.CacheBuilder"]
    assert _resolves("datamodules.cache.CacheBuilder") and not _resolves("datamodules.cache.NoSuchThing")


# CHANGELOG.md is left out: its history names paths that have moved since, as it should
ALL_DOCS = sorted({*DOCS, "README.md", "BENCHMARKS.md", "CREDITS.md", "sweeps/README.md",
                   *(p.relative_to(ROOT).as_posix() for p in (ROOT / "docs").rglob("*.md")),
                   *(p.relative_to(ROOT).as_posix() for p in (ROOT / "studies").rglob("*.md"))})
COMMAND = re.compile(r"python -m\s+((?:lit3d|datamodules|studies|benchmarks)\b[\w.<>*{}]*)")


def named_programs(text: str) -> list[str]:
    """The modules of the ``python -m MODULE`` commands in ``text`` (a command may wrap after ``-m``)."""
    return sorted({m.rstrip(".") for m in COMMAND.findall(text) if not _placeholder(m)})


@pytest.mark.parametrize("doc", ALL_DOCS)
def test_every_doc_names_existing_paths_and_programs(doc):
    """Every doc, the results pages and the studies' READMEs included: its paths exist, its dotted names
    resolve, and every ``python -m`` program it names is a module with a ``__main__`` block (or a package
    ``__main__``): a program that moved (the studies left the package) leaves no stale command behind."""
    missing = [p for p in named_paths(doc) if not _exists(p)] + [d for d in named_objects(doc) if not _resolves(d)]
    missing += [m for m in named_programs((ROOT / doc).read_text(encoding="utf-8")) if not _is_program(m)]
    assert not missing, f"{doc} names what does not exist: {missing}"


def test_the_commands_in_the_configs_exist():
    """The ``python -m`` commands that the configs' comments name (``conf/``, ``sweeps/``) exist."""
    missing = sorted({f"{p.relative_to(ROOT)}: {m}" for f in ("conf", "sweeps") for p in (ROOT / f).rglob("*.yaml")
                      for m in named_programs(p.read_text(encoding="utf-8")) if not _is_program(m)})
    assert not missing, f"configs name programs that do not exist: {missing}"


def _is_program(module: str) -> bool:
    parts = module.split(".")
    for candidate in (ROOT.joinpath(*parts).with_suffix(".py"), ROOT.joinpath(*parts, "__main__.py")):
        if candidate.is_file():
            return candidate.name == "__main__.py" or "__name__ == \"__main__\"" in candidate.read_text(encoding="utf-8")
    return False


def test_a_moved_program_is_caught(tmp_path, monkeypatch):
    assert named_programs("run `python -m\nstudies.canonical.pooled DIR` or python -m lit3d.<task>.x") == [
        "studies.canonical.pooled"]
    assert _is_program("studies.canonical.pooled") and not _is_program("lit3d.api")  # python -m lit3d.api: removed
    assert not _is_program("lit3d.canonical.pooled") and not _is_program("lit3d.no_such_module")
    (tmp_path / "lit3d" / "tool").mkdir(parents=True)
    (tmp_path / "lit3d" / "tool" / "__main__.py").write_text("print('a package program')\n")
    monkeypatch.setitem(globals(), "ROOT", tmp_path)
    assert _is_program("lit3d.tool") and not _is_program("lit3d")


def _packages(top: str) -> list[str]:
    return sorted(f"{p.parent.relative_to(ROOT).as_posix()}/" for p in (ROOT / top).glob("*/__init__.py"))


def test_the_layout_sections_name_every_package():
    """The README's architecture block and docs/design.md's tree name every package of lit3d/ (and design.md
    every package of datamodules/): a new room cannot go unmentioned, a moved one leaves no stale line
    (the paths they name exist: the tests above)."""
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    block = readme[readme.index("## Architecture"):]
    design = (ROOT / "docs/design.md").read_text(encoding="utf-8")
    missing = [f"README.md: {p}" for p in _packages("lit3d") if p not in block]
    missing += [f"docs/design.md: {p}" for p in _packages("lit3d") + _packages("datamodules") if p not in design]
    assert not missing, f"packages the layout sections do not name: {missing}"
