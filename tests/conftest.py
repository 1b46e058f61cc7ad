"""Shared fixtures: paths of the bundled networks and of the optional shared data."""

from __future__ import annotations

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
NETS = ROOT / "sumo_nets"
SHARED_DATA = ROOT.parent / "shared" / "data"
MONACO = SHARED_DATA / "monaco.net.xml.gz"


@pytest.fixture(scope="session")
def monaco_net() -> Path:
    """The Monaco network of ../shared/data, or a skip where that folder is absent."""
    if not MONACO.exists():
        pytest.skip(f"Monaco network not found at {MONACO} (../shared/data is absent)")
    return MONACO
