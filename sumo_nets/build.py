#!/usr/bin/env python3
"""Rebuild every bundled network from its sources with SUMO's netconvert and netgenerate.

Usage: ``python sumo_nets/build.py`` (needs ``netconvert`` and ``netgenerate`` on PATH,
e.g. from ``pip install eclipse-sumo``). All networks are built without turnarounds.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent

#: Options shared by every network.
COMMON = ["--no-turnarounds", "true", "--default.lanewidth", "3.2"]

COMMANDS: dict[str, list[str]] = {
    "straight.net.xml": [
        "netconvert", "--node-files", "straight.nod.xml", "--edge-files", "straight.edg.xml",
    ],
    "grid.net.xml": [
        "netgenerate", "--grid", "--grid.number", "4", "--grid.length", "150",
        "--default.lanenumber", "2", "--default.speed", "13.89",
    ],
    "curved.net.xml": [
        "netconvert", "--node-files", "curved.nod.xml", "--edge-files", "curved.edg.xml",
    ],
    "city.net.xml": [
        "netconvert", "--node-files", "city.nod.xml", "--edge-files", "city.edg.xml",
        "--connection-files", "city.con.xml", "--tls.default-type", "static",
    ],
}


def main() -> int:
    for out, cmd in COMMANDS.items():
        full = [*cmd, *COMMON, "--output-file", out]
        print(" ".join(full), flush=True)
        subprocess.run(full, cwd=HERE, check=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
