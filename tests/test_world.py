"""The SUMO adapter (libsumo, the bundled city with its flows): the vehicles round a planned
one, read from one subscription of every vehicle, are those that SUMO's own context
subscription finds."""

from __future__ import annotations

import numpy as np
from conftest import NETS, ROOT

from splineplan.sumo.world import World

RANGE = 40.0


def test_the_vehicles_around_are_sumos_context() -> None:
    """For each of the first cars to depart, taken under control at once: over 60 s, every
    step, the vehicles :meth:`World.around` gives are those within ``RANGE`` that a context
    subscription of SUMO's with the same range finds (a car within 1 m of the range's edge
    may be in one and not the other: SUMO measures to a vehicle's shape)."""
    world = World()
    world.start(["--net-file", str(NETS / "city.net.xml"),
                 "--route-files", str(ROOT / "scenarios" / "city.rou.xml"),
                 "--step-length", "0.1", "--no-step-log", "true", "--seed", "1"])
    sumo, c = world.sumo, world.c
    try:
        planned: list[str] = []
        compared = found = 0
        for _ in range(600):
            events = world.step()
            for vid in events.departed:
                if len(planned) < 6:
                    world.take_control(vid, subscribe_range=RANGE, remote=False)
                    sumo.vehicle.subscribeContext(vid, c.CMD_GET_VEHICLE_VARIABLE, RANGE,
                                                  [c.VAR_POSITION])
                    planned.append(vid)
            present = set(sumo.vehicle.getIDList())
            for vid in planned:
                if vid not in present:
                    continue
                ours = set(world.around(vid, 0.1).ids)
                theirs = set(sumo.vehicle.getContextSubscriptionResults(vid)) - {vid}
                me = np.array(sumo.vehicle.getPosition(vid))
                for other in ours ^ theirs:
                    d = float(np.hypot(*(np.array(sumo.vehicle.getPosition(other)) - me)))
                    assert abs(d - RANGE) < 1.0, (world.time, vid, other, d)
                compared += 1
                found += len(ours)
        assert compared > 1000 and found > 1000
    finally:
        world.close()


def test_a_vehicle_released_while_teleported_is_seen_when_it_is_back() -> None:
    """A car held behind a standing one jumps ahead by SUMO's teleport, past a road
    closed to cars; released from control while it is away (as a planned vehicle
    is when it fails), it is among the vehicles round another planned one once it is on
    the road again."""
    world = World()
    world.start(["--net-file", str(NETS / "straight.net.xml"),
                 "--step-length", "0.1", "--no-step-log", "true", "--seed", "1",
                 "--time-to-teleport", "2"])
    sumo = world.sumo
    try:
        sumo.route.add("r", ["e0", "e1", "e2"])
        sumo.route.add("e2", ["e2"])
        for vid, route, lane, pos in (("stuck", "r", 0, 60.0), ("watch", "e2", 2, 150.0)):
            sumo.vehicle.add(vid, route, departLane=str(lane), departPos=f"{pos:g}")
            sumo.vehicle.setStop(vid, sumo.route.getEdges(route)[0], pos=pos + 5.0,
                                 laneIndex=lane, duration=1000.0)
        sumo.vehicle.add("held", "r", departLane="0", departPos="20")
        for lane in range(3):  # no car may enter e1: the teleport passes it
            sumo.lane.setDisallowed(f"e1_{lane}", ["passenger"])
        away = back = False
        seen_back = []
        for _ in range(600):
            events = world.step()
            for vid in events.departed:
                if vid in ("held", "watch"):
                    world.take_control(vid, subscribe_range=1000.0, remote=False)
                if vid == "held":
                    sumo.vehicle.setLaneChangeMode(vid, 0)  # it stays behind "stuck"
            if "held" in events.teleported:
                away = True
                assert not world.present("held")
                world.release("held")
            if away and world.present("held"):
                back = True
                seen_back.append("held" in world.around("watch", 0.1).ids)
            if back and len(seen_back) >= 5:
                break
        assert away and back
        assert all(seen_back), seen_back
    finally:
        world.close()
