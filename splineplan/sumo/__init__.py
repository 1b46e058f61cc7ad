"""SUMO at the edge: :mod:`splineplan.sumo.world` is the only module that talks to a running
SUMO (``libsumo``, or ``traci`` for ``sumo-gui``)."""
