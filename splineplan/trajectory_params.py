"""Parameters of level 3 (:class:`TrajectoryParams`), checked on creation.

A module of its own so that the parts of level 3 (:mod:`splineplan.control_polygon`,
:mod:`splineplan.optimiser`) read them without importing :mod:`splineplan.trajectory`,
which imports them; users import the class from :mod:`splineplan.trajectory`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from splineplan.errors import ParameterError, require_non_negative, require_positive


@dataclass(frozen=True)
class TrajectoryParams:
    """Parameters of level 3, checked on creation.

    Attributes
    ----------
    degree
        Degree of the B-spline (3: cubic), 2 to 5.
    mu
        Friction coefficient of equation (1).
    g
        Gravity [m/s^2].
    s_max
        Maximum speed [m/s] (default 50 km/h, urban).
    a_max, b_max
        Acceleration and braking limits [m/s^2].
    sample_spacing
        Spacing [m] of the trajectory's samples along the curve.
    road_margin
        Clearance [m] the footprint keeps from the road edges. The paper and the issue ask
        only that the vehicle stay on the road (0); level 2's roadmap already keeps
        ``RoadmapParams.safety_margin`` from them where the road is wide enough, and the
        curve may use the rest of a lane in a bend, as a driver does. Obstacles always keep
        ``RoadmapParams.safety_margin``.
    min_turn_radius
        Smallest turning radius [m] of the path of the vehicle's centre (the middle of its
        rectangle): a hard limit on the curvature. A compact car with a 10.9 m turning
        circle (kerb to kerb) and a 2.6 m wheelbase turns its centre on about 4.2 m.
    wheelbase, max_steering_rate
        The car as a kinematic single-track model: its wheelbase [m], with the centre
        half of it ahead of the rear axle, and how fast it turns its front wheels [rad/s].
        Where the curvature changes, the speed profile slows so that the wheels, behind
        which the rear axle is towed, keep up (:func:`splineplan.speed.towed_speed_limit`;
        level 3's smoothing aims at the steady turn's angles,
        :func:`splineplan.speed.steering_speed_limit`, which ask more). Defaults: a
        compact car (BMW 320i, CommonRoad's vehicle type 2: 2.578 m, 0.4 rad/s). The
        largest steering angle follows from ``min_turn_radius``
        (:attr:`max_steering_angle`).
    max_iterations
        Cap on the number of control-point moves tried.
    bend_rounds
        Iterations of the joint moves that bring a curve still beyond the turning limit
        after the single-point moves within it (:meth:`splineplan.optimiser._Optimiser.ease_bends`);
        0: none.
    patience
        The optimisation also stops after this many rounds in a row that did not raise the
        curve's minimum allowed speed (its objective): the slowest point is then held by a
        bound (road edge, obstacle, turning limit) that the remaining moves cannot change.
        Without it, routes through junction turns spent hundreds of rounds on moves that
        were all refused or undone.
    band_fraction
        Fraction rho in [0, 1] of each free interval, centred on its midpoint, within which
        the initial control polygon crosses the sweep lines (band simplification); 0 keeps
        every turning vertex of the roadmap.
    max_control_spacing
        Longest stretch [m] of the roadmap between two control points of the initial
        polygon, so that equation (3) has points to move on long straights.
    repair_rounds
        Rounds of local repair of the first curve (vertices re-inserted, control points
        doubled) where its footprint is not clear.
    lead_in_lengths, lead_in_time
        The lead-in: roadmap vertices closer ahead of the vehicle than
        ``max(lead_in_lengths * vehicle_length, lead_in_time * start_speed)`` [m] are not
        control points at first, so that a lateral offset is taken over that distance.
    band_reserve
        Room [m] that each band leaves to its free interval's ends on each side.
    keep_separation
        Where level 2 placed the vertices (``RoadmapParams(place=True)``), the most
        clearance [m] beyond the safety margin that equation (3)'s moves and the
        steering's smoothing keep from the obstacles: none brings a sample of the curve
        that keeps ``BAND_KEEP`` (90 %) of its vertex's separation, at most this much,
        closer than that. Tight passages keep their separation; beyond this much,
        smoothing may trade separation for speed, as the paper's does. 0: none kept.
    detour_rate
        Largest lateral change [m per m of station] of the detour path
        (:func:`splineplan.control_polygon.detour_roadmap`) tried when the curve along
        level 2's path is not feasible; 0: no detour.
    """

    degree: int = 3
    mu: float = 0.7
    g: float = 9.81
    s_max: float = 13.89
    a_max: float = 2.0
    b_max: float = 4.0
    sample_spacing: float = 0.5
    road_margin: float = 0.0
    min_turn_radius: float = 4.2
    wheelbase: float = 2.578
    max_steering_rate: float = 0.4
    max_iterations: int = 5000
    band_fraction: float = 0.8
    max_control_spacing: float = 25.0
    repair_rounds: int = 6
    lead_in_lengths: float = 2.0
    lead_in_time: float = 1.5
    band_reserve: float = 0.15
    patience: int = 12
    bend_rounds: int = 30
    detour_rate: float = 0.4
    keep_separation: float = 0.3

    def __post_init__(self) -> None:
        if not isinstance(self.degree, int | np.integer) or not 2 <= self.degree <= 5:
            raise ParameterError(f"TrajectoryParams.degree must be an integer in 2..5, "
                                 f"got {self.degree!r}")
        for name in ("mu", "g", "s_max", "a_max", "b_max", "sample_spacing", "min_turn_radius",
                     "max_control_spacing", "wheelbase", "max_steering_rate"):
            require_positive(f"TrajectoryParams.{name}", getattr(self, name))
        if self.wheelbase >= 2.0 * self.min_turn_radius:
            raise ParameterError(f"TrajectoryParams.wheelbase ({self.wheelbase!r} m) must be "
                                 f"less than twice min_turn_radius ({self.min_turn_radius!r} "
                                 f"m): the car's centre could not turn that tightly")
        if not (isinstance(self.band_fraction, int | float | np.floating | np.integer)
                and 0.0 <= self.band_fraction <= 1.0):
            raise ParameterError(f"TrajectoryParams.band_fraction must be in [0, 1], "
                                 f"got {self.band_fraction!r}")
        for name in ("road_margin", "lead_in_lengths", "lead_in_time", "band_reserve",
                     "detour_rate", "keep_separation"):
            require_non_negative(f"TrajectoryParams.{name}", getattr(self, name))
        for name in ("max_iterations", "repair_rounds", "patience", "bend_rounds"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 0:
                raise ParameterError(f"TrajectoryParams.{name} must be an integer >= 0, "
                                     f"got {value!r}")

    @property
    def kappa_max(self) -> float:
        """Hard curvature limit [1/m]: ``1 / min_turn_radius``."""
        return 1.0 / self.min_turn_radius

    @property
    def max_steering_angle(self) -> float:
        """Front-wheel angle [rad] at the turning limit (kinematic single-track model)."""
        from splineplan.speed import steering_angle

        return float(steering_angle(self.kappa_max, self.wheelbase))

    @property
    def kappa_smax(self) -> float:
        """Curvature [1/m] above which equation (1) allows less than ``s_max``."""
        return self.mu * self.g / self.s_max**2
