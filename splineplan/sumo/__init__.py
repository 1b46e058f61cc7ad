"""SUMO at the edge: :mod:`splineplan.sumo.world` is the only module that talks to a running
SUMO (``libsumo``, or ``traci`` for ``sumo-gui``); :mod:`splineplan.sumo.ssm` equips a run
with SUMO's SSM device and reads its output."""
