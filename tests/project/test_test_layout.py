"""The tests' own layout.

- A test imports the package and ``tests.helpers``, never another test module (a helper two tests share
  moves to ``tests/helpers/``), and fixtures come from ``conftest.py``, not by import.
- The tests mirror the package: every test file sits in a folder of ``tests/`` named after what it tests
  (``tests/completion/``, ``tests/metrics/``, ``tests/project/`` for the house rules ...), none at the top
  (there only ``conftest.py``, whose fixtures every folder gets), and no two share a name (pytest imports
  test files by their name: the folders are not packages).
- ``tests/e2e/`` holds the end-to-end tests: those that start processes (a console script, ``python -c``,
  worker processes) and watch them as a user would. A file that mixes goes where most of it belongs:
  outside ``e2e/`` no file whose tests mostly (more than half) start a process, and in ``e2e/`` no file
  where fewer than a third do. A run of a tool (``git``, ``mount``) is not a process start of lit3d.
"""
from __future__ import annotations

import ast
from collections import Counter
from pathlib import Path

from tests.helpers.paths import TESTS

E2E = "e2e"
NOT_TEST_FOLDERS = ("helpers", "fixtures")  # shared code and data of the tests
SUBPROCESS_CALLS = {"run", "Popen", "call", "check_call", "check_output"}


