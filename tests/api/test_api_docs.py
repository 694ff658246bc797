"""docs/api.md's examples are doctests: they run here, so the page shows what the code does."""
from __future__ import annotations

import doctest
import tempfile

import pytest
from tests.helpers.paths import REPO

PAGE = REPO / "docs" / "api.md"

pytestmark = pytest.mark.usefixtures("one_torch_thread")


def test_api_page_examples_run(tmp_path, monkeypatch):
    monkeypatch.setenv("LIT3D_CACHE", str(tmp_path / "cache"))
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))  # the page's tempfile.mkdtemp() lands here
    result = doctest.testfile(str(PAGE), module_relative=False, report=True,
                              optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    assert result.attempted >= 30, result  # the page still holds its examples
    assert result.failed == 0, f"{result.failed} of {result.attempted} examples in {PAGE} failed (output above)"
