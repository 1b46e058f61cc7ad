"""The closed loop in SUMO for any number of planned vehicles.

:mod:`~splineplan.closedloop.driver` holds one planned vehicle's plan and state (its
perception, replanning and control come from :mod:`.perception`, :mod:`.replan` and
:mod:`.control`) and never calls SUMO; :mod:`.run` loops over the active drivers, talking to
SUMO only through :class:`splineplan.sumo.world.World`; :mod:`.record` writes the outputs.
"""
