"""The tests' own layout: a test imports the package and ``tests.helpers``, never another test module (a
helper two tests share moves to ``tests/helpers/``), and fixtures come from ``conftest.py``, not by import."""
from __future__ import annotations

import ast
from pathlib import Path

TESTS = Path(__file__).resolve().parent


def cross_test_imports(path: Path) -> list[str]:
    """The test modules (``test_*``) and ``conftest`` that ``path`` imports, at any depth."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        names = [node.module or ""] if isinstance(node, ast.ImportFrom) else \
            [a.name for a in node.names] if isinstance(node, ast.Import) else []
        for name in names:
            last = name.split(".")[-1] if name.startswith("tests.") else name.split(".")[0]
            if last.startswith("test_") or last == "conftest":
                found.append(f"{path.relative_to(TESTS)}:{node.lineno}: {name}")
    return found


def test_no_test_module_imports_another():
    offenders = [hit for p in sorted(TESTS.rglob("*.py")) for hit in cross_test_imports(p)]
    assert not offenders, "move what these share to tests/helpers/:\n" + "\n".join(offenders)


def test_the_check_finds_a_cross_test_import(tmp_path):
    bad = tmp_path / "x.py"
    bad.write_text("from test_cache_policy import TINY_NETS\nimport tests.test_api\nfrom conftest import x\n"
                   "from tests.helpers.runs import BIN\n")
    global TESTS
    saved, TESTS = TESTS, tmp_path
    try:
        assert [h.split(": ")[1] for h in cross_test_imports(bad)] == ["test_cache_policy", "tests.test_api", "conftest"]
    finally:
        TESTS = saved
