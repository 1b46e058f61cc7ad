"""Errors of the package: one base class, one subclass per failure.

Every message names what failed and where (file, edge id, station in metres), so that
the command-line tool can print it as one line.
"""

from __future__ import annotations

import math
from numbers import Real


class SplineplanError(Exception):
    """Base class of every error raised by splineplan."""


class ParameterError(SplineplanError, ValueError):
    """A parameter is out of its physical or allowed range."""


class NetworkError(SplineplanError):
    """A network file is missing, unreadable or not a SUMO network."""


class UnknownEdgeError(SplineplanError, KeyError):
    """An edge id is not in the network."""

    def __str__(self) -> str:  # KeyError would quote the message
        return str(self.args[0]) if self.args else ""


class VehicleClassError(SplineplanError):
    """The vehicle class is unknown or may not use the edges asked for."""


class NoRouteError(SplineplanError):
    """No road route leads from the origin to the destination."""


class GeometryError(SplineplanError):
    """Geometry is malformed: a degenerate corridor, a bad polygon, a pose off the road."""


class RoadBlockedError(SplineplanError):
    """Level 2 found no passage through a road segment.

    Attributes
    ----------
    station
        Station [m] on the whole route (the segment's ``offset`` added) of the first sweep
        line that no path reaches.
    edge
        Id of the SUMO edge at that station, where the corridor knows it (else ``None``).
    junction
        The route edges ``(from, to)`` when the station lies in the junction between them:
        then the turn onto ``to`` is what is closed (else ``None``).
    """

    def __init__(self, message: str, *, station: float, edge: str | None = None,
                 junction: tuple[str, str] | None = None) -> None:
        super().__init__(message)
        self.station = station
        self.edge = edge
        self.junction = junction

    @property
    def closed_edge(self) -> str | None:
        """The edge a new road selection should avoid: the one entered through the closed
        junction, else the closed edge itself."""
        return self.junction[1] if self.junction is not None else self.edge


class TrajectoryError(SplineplanError):
    """Level 3 could not build a trajectory (too few points, infeasible start)."""


class ScenarioError(SplineplanError):
    """A scenario file is malformed: unknown key, missing file, bad value."""


class SimulationError(SplineplanError):
    """SUMO failed to start, or the simulation could not go on."""


class OutputError(SplineplanError):
    """An output file or folder cannot be written (a file where a folder is wanted, no
    permission, an unknown picture format)."""


def require_positive(name: str, value: object) -> None:
    """Raise :class:`ParameterError` unless ``value`` is a finite number above 0."""
    x = _number(name, value)
    if x <= 0:
        raise ParameterError(f"{name} must be positive, got {value!r}")


def require_non_negative(name: str, value: object) -> None:
    """Raise :class:`ParameterError` unless ``value`` is a finite number, 0 or above."""
    x = _number(name, value)
    if x < 0:
        raise ParameterError(f"{name} must be >= 0, got {value!r}")


def _number(name: str, value: object) -> float:
    """``value`` as a float, or a :class:`ParameterError` that says it must be a (finite)
    number: a string or a list is not "below 0", it is not a number at all."""
    x = _finite(value)
    if x is None:
        if isinstance(value, Real) and not isinstance(value, bool):
            raise ParameterError(f"{name} must be a finite number, got {value!r}")
        raise ParameterError(f"{name} must be a number, got {value!r}")
    return x


def _finite(value: object) -> float | None:
    """``value`` as a float if it is a finite number (Python's or numpy's ints and floats,
    not bools, which are ints to Python), else ``None``."""
    if isinstance(value, Real) and not isinstance(value, bool) and math.isfinite(value):
        return float(value)
    return None


class Interrupted(KeyboardInterrupt):
    """The user stopped a run (Ctrl-C, SIGINT); what it had done is written out.

    Not a failure of the package, so not a :class:`SplineplanError`: a
    :class:`KeyboardInterrupt`, so that code that does not know it stops as for any Ctrl-C.

    Attributes
    ----------
    result
        What the run returns when it ends normally, holding what was done up to the
        interruption (a :class:`~splineplan.sim.SimResult` or a
        :class:`~splineplan.bench.BenchResult`).
    """

    def __init__(self, message: str, result: object = None) -> None:
        super().__init__(message)
        self.result = result

    def __str__(self) -> str:
        return str(self.args[0]) if self.args else ""
