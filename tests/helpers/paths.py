"""Where the tests find things, wherever a test file sits under ``tests/``: the checkout (REPO), the
tests' folder (TESTS) and committed fixtures (FIXTURES), and the developers' data folder beside the
checkout (SHARED_DATA, ``../shared/data``; a user's clone has none, and the tests that read it skip)."""
from __future__ import annotations

from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
TESTS = REPO / "tests"
FIXTURES = TESTS / "fixtures"
SHARED_DATA = REPO.parent / "shared" / "data"
