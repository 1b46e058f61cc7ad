"""Shared fixtures: paths of the bundled networks and of the optional shared data."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
from hypothesis import settings

# The fast suite draws the same examples on every run, so that the same code gets the same
# verdict; HYPOTHESIS_PROFILE=explore draws new ones (``tox -e explore``, and the slow runs).
settings.register_profile("repeatable", derandomize=True)
settings.register_profile("explore", derandomize=False)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "repeatable"))
# commonroad-io before 2026 ships protobuf 3 code, which newer protobuf releases load only
# with their pure-Python implementation (splineplan.commonroad chooses it too)
os.environ.setdefault("PROTOCOL_BUFFERS_PYTHON_IMPLEMENTATION", "python")

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


#: Routes on grid.net.xml through each kind of junction turn: right, left, right, a
#: corner of the grid with turns, and a longer route with several turns.
GRID_TURNS = [("A1B1", "B1B0"), ("B0C0", "C0C1"), ("C0C1", "C1D1"), ("C2C1", "C2B2"),
              ("B1C1", "C2D2")]
#: Routes through the grid's outer corners, where two edges meet at a sharp inner corner
#: with no junction area to round it.
GRID_CORNERS = [("C3D3", "B1A1"), ("A2A3", "D0D1")]


def winding_line(rng: np.random.Generator, m: int
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A random winding line of ``m`` points (origins ``(m, 2)``, unit normals ``(m, 2)``)
    and random centre offsets ``(m,)`` along the normals: a control polygon's sweep lines."""
    heading = np.cumsum(rng.normal(0.0, 0.3, m))
    step = rng.uniform(0.3, 3.0, m)
    origin = np.column_stack((np.cumsum(step * np.cos(heading)),
                              np.cumsum(step * np.sin(heading))))
    normal = np.column_stack((-np.sin(heading), np.cos(heading)))
    return origin, normal, rng.uniform(-1.0, 1.0, m)
