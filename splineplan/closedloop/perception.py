"""Perception of one planned vehicle: what its surroundings mean for its plan.

From the vehicles around it (:class:`~splineplan.traffic.Others`, read by the run from
SUMO) and the route's corridor: its clearances and collisions (our own footprint check),
whether it is on the road, where it is on its route (a local projection), the stopped
vehicles and obstacle polygons ahead within the look-ahead (obstacles for level 2), and the
moving vehicles beside it (swept footprints for level 2, and the check for one coming near
the plan). No SUMO calls.
"""

from __future__ import annotations

import bisect
import math

import numpy as np

from splineplan.closedloop._state import DriverState
from splineplan.geometry import FloatArray, wrap_angle
from splineplan.metrics import footprints, rectangle_distances
from splineplan.obstacles import Obstacles
from splineplan.traffic import probe_points

#: A moving vehicle whose centre is at least this far [m] to the side of the ego's centre
#: (across the route) is *beside* the ego, not ahead in its path: level 2 and 3 plan around
#: where it goes in the next :data:`SWEEP_TIME` (its swept footprint), so that the ego keeps
#: a lateral separation from it; a vehicle within it is handled by speed (time gap).
BESIDE_LATERAL = 1.0
#: Horizon [s] of a beside vehicle's swept footprint (constant speed along the route).
SWEEP_TIME = 2.0
#: Stations [m] behind and ahead of the ego's centre within which vehicles count as beside.
_BESIDE_BACK = 15.0
_BESIDE_AHEAD = 40.0
#: A swept footprint starts at least this far [m], and this many seconds at the ego's speed,
#: ahead of the ego's front bumper.
_SWEEP_CLIP = 3.0
_SWEEP_CLIP_TIME = 1.0
#: Prediction times [s] of the check for a beside vehicle coming near the planned path.
_CONFLICT_TIMES: tuple[float, ...] = tuple(0.5 * k for k in range(7))
#: Longitudinal slack [m] of that check.
_CONFLICT_SLACK = 1.0
#: A vehicle that has held the ego standing inside a junction this long [s], standing
#: itself across the ego's way (heading more than :data:`BLOCKER_TURN` away), is planned
#: round as a stopped one: each may wait for the other for good (SUMO's drivers wait at
#: an internal junction with their front in the crossing lane).
BLOCKED_AFTER = 5.0
BLOCKER_TURN = math.radians(30.0)
#: Slower than this [m/s] is standing (a vehicle, and the ego for the deadlock watch).
STANDING_SPEED = 0.1


