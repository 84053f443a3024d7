"""Shared fixtures: the real drum frames that ship with the tests (``tests/data``)."""

from __future__ import annotations

from pathlib import Path

import pytest

TESTS = Path(__file__).resolve().parent
REPO = TESTS.parent
TEST_DATA = TESTS / "data"


@pytest.fixture(scope="session")
def real_drum_dir() -> Path:
    """Folder of the real blue/white PMMA drum frames and their YOLO labels
    (CC BY 4.0, T. Delorenzi; see ``tests/data/real-drum-pmma/README.md``)."""
    path = TEST_DATA / "real-drum-pmma"
    if not path.is_dir():
        raise FileNotFoundError(f"test data missing: {path}")
    return path
