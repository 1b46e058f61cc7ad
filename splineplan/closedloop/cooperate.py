"""Cooperation of planned vehicles, the prioritised scheme.

Every planned vehicle publishes its trajectory in space and time
(:func:`splineplan.spacetime.published`) each time it plans. Vehicles have priorities, in
the order they entered the simulation: a vehicle treats the published plans of those
before it as moving obstacles (:func:`among_plans`): it keeps its path and changes its
speed profile first (:func:`splineplan.spacetime.retime`: pass in front where the limits
allow, else yield), and plans its path again (levels 2 and 3) around the other's swept
rectangles (:meth:`splineplan.spacetime.Conflict.as_static`) where speed alone cannot keep
the margin. A fixed order keeps two vehicles from each waiting for the other; vehicles later
in the order are still seen as SUMO sees them (time gap, traffic beside, junction foes).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, replace

import numpy as np

from splineplan import kernels
from splineplan.geometry import FloatArray, kernel_floats
from splineplan.spacetime import MovingObstacle, box_gap

#: Seconds between replans while a vehicle waits for another's published plan.
WAIT_REPLAN = 1.0
#: How far [m] beyond a path's bounding box another plan counts as near it.
NEAR = 10.0
#: A plan meeting the path at more than this angle [rad] crosses it (or comes the other way).
CROSSING = math.radians(30.0)
#: Time step [s] and horizon [s] of the check of a plan against others' new plans.
CHECK_STEP = 0.2
CHECK_HORIZON = 15.0


@dataclass(frozen=True)
class Published:
    """One planned vehicle's latest plan on the board: its priority (lower goes first), its
    trajectory in space and time, and the board's count of plans published when it came."""

    priority: int
    plan: MovingObstacle
    seq: int = 0

    @property
    def box(self) -> tuple[FloatArray, FloatArray]:
        """The plan's bounding box: lowest and highest x, y [m] (computed once)."""
        cached = self.__dict__.get("_box")
        if cached is None:
            cached = (np.min(self.plan.xy, axis=0), np.max(self.plan.xy, axis=0))
            object.__setattr__(self, "_box", cached)
        return cached


def plans_before(board: Mapping[str, Published], me: str, priority: int, xy: FloatArray,
                 heading: FloatArray, t0: float, *, pad: float = 0.0, after: int = -1,
                 released: Mapping[str, float] | None = None) -> list[MovingObstacle]:
    """The published plans of the vehicles before ``me`` in priority that are still to
    come (after ``t0`` [s]) and come within :data:`NEAR` of the path ``xy`` ``(n, 2)``
    (headings ``(n,)`` [rad]).

    A plan that crosses the path or comes the other way (more than :data:`CROSSING` from
    the path's heading where they meet) is grown by ``pad`` [m] on every side: the vehicle
    is to wait that far from it (the time-gap control's standstill distance), not only the
    safety margin; plans along the path are not, so that two vehicles may drive side by
    side. ``after``: only plans published after the board's count was that.
    ``released``: vehicles whose plans are left out until the time [s] given (a wait
    released from a deadlock, :func:`waits_in_cycle`).
    """
    if not board or not len(xy):
        return []
    lo = np.min(xy, axis=0) - NEAR
    hi = np.max(xy, axis=0) + NEAR
    out = []
    for vid, pub in board.items():
        if vid == me or pub.priority >= priority or pub.seq <= after:
            continue
        if released and released.get(vid, -math.inf) > t0:
            continue
        p = pub.plan
        if p.t[-1] < t0 and not p.stays:
            continue
        b_lo, b_hi = pub.box
        if (b_lo > hi).any() or (b_hi < lo).any():
            continue
        inside = np.all((p.xy >= lo) & (p.xy <= hi), axis=1)
        if not inside.any():
            continue
        if pad > 0.0 and _crosses(p, xy, heading, inside, (b_lo, b_hi)):
            p = replace(p, length=p.length + 2.0 * pad, width=p.width + 2.0 * pad)
        out.append(p)
    return out


def waits_in_cycle(holds: Mapping[str, tuple[str, ...]], start: str) -> list[str] | None:
    """A cycle of standing vehicles each held by the next, from ``start`` round to the one
    that holds ``start`` (``start`` first), or ``None``.

    ``holds``: for each standing vehicle, the vehicles that hold it back (its speed
    control's reason). Planned vehicles that wait for each other this way, one for
    another's published plan and that one for a gap the first stands in, stand for
    ever: the run releases such a wait (:class:`~.run._Run`)."""
    path = [start]
    seen = {start}

    def search(v: str) -> list[str] | None:
        for w in holds.get(v, ()):
            if w == start:
                return list(path)
            if w in seen or w not in holds:
                continue
            seen.add(w)
            path.append(w)
            found = search(w)
            if found is not None:
                return found
            path.pop()
        return None

    return search(start)


def _crosses(plan: MovingObstacle, xy: FloatArray, heading: FloatArray,
             inside: np.ndarray, box: tuple[FloatArray, FloatArray]) -> bool:
    """Whether a plan meets the path (within :data:`NEAR`) at more than :data:`CROSSING`
    from the path's heading.

    Only the plan's points ``inside`` the path's bounding box grown by :data:`NEAR`, and
    the path's points inside the plan's bounding ``box`` grown by it, can meet."""
    lo, hi = box[0] - NEAR, box[1] + NEAR
    return bool(kernels.crosses(kernel_floats(plan.xy), kernel_floats(plan.heading),
                                np.ascontiguousarray(inside, dtype=bool), kernel_floats(xy),
                                kernel_floats(heading), float(lo[0]), float(lo[1]),
                                float(hi[0]), float(hi[1]), NEAR, CROSSING))


def keeps_clear_of(mine: MovingObstacle, others: list[MovingObstacle], t0: float, *,
                   margin: float) -> bool:
    """Whether the plan ``mine`` keeps ``margin`` [m] from each of ``others`` at every
    :data:`CHECK_STEP` from ``t0`` [s] while both are on the road, up to
    :data:`CHECK_HORIZON` (``mine`` stays at its last pose after its end: the vehicle
    stands there until it plans again).

    A vehicle whose plan keeps clear of others' new plans need not plan again among them.
    """
    stay = MovingObstacle(mine.id, mine.t, mine.xy, mine.heading, mine.length, mine.width,
                          stays=True)
    for p in others:
        t_end = p.t[-1] if not p.stays else max(p.t[-1], mine.t[-1])
        t1 = min(max(t_end, t0), t0 + CHECK_HORIZON)
        tt = np.arange(max(t0, p.t[0]), t1 + CHECK_STEP / 2.0, CHECK_STEP)
        if not len(tt):
            continue
        xy1, h1, in1 = stay.at(tt)
        xy2, h2, in2 = p.at(tt)
        both = in1 & in2
        # only where the bounding circles come within the margin can the boxes
        reach = 0.5 * (math.hypot(stay.length, stay.width) + math.hypot(p.length, p.width))
        both &= np.hypot(xy1[:, 0] - xy2[:, 0], xy1[:, 1] - xy2[:, 1]) < reach + margin
        if not both.any():
            continue
        gap = box_gap(xy1[both], h1[both], (stay.length, stay.width), xy2[both], h2[both],
                      (p.length, p.width))
        if float(gap.min()) < margin:
            return False
    return True