class Perception(DriverState):
    """The perception half of a :class:`~splineplan.closedloop.driver.Driver` (a mixin:
    the methods read and cache on the driver's state)."""

    def _safety(self, x: float, y: float, h: float) -> tuple[float, float, bool]:
        """Clearance [m] to stopped and to moving vehicles (and obstacle polygons), collisions
        (recorded), and whether the ego's footprint leaves the road.

        Every vehicle around the ego is checked: a lower bound of its distance from its
        bounding circle (one array pass), the exact footprint distance where that comes
        within 2 m.
        """
        ego, o = self.sc.ego, self.others
        # corners, centre and edge midpoints; the centre is not needed by the road check
        pts = probe_points(x, y, math.cos(h), math.sin(h), ego.length / 2.0, ego.width / 2.0)
        corners = pts[:4]
        clear_obs = clear_veh = math.inf
        r_ego = 0.5 * math.hypot(ego.length, ego.width)
        if o.n:
            dist = np.hypot(o.cx - x, o.cy - y) - (o.radius + r_ego)
            close = np.flatnonzero(dist < 2.0)
            if len(close):
                dist[close] = rectangle_distances(
                    (x, y), h, ego.length, ego.width, np.column_stack((o.cx[close],
                                                                     o.cy[close])),
                    o.head[close], o.length[close], o.width[close])
                for j in close[dist[close] <= 0.0]:
                    self.collisions.append({"time": self.time, "other": o.ids[j],
                                            "other_stopped": bool(o.stopped[j]),
                                            "source": "footprint"})
            if o.n_stopped:
                clear_obs = float(dist[o.stopped].min())
            if o.n_stopped < o.n:
                clear_veh = float(dist[~o.stopped].min() if o.n_stopped else dist.min())
        if len(self.polygons):
            ego_box = np.array(corners)
            near = self.polygons.near(ego_box, self.sc.sim.lookahead)
            if len(near):
                clear_obs = min(clear_obs, float(near.distance(ego_box).min()))
        probe = corners + pts[5:]
        off_road = not self.road.contains_all(probe, centre=(x, y), radius=r_ego)
        return clear_obs, clear_veh, off_road

    def _project(self, xy: FloatArray, *, back: float = 10.0, ahead: float = 20.0
                 ) -> FloatArray:
        """Stations and lateral offsets ``(k, 2)`` of points ``(k, 2)`` (or ``(2,)`` of one
        point ``(2,)``) near the ego.

        A local search over the corridor's reference segments from ``back`` [m] behind to
        ``ahead`` [m] ahead of the ego's last station (the ego moves a few decimetres a
        step); a full projection (:meth:`Corridor.to_sl`) for points whose nearest segment
        is at the window's edge.
        """
        c = self.corridor
        assert c is not None
        pts = np.asarray(xy, dtype=float)
        one = pts.ndim == 1
        pts = pts.reshape(-1, 2)
        s = c.s
        nseg = len(s) - 1
        lo = max(bisect.bisect_left(self._ref_s, self.station - back) - 1, 0)
        hi = min(bisect.bisect_left(self._ref_s, self.station + ahead) + 1, nseg)
        if hi <= lo:
            out = np.asarray(c.to_sl(pts))
            return out[0] if one else out
        cols = self._ref_cols
        ax, ay, abx, aby, len2 = (cols[0][lo:hi], cols[1][lo:hi], cols[2][lo:hi],
                                  cols[3][lo:hi], cols[4][lo:hi])
        if one:  # one point: the same arithmetic on (n,) rows, then plain floats
            px, py = float(pts[0, 0]), float(pts[0, 1])
            dx1 = px - ax
            dy1 = py - ay
            t1 = np.minimum(np.maximum((dx1 * abx + dy1 * aby) / len2, 0.0), 1.0)
            ex1 = dx1 - t1 * abx
            ey1 = dy1 - t1 * aby
            k1 = int(np.argmin(ex1 * ex1 + ey1 * ey1))
            if (k1 == 0 and lo > 0) or (k1 == hi - lo - 1 and hi < nseg):
                return np.asarray(c.to_sl(pts))[0]
            ln1 = float(self._ref_len[lo + k1])
            return np.array([float(s[lo + k1]) + float(t1[k1]) * ln1,
                             (float(abx[k1]) * float(dy1[k1]) - float(aby[k1])
                              * float(dx1[k1])) / ln1])
        dx = pts[:, 0, None] - ax  # (k, n)
        dy = pts[:, 1, None] - ay
        t = np.minimum(np.maximum((dx * abx + dy * aby) / len2, 0.0), 1.0)
        ex = dx - t * abx
        ey = dy - t * aby
        k = np.argmin(ex * ex + ey * ey, axis=1)
        r = np.arange(len(pts))
        ln = self._ref_len[lo + k]
        out = np.column_stack((s[lo + k] + t[r, k] * ln,
                               (abx[k] * dy[r, k] - aby[k] * dx[r, k]) / ln))
        edge = ((k == 0) & (lo > 0)) | ((k == hi - lo - 1) & (hi < nseg))
        if edge.any():
            out[edge] = c.to_sl(pts[edge])
        return out[0] if one else out

    def _edge_at(self, station: float) -> str:
        """:meth:`Corridor.edge_at` of the route's corridor (``""`` for none), on a list."""
        assert self.corridor is not None
        edges = self.corridor.edges
        if not edges:
            return ""
        return edges[max(bisect.bisect_right(self._edge_starts, station) - 1, 0)] or ""

    # -- obstacles ahead ----------------------------------------------------------------------
    def _ahead(self) -> tuple[np.ndarray, np.ndarray]:
        """Indices of the stopped vehicles (in ``self.others``) and of the obstacle polygons
        near the route within the look-ahead.

        Where an obstacle lies on the route is computed once per obstacle and position (a
        stopped vehicle does not move) and route.
        """
        o = self.others
        sim, ego = self.sc.sim, self.sc.ego
        lo = self.station - ego.length - 5.0
        assert self.corridor is not None
        hi = min(self.station + sim.lookahead, self.corridor.length) + 5.0
        veh = np.flatnonzero(o.stopped) if o.n_stopped else np.zeros(0, dtype=np.int64)
        blockers = self._blockers()
        if blockers:
            veh = np.union1d(veh, blockers)
        keep_v = []
        for i in veh:
            fx, fy = o.front[i]
            key = (o.ids[i], round(float(fx), 1), round(float(fy), 1))
            where = self._obs_cache.get(key)
            if where is None:
                box = footprints(o.front[i:i + 1], o.head[i:i + 1], o.length[i:i + 1],
                                 o.width[i:i + 1])[0]
                where = self._on_route(box)
                self._obs_cache[key] = where
            if where[2] and where[1] >= lo and where[0] <= hi:
                keep_v.append(i)
        keep_p: list[int] = []
        for j in range(len(self.polygons)):
            key = (f"polygon:{j}", 0.0, 0.0)
            where = self._obs_cache.get(key)
            if where is None:
                where = self._on_route(self.polygons.polygon(j))
                self._obs_cache[key] = where
            if where[2] and where[1] >= lo and where[0] <= hi:
                keep_p.append(j)
        return np.asarray(keep_v, dtype=np.int64), np.asarray(keep_p, dtype=np.int64)

    def _blockers(self) -> list[int]:
        """The vehicles (indices in ``self.others``) that hold the ego standing inside a
        junction for :data:`BLOCKED_AFTER` or longer and stand across its way themselves
        (their heading more than :data:`BLOCKER_TURN` from the ego's): obstacles for
        level 2 as stopped ones are."""
        if (self.stand_since is None or self.time - self.stand_since < BLOCKED_AFTER
                or not self.slowed_by or not self.last_lane.startswith(":")):
            return []
        o = self.others
        found = []
        for vid in self.slowed_by:
            try:
                j = o.ids.index(vid)
            except ValueError:
                continue
            turn = abs(wrap_angle(float(o.head[j]) - float(self.pose[2])))
            if o.speed[j] < STANDING_SPEED and turn > BLOCKER_TURN:
                found.append(j)
        return found

    def _on_route(self, poly: FloatArray) -> tuple[float, float, bool]:
        """Station range [m] of a polygon on the route, and whether it is within 1 m of the
        drivable area laterally."""
        assert self.corridor is not None
        sl = self.corridor.to_sl(poly)
        r, lft = self.corridor.bounds_at(np.clip(sl[:, 0], 0.0, self.corridor.length))
        lateral = bool((sl[:, 1].max() >= r.min() - 1.0) and (sl[:, 1].min() <= lft.max() + 1.0))
        return float(sl[:, 0].min()), float(sl[:, 0].max()), lateral

    def _ahead_ids(self, veh: np.ndarray, poly: np.ndarray) -> set[str]:
        if not len(veh) and not len(poly):
            return set()
        ids = self.others.ids
        return {ids[i] for i in veh} | {self.polygons.ids[j] for j in poly}

    def _obstacles_ahead(self, ahead: tuple[np.ndarray, np.ndarray] | None = None
                         ) -> Obstacles:
        """Stopped vehicles and obstacle polygons near the route within the look-ahead."""
        veh, poly = self._ahead() if ahead is None else ahead
        o = self.others
        obs = Obstacles.empty()
        if len(veh):
            obs = Obstacles.from_boxes(o.front[veh], o.head[veh], o.length[veh], o.width[veh],
                                       reference="front", ids=[o.ids[i] for i in veh])
        if len(poly):
            obs = obs + self.polygons.subset(poly)
        return obs

    def _beside(self) -> tuple[np.ndarray, FloatArray]:
        """Moving vehicles beside the ego: indices into ``self.others`` and their centres'
        station and lateral offset ``(k, 2)`` on the route.

        Beside: not stopped, driving the route's way (within 45 degrees), on the route's
        road, between :data:`_BESIDE_BACK` behind and :data:`_BESIDE_AHEAD` ahead of the
        ego's centre, and at least :data:`BESIDE_LATERAL` to its side.
        """
        o = self.others
        if not o.n or self.corridor is None:
            return np.zeros(0, dtype=np.int64), np.zeros((0, 2))
        if self._beside_at == (self.time, self.station):
            return self._beside_was
        self._beside_at = (self.time, self.station)
        self._beside_was = self._beside_now()
        return self._beside_was

    def _beside_now(self) -> tuple[np.ndarray, FloatArray]:
        o = self.others
        assert self.corridor is not None
        picked = self._beside_candidates()
        if not picked:
            return np.zeros(0, dtype=np.int64), np.zeros((0, 2))
        cand = np.asarray(picked, dtype=np.int64)
        c = self.corridor
        sl = self._project(np.column_stack((o.cx[cand], o.cy[cand])),
                           back=_BESIDE_BACK + 15.0, ahead=_BESIDE_AHEAD + 15.0)
        s_in = np.minimum(np.maximum(sl[:, 0], 0.0), c.length)
        right, left = c.bounds_at(s_in)
        seg = np.minimum(np.searchsorted(c.s, s_in, side="right") - 1, len(c.s) - 2)
        along = np.cos(o.head[cand] - self._ref_heading[seg]) > math.cos(math.pi / 4.0)
        keep = (along & (sl[:, 0] >= self.station - _BESIDE_BACK)
                & (sl[:, 0] <= self.station + _BESIDE_AHEAD)
                & (sl[:, 1] >= right - 0.5) & (sl[:, 1] <= left + 0.5)
                & (np.abs(sl[:, 1] - self.lateral) >= BESIDE_LATERAL))
        return cand[keep], sl[keep]

    def _beside_candidates(self) -> list[int]:
        """Increasing indices into ``self.others`` of the vehicles that may be beside the ego
        (:meth:`_beside`): a cheap first cut in the ego's own frame, a superset of those
        beside, before projecting onto the route. Cached per time and station."""
        if self._cand_at == (self.time, self.station):
            return self._cand_was
        o = self.others
        x, y, h = (float(v) for v in self.pose)
        ch, sh = math.cos(h), math.sin(h)
        window = self._route_window()
        cos_min = math.nan  # computed once a vehicle needs it
        picked = []
        # plain floats: a few vehicles
        for i, (cx, cy, co, si, stopped) in enumerate(zip(
                o.cx.tolist(), o.cy.tolist(), o.cos.tolist(), o.sin.tolist(),
                o.stopped.tolist(), strict=True)):
            if stopped:
                continue
            dx, dy = cx - x, cy - y
            lon = dx * ch + dy * sh
            lat = abs(dy * ch - dx * sh)
            if not (-_BESIDE_BACK - 5.0 < lon < _BESIDE_AHEAD + 5.0
                    and BESIDE_LATERAL - 0.5 < lat < 10.0):
                continue
            if math.isnan(cos_min):
                # a vehicle heading more than 45 degrees plus the route's largest turn away
                # from the ego's heading (within the beside stations) cannot drive the
                # route's way
                cos_min = math.cos(min(math.pi / 4.0 + self._route_turn(h, window), math.pi))
            if co * ch + si * sh >= cos_min - 1e-9:
                picked.append(i)
        self._cand_at = (self.time, self.station)
        self._cand_was = picked
        return picked

    def _route_window(self) -> FloatArray:
        """Headings [rad] of the route's segments from a metre before :data:`_BESIDE_BACK`
        behind the ego's station to a metre after :data:`_BESIDE_AHEAD` ahead (the window
        moves on once the ego has driven a metre)."""
        c = self.corridor
        assert c is not None
        key = self._turn_key
        if key is None or key[0] is not c or abs(self.station - key[1]) > 1.0:
            lo = max(int(np.searchsorted(c.s, self.station - _BESIDE_BACK - 2.0)) - 1, 0)
            hi = int(np.searchsorted(c.s, self.station + _BESIDE_AHEAD + 2.0)) + 1
            self._turn_window = self._ref_heading[lo:hi]
            self._turn_key = (c, self.station)
        return self._turn_window

    @staticmethod
    def _route_turn(h: float, window: FloatArray) -> float:
        """Largest angle [rad] between a heading ``h`` and the headings ``window``
        (:meth:`_route_window`)."""
        d = np.abs(np.mod(window - h + math.pi, 2.0 * math.pi) - math.pi)
        return float(d.max()) if len(d) else math.pi

    def _moving_obstacles(self) -> Obstacles:
        """Swept footprints of the moving vehicles beside the ego (:meth:`_beside`).

        Each is the band of the vehicle's width at its lateral offset on the route, from its
        rear to where its front will be after :data:`SWEEP_TIME` at its speed, following the
        road; it starts some way ahead of the ego's front bumper (:data:`_SWEEP_CLIP`; the
        ego cannot leave the place it is in, and a plan that starts inside an obstacle
        would be refused).
        """
        idx, sl = self._beside()
        if not len(idx):
            return Obstacles.empty()
        assert self.corridor is not None
        c, ego = self.corridor, self.sc.ego
        o = self.others
        ids, lens, wids, speeds = o.ids, o.length, o.width, o.speed
        clip = self.station + ego.length / 2.0 + max(_SWEEP_CLIP, self.v * _SWEEP_CLIP_TIME)
        polys, names = [], []
        for j, i in enumerate(idx):
            s_c, l_c = float(sl[j, 0]), float(sl[j, 1])
            s_lo = max(s_c - lens[i] / 2.0, clip)
            s_hi = min(s_c + lens[i] / 2.0 + max(float(speeds[i]), 0.0) * SWEEP_TIME,
                       c.length)
            if s_hi - s_lo < 0.5:
                continue
            ss = np.linspace(s_lo, s_hi, max(math.ceil((s_hi - s_lo) / 2.0), 1) + 1)
            half = wids[i] / 2.0
            polys.append(np.vstack((c.to_xy(ss, l_c - half), c.to_xy(ss[::-1], l_c + half))))
            names.append(f"moving:{ids[i]}")
        return Obstacles.from_polygons(polys, names) if polys else Obstacles.empty()

    def _traffic_conflict(self) -> str | None:
        """The first moving vehicle beside the ego that, driving on at its speed and
        heading, comes within the ego's width plus the safety margin of where the ego will
        be along its plan in the next few seconds; ``None`` if none does."""
        if self.traj is None or not self.others.n or self.corridor is None:
            return None
        # the test on the cheap superset of the vehicles beside first: usually none comes
        # near, and then none of those beside does either
        cand = self._beside_candidates()
        if not cand:
            return None
        hits = self._conflicts(cand)
        if not hits:
            return None
        idx, _ = self._beside()
        first = [i for i in idx.tolist() if i in hits]
        return self.others.ids[first[0]] if first else None

    def _conflicts(self, idx: list[int]) -> list[int]:
        """Those of the vehicles ``idx`` (indices into ``self.others``) that, driving on at
        their speed and heading, come near the plan (:meth:`_traffic_conflict`).

        Plain floats: a few vehicles at a few prediction times."""
        ego, margin = self.sc.ego, self.sc.roadmap.safety_margin
        o = self.others
        ps, px, py, ph, _ = self._pl
        end = ps[-1]
        poses = []  # where the ego will be: x, y, cos, sin of the heading
        for tau in _CONFLICT_TIMES:
            j, f = _locate(min(self.u + self.v * tau, end), ps)
            if len(ps) < 2:
                x, y, h = px[0], py[0], ph[0]
            else:
                x = px[j] + f * (px[j + 1] - px[j])
                y = py[j] + f * (py[j + 1] - py[j])
                h = ph[j] + f * (ph[j + 1] - ph[j])
            poses.append((tau, x, y, math.cos(h), math.sin(h)))
        hits = []
        for i in idx:
            cx, cy, co, si = float(o.cx[i]), float(o.cy[i]), float(o.cos[i]), float(o.sin[i])
            v = float(o.speed[i])
            lon_max = (ego.length + float(o.length[i])) / 2.0 + _CONFLICT_SLACK
            lat_max = (ego.width + float(o.width[i])) / 2.0 + margin
            for tau, x, y, ce, se in poses:
                dx = cx + v * tau * co - x
                dy = cy + v * tau * si - y
                if abs(dx * ce + dy * se) < lon_max and abs(dy * ce - dx * se) < lat_max:
                    hits.append(i)
                    break
        return hits


def _locate(u: float, s: list[float]) -> tuple[int, float]:
    """Segment ``j`` and fraction ``f`` of ``u`` on increasing stations ``s`` (clamped to the
    ends, as :func:`numpy.interp`)."""
    n = len(s)
    if n < 2 or u <= s[0]:
        return 0, 0.0
    if u >= s[-1]:
        return max(n - 2, 0), 1.0 if n >= 2 else 0.0
    j = min(bisect.bisect_right(s, u) - 1, n - 2)
    span = s[j + 1] - s[j]
    return j, (u - s[j]) / span if span > 0 else 0.0


def _interp(u: float, s: list[float], v: list[float]) -> float:
    """``numpy.interp(u, s, v)`` for one value on plain lists."""
    j, f = _locate(u, s)
    if len(s) < 2:
        return v[0]
    return v[j] + f * (v[j + 1] - v[j])
