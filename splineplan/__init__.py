"""splineplan: spline-based multi-level planning for autonomous vehicles in SUMO.

Three levels after R. Kala and K. Warwick, "Spline-Based Multi-Level Planning for
Autonomous Vehicles": road selection (:mod:`splineplan.route`), a widest-then-shortest
roadmap on each road segment (:mod:`splineplan.roadmap`) and a speed-optimised B-spline
trajectory (:mod:`splineplan.trajectory`).
"""

from splineplan.errors import SplineplanError

__all__ = ["SplineplanError", "__version__"]
__version__ = "0.1.0"