def cross_test_imports(path: Path, tests: Path = TESTS) -> list[str]:
    """The test modules (``test_*``) and ``conftest`` that ``path`` imports, at any depth."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        names = [node.module or ""] if isinstance(node, ast.ImportFrom) else \
            [a.name for a in node.names] if isinstance(node, ast.Import) else []
        for name in names:
            last = name.split(".")[-1] if name.startswith("tests.") else name.split(".")[0]
            if last.startswith("test_") or last == "conftest":
                found.append(f"{path.relative_to(tests)}:{node.lineno}: {name}")
    return found


def misplaced_files(tests: Path) -> list[str]:
    """Test files at the top of ``tests/`` or in its helper folders, and test file names used twice."""
    files = sorted(tests.rglob("test_*.py"))
    wrong = [str(p.relative_to(tests)) for p in files
             if p.parent == tests or p.relative_to(tests).parts[0] in NOT_TEST_FOLDERS]
    twice = [name for name, n in Counter(p.name for p in files).items() if n > 1]
    return wrong + [f"{name}: the name of more than one test file" for name in sorted(twice)]


def _is_process_start(call: ast.Call) -> bool:
    """``subprocess.run`` & co. (not of a tool such as ``["git", ...]``), ``start_script``, or worker
    processes (``mp.spawn``, ``ctx.Process``)."""
    f = call.func
    if isinstance(f, ast.Name):
        return f.id == "start_script"
    if not isinstance(f, ast.Attribute):
        return False
    if f.attr in {"spawn", "Process"}:
        return True
    if not (isinstance(f.value, ast.Name) and f.value.id == "subprocess" and f.attr in SUBPROCESS_CALLS):
        return False
    args = call.args[0] if call.args else None
    first = args.elts[0] if isinstance(args, (ast.List, ast.Tuple)) and args.elts else None
    return not (isinstance(first, ast.Constant) and isinstance(first.value, str) and not first.value.startswith("lit3d"))


def _functions(tree: ast.Module) -> dict[str, ast.FunctionDef]:
    """The module's functions and its classes' methods, by name."""
    found = {}
    for node in tree.body:
        members = node.body if isinstance(node, ast.ClassDef) else [node]
        found.update({m.name: m for m in members if isinstance(m, ast.FunctionDef)})
    return found


def process_tests(path: Path) -> tuple[int, int]:
    """(tests that start a process, tests) of the file at ``path``: a test starts one itself, or through a
    function or fixture of its file that does (at any depth)."""
    funcs = _functions(ast.parse(path.read_text(), str(path)))
    uses = {name: {n.id for n in ast.walk(f) if isinstance(n, ast.Name)} | {a.arg for a in f.args.args}
            for name, f in funcs.items()}
    starting = {name for name, f in funcs.items() if any(isinstance(n, ast.Call) and _is_process_start(n)
                                                          for n in ast.walk(f))}
    grown = True
    while grown:
        more = {name for name in funcs if name not in starting and uses[name] & starting}
        starting |= more
        grown = bool(more)
    tests = [name for name in funcs if name.startswith("test_")]
    return sum(name in starting for name in tests), len(tests)


def misfiled_e2e(tests: Path) -> list[str]:
    """Files outside ``e2e/`` whose tests mostly start processes, and files in it where fewer than a third do."""
    wrong = []
    for path in sorted(tests.rglob("test_*.py")):
        starting, total = process_tests(path)
        in_e2e = path.relative_to(tests).parts[0] == E2E
        if total and (3 * starting < total if in_e2e else 2 * starting > total):
            where = "belongs outside e2e/" if in_e2e else "belongs in e2e/"
            wrong.append(f"{path.relative_to(tests)}: {starting} of {total} tests start a process: {where}")
    return wrong


def test_no_test_module_imports_another():
    offenders = [hit for p in sorted(TESTS.rglob("*.py")) for hit in cross_test_imports(p)]
    assert not offenders, "move what these share to tests/helpers/:\n" + "\n".join(offenders)


def test_the_check_finds_a_cross_test_import(tmp_path):
    bad = tmp_path / "x.py"
    bad.write_text("from test_cache_policy import TINY_NETS\nimport tests.test_api\nfrom conftest import x\n"
                   "from tests.helpers.runs import BIN\n")
    assert [h.split(": ")[1] for h in cross_test_imports(bad, tmp_path)] == ["test_cache_policy", "tests.test_api",
                                                                              "conftest"]


def test_every_test_file_sits_in_a_folder_named_after_what_it_tests():
    assert sorted(p.name for p in TESTS.glob("*.py")) == ["conftest.py"]
    assert not misplaced_files(TESTS), "\n".join(misplaced_files(TESTS))
    assert (TESTS / E2E).is_dir() and (TESTS / "project" / Path(__file__).name).is_file()


def test_the_folder_check_finds_a_flat_a_helper_and_a_twice_named_test_file(tmp_path):
    for name in ("test_flat.py", "helpers/test_helper.py", "a/test_twice.py", "b/test_twice.py", "a/test_ok.py"):
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text("")
    assert misplaced_files(tmp_path) == ["helpers/test_helper.py", "test_flat.py",
                                         "test_twice.py: the name of more than one test file"]


def test_the_end_to_end_tests_are_in_e2e():
    wrong = misfiled_e2e(TESTS)
    assert not wrong, "\n".join(wrong)


def test_the_e2e_check_counts_process_starts(tmp_path):
    (tmp_path / E2E).mkdir()
    (tmp_path / "unit").mkdir()
    runner = ("import subprocess\nfrom tests.helpers.runs import BIN, start_script\n\n"
              "def _run(args):\n    return subprocess.run([str(BIN / 'lit3d-train'), *args])\n\n"
              "@pytest.fixture\ndef worker(tmp_path):\n    return mp.spawn(print, nprocs=2)\n\n")
    (tmp_path / "unit" / "test_runs.py").write_text(
        runner + "def test_a():\n    _run([])\n\ndef test_b(worker):\n    pass\n\n"
        "def test_c():\n    start_script(['lit3d-data'], None)\n\ndef test_d():\n    assert 1\n")
    (tmp_path / E2E / "test_tools.py").write_text(
        runner + "def test_git():\n    subprocess.run(['git', 'status'])\n\ndef test_e():\n    assert 1\n\n"
        "def test_f():\n    subprocess.run(['lit3d-eval', '--help'])\n\ndef test_g():\n    assert 1\n")
    assert process_tests(tmp_path / "unit" / "test_runs.py") == (3, 4)
    assert process_tests(tmp_path / E2E / "test_tools.py") == (1, 4)
    assert misfiled_e2e(tmp_path) == ["e2e/test_tools.py: 1 of 4 tests start a process: belongs outside e2e/",
                                      "unit/test_runs.py: 3 of 4 tests start a process: belongs in e2e/"]
