"""Shared fixtures: where the real drum frames live (``../shared/data``)."""

from __future__ import annotations

from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED_DATA = REPO.parent / "shared" / "data"


@pytest.fixture(scope="session")
def real_drum_dir() -> Path:
    """Folder of the real blue/white PMMA drum frames and their YOLO labels."""
    path = SHARED_DATA / "real-drum-pmma"
    if not path.is_dir():
        raise FileNotFoundError(f"shared data missing: {path} (clone with ../shared beside the repo)")
    return path
