"""Which of a SUMO scenario's own vehicles the planner drives.

By id (``--vehicles``), by vehicle type (``--vtype``) or a seeded share of the passenger
vehicles as they depart (``--share``, ``--seed``). Ids and types are checked against the
route files before SUMO starts, so that a typo costs no simulation.
"""

from __future__ import annotations

import gzip
import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from splineplan.errors import ParameterError, ScenarioError

#: SUMO's built-in vehicle types (always known).
_BUILTIN_TYPES = frozenset({"DEFAULT_VEHTYPE", "DEFAULT_PEDTYPE", "DEFAULT_BIKETYPE",
                            "DEFAULT_CONTAINERTYPE", "DEFAULT_TAXITYPE", "DEFAULT_RAILTYPE"})


@dataclass(frozen=True)
class Selection:
    """The planned vehicles of a SUMO scenario.

    Attributes
    ----------
    vehicles
        Vehicle ids (a flow's vehicles are ``<flow id>.<n>``).
    vtype
        Every vehicle of this type.
    share
        Fraction [0, 1] of the departing passenger vehicles, drawn with ``seed``.
    seed
        Seed of that draw.
    """

    vehicles: tuple[str, ...] = ()
    vtype: str | None = None
    share: float = 0.0
    seed: int = 0

    def __post_init__(self) -> None:
        if (isinstance(self.share, bool) or not isinstance(self.share, int | float)
                or not math.isfinite(self.share) or not 0.0 <= self.share <= 1.0):
            raise ParameterError(f"--share must be a fraction between 0 and 1, "
                                 f"got {self.share!r}")
        if isinstance(self.seed, bool) or not isinstance(self.seed, int) or self.seed < 0:
            raise ParameterError(f"--seed must be an integer >= 0, got {self.seed!r}")

    @property
    def empty(self) -> bool:
        """Whether no vehicle can be chosen."""
        return not self.vehicles and self.vtype is None and self.share <= 0.0

    def check(self, route_files: tuple[Path, ...]) -> None:
        """Unknown ids or type are a :class:`ScenarioError` naming them."""
        if not self.vehicles and self.vtype is None:
            return
        ids, flows, types = _declared(route_files)
        names = ", ".join(p.name for p in route_files) or "no route file"
        for vid in self.vehicles:
            if vid in ids or vid.rsplit(".", 1)[0] in flows:
                continue
            raise ScenarioError(f"unknown vehicle id '{vid}': no vehicle, trip or flow of "
                                f"that id in {names}")
        if self.vtype is not None and self.vtype not in types | _BUILTIN_TYPES:
            raise ScenarioError(f"unknown vehicle type '{self.vtype}': no vType of that id "
                                f"in {names}")


class Picker:
    """Decides, as each vehicle departs, whether the planner drives it (the draw is made
    in SUMO's order of departure, so a seed gives the same vehicles every run)."""

    def __init__(self, selection: Selection) -> None:
        self.sel = selection
        self.rng = np.random.default_rng(selection.seed)
        self._ids = frozenset(selection.vehicles)

    def picks(self, vid: str, type_id: str, vclass: str) -> bool:
        """Whether vehicle ``vid`` of type ``type_id`` and class ``vclass`` is planned."""
        sel = self.sel
        if vid in self._ids or (sel.vtype is not None and type_id == sel.vtype):
            return True
        if sel.share > 0.0 and vclass == "passenger":
            return bool(self.rng.random() < sel.share)
        return False


def _declared(route_files: tuple[Path, ...]) -> tuple[set[str], set[str], set[str]]:
    """Vehicle and trip ids, flow ids and vType ids declared in route files."""
    ids: set[str] = set()
    flows: set[str] = set()
    types: set[str] = set()
    for path in route_files:
        try:
            opener = gzip.open if str(path).endswith(".gz") else open
            with opener(path, "rb") as fh:
                for _, el in ET.iterparse(fh):
                    tag, vid = el.tag, el.get("id")
                    if vid is not None:
                        if tag in ("vehicle", "trip"):
                            ids.add(vid)
                        elif tag == "flow":
                            flows.add(vid)
                        elif tag == "vType":
                            types.add(vid)
                    if tag in ("vehicle", "trip", "flow"):
                        el.clear()
        except (OSError, ET.ParseError) as err:
            raise ScenarioError(f"route file {path} is not readable XML: {err}") from err
    return ids, flows, types
