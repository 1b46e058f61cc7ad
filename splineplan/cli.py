"""Command-line interface: ``splineplan COMMAND ...``.

Each command has an ``_add_<name>`` function that declares its arguments and a
``_cmd_<name>`` function that runs it. Package errors print as one line on stderr with a
non-zero exit status.
"""

from __future__ import annotations

import argparse
import logging
import math
import os
import sys
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import Any, NoReturn

from splineplan import __version__
from splineplan.errors import OutputError, SplineplanError

# ---- checks shared by the commands: numbers and output paths, before any work -----------

#: Longest road [m] that ``plan-image`` plans across: ``--scale`` times the map's width in
#: pixels (a mistyped scale of 1e6 m per pixel made a road of 4e8 m, and the process ran out of
#: memory building it).
MAX_MAP_LENGTH = 20_000.0
#: Largest SUMO seed (a C int).
MAX_SEED = 2**31 - 1
#: Picture formats that ``--plot FILE`` may name (by its extension).
PICTURE_FORMATS = ("png", "pdf", "svg", "svgz", "jpg", "jpeg", "tif", "tiff", "webp", "eps",
                   "ps")


def _float(text: str) -> float:
    """A finite float, or an argparse error that says the value must be a number."""
    try:
        x = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a number, got {text!r}") from None
    if not math.isfinite(x):
        raise argparse.ArgumentTypeError(f"must be a finite number, got {text!r}")
    return x


def _positive(text: str) -> float:
    """A finite float above 0 (an argparse type)."""
    x = _float(text)
    if x <= 0:
        raise argparse.ArgumentTypeError(f"must be positive, got {text!r}")
    return x


def _non_negative(text: str) -> float:
    """A finite float, 0 or above (an argparse type)."""
    x = _float(text)
    if x < 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {text!r}")
    return x


def _int_in(low: int, high: int | None = None) -> Callable[[str], int]:
    """An argparse type: an integer from ``low`` (to ``high``)."""
    def parse(text: str) -> int:
        try:
            n = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be an integer, got {text!r}") from None
        if n < low or (high is not None and n > high):
            within = f">= {low}" if high is None else f"in {low}..{high}"
            raise argparse.ArgumentTypeError(f"must be an integer {within}, got {text!r}")
        return n
    parse.__name__ = "integer"
    return parse


def _spacing(text: str) -> float:
    """The sweep-line spacing ``--d`` [m], within :data:`splineplan.roadmap.D_RANGE` (an
    argparse type)."""
    from splineplan.roadmap import D_RANGE

    x = _float(text)
    lo, hi = D_RANGE
    if not lo <= x <= hi:
        raise argparse.ArgumentTypeError(
            f"the sweep-line spacing must be between {lo:g} and {hi:g} m, got {text!r}")
    return x


def _threshold(text: str) -> float:
    """A luminance threshold in (0, 1) (an argparse type)."""
    x = _float(text)
    if not 0.0 < x < 1.0:
        raise argparse.ArgumentTypeError(f"must lie between 0 and 1, got {text!r}")
    return x


def _out_dir(path: str | Path, option: str = "--out") -> Path:
    """The output folder ``path``, checked before any work: it is a folder, or can be made
    one, and may be written; else :class:`OutputError` naming ``option``."""
    p = Path(path)
    if p.exists() and not p.is_dir():
        raise OutputError(f"{option} {p} is a file, not a folder")
    _writable(p if p.exists() else _existing_parent(p, option), p, option)
    return p


def _out_file(path: str | Path, option: str = "--plot") -> Path:
    """The picture file ``path``, checked before any work: not a folder, a known picture
    format, and writable (its missing parent folders are made when it is written, by
    :func:`_make_parent`); else :class:`OutputError` naming ``option``."""
    p = Path(path)
    if p.is_dir():
        raise OutputError(f"{option} {p} is a folder; give a picture file, such as "
                          f"{p / 'picture.png'}")
    fmt = p.suffix[1:].lower()
    if fmt not in PICTURE_FORMATS:
        what = f"unknown picture format {p.suffix!r}" if fmt else "no picture extension"
        raise OutputError(f"{option} {p} has {what}; use .png, .pdf or .svg")
    _writable(p if p.exists() else _existing_parent(p, option), p, option)
    return p


def _existing_parent(p: Path, option: str) -> Path:
    """The nearest folder above ``p`` that exists; an error if it is a file."""
    q = p.parent
    while not q.exists() and q != q.parent:
        q = q.parent
    if not q.is_dir():
        raise OutputError(f"{option} {p}: {q} is a file, not a folder")
    return q


def _writable(q: Path, p: Path, option: str) -> None:
    if not os.access(q, os.W_OK | (os.X_OK if q.is_dir() else 0)):
        raise OutputError(f"{option} {p} cannot be written: {q} is not writable")


def _make_parent(p: Path) -> Path:
    """``p`` after making its parent folders (a picture's, as ``plan --plot`` does)."""
    p.parent.mkdir(parents=True, exist_ok=True)
    return p


def _clear_outputs(out: Path, names: Iterable[str]) -> None:
    """Remove from ``out`` the files an earlier run of the same command wrote (glob
    ``names``), so that a reused folder holds only this run's outputs; nothing else in it
    is touched."""
    if not out.is_dir():
        return
    for name in names:
        for f in out.glob(name):
            if f.is_file():
                f.unlink()


#: What ``plan`` and ``plan-image`` write into their folder (and ``plot`` draws from it).
_PLAN_OUTPUTS = ("plan.json", "trajectory.csv",
                 *(f"{n}.{fmt}" for n in ("roadmap", "trajectory", "speed")
                   for fmt in ("png", "pdf", "svg")))
#: What ``simulate`` writes into its folder.
_SIM_OUTPUTS = ("metrics.json", "trajectory.csv", "fcd.xml", "ssm.xml", "sumo.log", "run.log",
                "summary.json", "tripinfo.xml", "*/metrics.json", "*/trajectory.csv",
                *(f"{n}.{fmt}" for n in ("route", "speed_time") for fmt in ("png", "pdf", "svg")),
                "plans/plan_*.png")


# ---- commands (one _add_/_cmd_ pair each; keep them in this order) ----------------------

def _add_route(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("route", help="plan a road-level route (level 1) on a SUMO network",
                       description="Shortest road route between two SUMO edges (Dijkstra "
                                   "over the network's allowed connections).")
    p.add_argument("net", metavar="NET", help="SUMO network (.net.xml or .net.xml.gz)")
    p.add_argument("from_edge", metavar="FROM_EDGE", help="origin edge id")
    p.add_argument("to_edge", metavar="TO_EDGE", help="destination edge id")
    p.add_argument("--vclass", default="passenger", help="SUMO vehicle class (passenger)")
    p.add_argument("--weight", choices=("length", "time"), default="length",
                   help="minimise length [m] or travel time [s] (length)")
    p.add_argument("--avoid", nargs="+", default=[], metavar="EDGE",
                   help="edges the route must not use")
    p.add_argument("--start-pos", type=_non_negative, default=0.0, metavar="M",
                   help="start position [m] along FROM_EDGE (0)")
    p.add_argument("--plot", metavar="PNG", help="write a picture of the route on the network "
                   "(missing folders are made)")
    p.add_argument("--json", action="store_true", help="print the result as JSON")
    p.set_defaults(func=_cmd_route)


def _cmd_route(args: argparse.Namespace) -> int:
    import json

    from splineplan.network import load_network
    from splineplan.route import shortest_route

    picture = _out_file(args.plot) if args.plot else None
    net = load_network(args.net)
    route = shortest_route(net, args.from_edge, args.to_edge, vclass=args.vclass,
                           weight=args.weight, avoid=tuple(args.avoid),
                           start_pos=args.start_pos)
    if picture is not None:
        from splineplan.plot import plot_route

        plot_route(net, route, path=_make_parent(picture))
    unit = "m" if route.weight == "length" else "s"
    if args.json:
        print(json.dumps({
            "network": str(args.net), "from": route.edges[0], "to": route.edges[-1],
            "vclass": route.vclass, "weight": route.weight, "avoid": list(args.avoid),
            "start_pos": route.start_pos, "edges": list(route.edges),
            "length": route.length, "cost": route.cost, "plot": args.plot,
        }, indent=2))
    else:
        print(f"route {route.edges[0]} -> {route.edges[-1]} ({route.vclass}, by {route.weight})")
        print(f"edges ({len(route.edges)}): {' '.join(route.edges)}")
        print(f"length: {route.length:.2f} m")
        print(f"cost: {route.cost:.2f} {unit}")
        if args.plot:
            print(f"picture: {args.plot}")
    return 0

def _xy_pair(text: str) -> tuple[float, float]:
    """``"X,Y"`` [m] as two floats (an argparse type)."""
    try:
        x, y = (float(v) for v in text.split(","))
    except ValueError:
        x = y = math.nan
    if not (math.isfinite(x) and math.isfinite(y)):
        raise argparse.ArgumentTypeError(
            f"expected X,Y in metres (two finite numbers), got {text!r}")
    return x, y


def _add_plan_image(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "plan-image", help="plan levels 2 and 3 across a road drawn as an image",
        description="Read a road segment drawn as an image (light = road, dark = obstacle or "
                    "off-road; x to the right and y up from the bottom-left corner, in metres), "
                    "plan the roadmap and the trajectory from the left edge to the right edge, "
                    "and write trajectory.csv (t, x, y, heading, speed, curvature, s), "
                    "plan.json and pictures to the output folder.")
    p.add_argument("map", metavar="MAP", help="map image (PNG or any format Pillow reads)")
    p.add_argument("--scale", type=_positive, required=True, metavar="M",
                   help="size of a pixel [m] (metres per pixel)")
    p.add_argument("--start", type=_xy_pair, metavar="X,Y",
                   help="start [m] (default: the middle of the road on the left edge)")
    p.add_argument("--goal", type=_xy_pair, metavar="X,Y",
                   help="goal [m]: the plan ends on the sweep line through it "
                        "(default: the right edge)")
    p.add_argument("--out", metavar="DIR", help="output folder (default: MAP's name + '_plan'); "
                   "its earlier plan files and pictures are replaced")
    p.add_argument("--threshold", type=_threshold, default=0.5,
                   help="luminance in (0, 1) from which a pixel is road (0.5)")
    p.add_argument("--merge-tolerance", type=_int_in(0), default=0, metavar="PIXELS",
                   help="merge obstacle rows whose ends differ by at most this many pixels "
                        "(fewer, slightly larger obstacles; 0 = pixel-exact)")
    p.add_argument("--no-plot", action="store_true", help="write no pictures")
    p.set_defaults(func=_cmd_plan_image)



def _cmd_plan_image(args: argparse.Namespace) -> int:
    from pathlib import Path

    from splineplan.image_map import image_map, plan_image
    from splineplan.io import save_plan
    from splineplan.trajectory import TrajectoryParams

    out = _out_dir(args.out if args.out else f"{Path(args.map).stem}_plan")
    _check_map_length(args.map, args.scale)
    amap = image_map(args.map, scale=args.scale, threshold=args.threshold,
                     merge_tolerance=args.merge_tolerance)
    params = TrajectoryParams()
    plan = plan_image(amap, start=args.start, goal=args.goal, params=params)
    tr = plan.trajectory
    _clear_outputs(out, _PLAN_OUTPUTS)
    save_plan(out, corridor=plan.corridor, obstacles=amap.obstacles, roadmaps=plan.roadmaps,
              trajectory=tr, trajectory_params=params,
              meta={"source": "image", "map": str(Path(args.map).resolve()),
                    "scale": amap.scale, "threshold": args.threshold,
                    "start": plan.start, "goal": plan.goal})
    if not args.no_plot:
        from splineplan.plot import plot_plan_folder

        plot_plan_folder(out)
    h, w = amap.shape
    print(f"map {args.map}: {w} x {h} pixels, {w * amap.scale:.1f} x {h * amap.scale:.1f} m, "
          f"{amap.n_blobs} obstacles ({len(amap.obstacles)} rectangles)")
    print(f"trajectory: {tr.length:.1f} m in {tr.duration:.1f} s, "
          f"min clearance {tr.min_clearance:.2f} m, feasible: {'yes' if tr.feasible else 'no'}")
    print(f"written to {out}/ (trajectory.csv, plan.json"
          f"{'' if args.no_plot else ', roadmap.png, trajectory.png, speed.png'})")
    _report_infeasible("plan-image", tr, plan.corridor)
    return 0


#: At most this many broken limits are listed for an infeasible plan.
MAX_REPORTED_VIOLATIONS = 5


def _report_infeasible(command: str, trajectory: Any, corridor: Any) -> None:
    """On stderr: which limit an infeasible trajectory breaks, where (station, edge)."""
    if trajectory.feasible:
        return
    found = trajectory.violations
    print(f"splineplan {command}: warning: the trajectory is not feasible "
          f"({len(found)} limit{'s' if len(found) != 1 else ''} broken):", file=sys.stderr)
    for v in found[:MAX_REPORTED_VIOLATIONS]:
        print(f"  {v.describe(corridor)}", file=sys.stderr)
    if len(found) > MAX_REPORTED_VIOLATIONS:
        print(f"  ... and {len(found) - MAX_REPORTED_VIOLATIONS} more (plan.json lists them)",
              file=sys.stderr)


def _check_map_length(path: str, scale: float) -> None:
    """Refuse a ``--scale`` that makes the map's road longer than :data:`MAX_MAP_LENGTH`
    (read from the image's header; a file that is no image is left to the reader)."""
    from PIL import Image

    try:
        with Image.open(path) as im:
            width = im.size[0]
    except (OSError, ValueError, Image.DecompressionBombError):
        return  # image_map says what is wrong with the file
    if width * scale > MAX_MAP_LENGTH:
        from splineplan.errors import ParameterError

        raise ParameterError(
            f"--scale {scale:g} m per pixel makes the {width}-pixel-wide map "
            f"{width * scale / 1000:.4g} km long; plan-image plans at most "
            f"{MAX_MAP_LENGTH / 1000:g} km (is the scale in metres per pixel?)")


def _add_plot(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "plot", help="draw the figures of a plan or simulation folder",
        description="Redraw the paper's figures from a run folder: with plan.json (written by "
                    "plan-image), the roadmap (Fig. 2), the trajectory coloured by speed "
                    "(Fig. 4) and the speed profile; with metrics.json (a simulation run), "
                    "the route on the network (Fig. 3) and the driven path coloured by speed.")
    p.add_argument("run_dir", metavar="RUN_DIR", help="folder holding plan.json or metrics.json")
    p.add_argument("--out", metavar="DIR", help="where to write the pictures (RUN_DIR; "
                   "missing folders are made)")
    p.add_argument("--format", default="png", choices=("png", "pdf", "svg"),
                   help="picture format (png)")
    p.set_defaults(func=_cmd_plot)


def _cmd_plot(args: argparse.Namespace) -> int:
    import json
    from pathlib import Path

    from splineplan.errors import ScenarioError

    run = Path(args.run_dir)
    if not run.is_dir():
        raise ScenarioError(f"RUN_DIR {run} " + ("is a file, not a folder" if run.exists()
                                                 else "not found"))
    out = _out_dir(args.out) if args.out else _out_dir(run, "RUN_DIR")
    from splineplan.plot import plot_plan_folder, plot_run_folder

    if (run / "plan.json").exists():
        written = plot_plan_folder(run, out_dir=out, fmt=args.format)
    elif (run / "metrics.json").exists():
        try:
            json.loads((run / "metrics.json").read_text())
        except (UnicodeDecodeError, json.JSONDecodeError) as err:
            raise ScenarioError(f"{run / 'metrics.json'} is not readable JSON: {err}") from err
        written = plot_run_folder(run, out_dir=out, fmt=args.format)
    else:
        raise ScenarioError(f"{run} holds neither plan.json nor metrics.json")
    for f in written:
        print(f)
    if not written:
        print(f"{run}: nothing to draw (see the warnings)")
    return 0

def _share(text: str) -> float:
    """A fraction in [0, 1] (an argparse type)."""
    x = _float(text)
    if not 0.0 <= x <= 1.0:
        raise argparse.ArgumentTypeError(f"must be a fraction between 0 and 1, got {text!r}")
    return x


def _add_simulate(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "simulate", help="drive vehicles with the planner through a SUMO scenario",
        description="Run a scenario (TOML, see scenarios/; or SUMO's own: a .sumocfg, or "
                    "--net with --routes) in SUMO with the planner driving the ego "
                    "vehicle(s), or a chosen set of SUMO's vehicles (--vehicles, --vtype, "
                    "--share); write metrics.json, trajectory.csv, fcd.xml and ssm.xml "
                    "(per planned vehicle in <out>/<id>/, with summary.json and "
                    "tripinfo.xml, when more than one vehicle is planned).")
    p.add_argument("scenario", nargs="?", default=None,
                   help="scenario file (.toml) or SUMO configuration (.sumocfg)")
    p.add_argument("--net", default=None, help="SUMO network (instead of a scenario file)")
    p.add_argument("--routes", nargs="+", default=[], metavar="R.rou.xml",
                   help="SUMO route files (with --net)")
    p.add_argument("--additional", nargs="+", default=[], metavar="A.add.xml",
                   help="SUMO additional files (with --net)")
    p.add_argument("--duration", type=_positive, default=None,
                   help="simulated seconds (a SUMO scenario: default its end time, else an "
                        "hour)")
    p.add_argument("--vehicles", nargs="+", default=[], metavar="ID",
                   help="plan these of SUMO's vehicles (a flow's are <flow id>.<n>)")
    p.add_argument("--vtype", default=None, help="plan SUMO's vehicles of this type")
    p.add_argument("--share", type=_share, default=None,
                   help="plan this fraction (0..1) of SUMO's departing passenger vehicles, "
                        "drawn with --seed")
    p.add_argument("--out", default=None,
                   help="output folder (default: runs/<scenario name>); its earlier run "
                        "files and pictures are replaced")
    p.add_argument("--plot", action="store_true", help="also draw the route and each plan")
    p.add_argument("--gui", action="store_true", help="watch in sumo-gui (through traci)")
    p.add_argument("--seed", type=_int_in(0, MAX_SEED), default=None,
                   help="SUMO's random seed and that of --share's draw (an integer >= 0)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--driver", choices=("planner", "sumo", "sublane"), default="planner",
                   help="who drives the ego: the planner (default), SUMO's lane-based "
                        "model or SUMO's sublane model (baselines)")
    p.set_defaults(func=_cmd_simulate)


def _cmd_simulate(args: argparse.Namespace) -> int:
    import dataclasses
    from pathlib import Path

    from splineplan.errors import Interrupted, ScenarioError
    from splineplan.scenario import load_scenario, sumo_scenario
    from splineplan.sim import simulate

    given = _out_dir(args.out) if args.out else None
    if args.scenario is None and args.net is None:
        raise ScenarioError("give a scenario file (.toml or .sumocfg) or --net NET")
    if args.scenario is not None and args.net is not None:
        raise ScenarioError("give either a scenario file or --net, not both")
    if args.scenario is not None and not args.scenario.endswith((".sumocfg", ".cfg")):
        if args.routes or args.additional:
            raise ScenarioError("--routes and --additional go with --net or a .sumocfg")
        scenario = load_scenario(args.scenario)
        if args.duration is not None:
            scenario = dataclasses.replace(scenario, sim=dataclasses.replace(
                scenario.sim, duration=args.duration))
    else:
        scenario = sumo_scenario(args.scenario, net=args.net, routes=tuple(args.routes),
                                 additional=tuple(args.additional), duration=args.duration)
    out = given or _out_dir(Path("runs") / scenario.name)
    _clear_outputs(out, _SIM_OUTPUTS)
    try:
        result = simulate(scenario, out_dir=out, plot=args.plot, gui=args.gui, seed=args.seed,
                          progress=False if args.no_progress else None, driver=args.driver,
                          share=args.share, vehicles=tuple(args.vehicles), vtype=args.vtype)
    except Interrupted as stop:  # Ctrl-C: the record up to then is written
        print(f"splineplan simulate: {stop}", file=sys.stderr)
        return 130
    m = result.metrics
    print(f"{scenario.name}: {result.status}: {result.reason}")
    if result.vehicles or "planned" in m:
        print(f"  planned {m['planned']}, arrived {m['arrived']}, collisions "
              f"{m['collisions']}, off road {m['vehicles_off_road']} vehicle(s), "
              f"wall {m['wall_time']:.1f} s for {m['sim_time_end']:.1f} s simulated")
        pairs = m.get("pairs") or {}
        if "overlapping_pairs_unplanned" in pairs:
            print(f"  pairs whose footprints overlapped: "
                  f"{len(pairs['collision_pairs_planned'])} with a planned vehicle, "
                  f"{pairs['overlapping_pairs_unplanned']} of SUMO's own vehicles")
        for vid, v in result.vehicles.items():
            if v.status == "failed":
                print(f"  {vid}: failed: {v.reason}")
    else:
        print(f"  travel time {m['travel_time'] or 0:.1f} s, distance {m['distance']:.1f} m, "
              f"collisions {m['collisions']}, off road {m['time_off_road']:.1f} s, "
              f"replans {m['replan_count']}")
    print(f"  outputs in {out}")
    return 0 if result.arrived else 1


def _add_plan(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "plan", help="plan levels 1-3 on a SUMO network and write the trajectory",
        description="Plan the route (level 1), the roadmaps (level 2) and the trajectory "
                    "(level 3) from the start of FROM_EDGE to the end of TO_EDGE (or "
                    "--end-pos on it); write "
                    "trajectory.csv and plan.json into --out, and a picture with --plot.")
    p.add_argument("net", metavar="NET", help="SUMO network (.net.xml or .net.xml.gz)")
    p.add_argument("from_edge", metavar="FROM_EDGE")
    p.add_argument("to_edge", metavar="TO_EDGE")
    p.add_argument("--obstacles", metavar="FILE",
                   help="SUMO additional/route file: <poly> shapes and vehicles with a <stop>")
    p.add_argument("--out", metavar="DIR", default="plan",
                   help="output folder (plan); its earlier plan files and pictures are replaced")
    p.add_argument("--plot", metavar="PNG", help="picture of road, obstacles, roadmap and curve "
                   "(missing folders are made)")
    p.add_argument("--vclass", default="passenger", help="SUMO vehicle class (passenger)")
    p.add_argument("--weight", choices=("length", "time"), default="length")
    p.add_argument("--avoid", nargs="+", default=[], metavar="EDGE", help="edges not to use")
    p.add_argument("--start-pos", type=_non_negative, default=0.0, metavar="M",
                   help="start position [m] along FROM_EDGE")
    p.add_argument("--end-pos", type=_non_negative, default=None, metavar="M",
                   help="position [m] along TO_EDGE where the plan ends, as SUMO's "
                        "arrivalPos (default: its end)")
    p.add_argument("--s-max", type=_positive, default=None, metavar="M/S",
                   help="maximum speed [m/s]")
    p.add_argument("--d", type=_spacing, default=None, metavar="M",
                   help="sweep-line spacing [m], 0.1 to 10 (1)")
    p.add_argument("--place", action="store_true",
                   help="place level 2's vertices for the separation from obstacles and "
                        "the lane's centre (RoadmapParams(place=True)), and keep it in "
                        "level 3")
    p.set_defaults(func=_cmd_plan)


def _cmd_plan(args: argparse.Namespace) -> int:
    from dataclasses import replace
    from pathlib import Path

    from splineplan.io import save_plan
    from splineplan.network import load_network, read_obstacles
    from splineplan.obstacles import Obstacles
    from splineplan.pipeline import plan
    from splineplan.roadmap import RoadmapParams
    from splineplan.trajectory import TrajectoryParams

    out = _out_dir(args.out)
    picture = _out_file(args.plot) if args.plot else None
    net = load_network(args.net)
    obstacles = read_obstacles(net, args.obstacles) if args.obstacles else Obstacles.empty()
    if args.obstacles:
        print(f"obstacles: {len(obstacles)} read from {args.obstacles}")
        if not len(obstacles):
            print(f"splineplan plan: warning: {args.obstacles} holds no obstacles (no <poly> "
                  "shapes, no vehicles with a <stop> on a lane): planning on an empty road",
                  file=sys.stderr)
    rp = RoadmapParams(place=args.place) if args.d is None else RoadmapParams(
        d=args.d, place=args.place)
    tp = TrajectoryParams()
    if args.s_max is not None:
        tp = replace(tp, s_max=args.s_max)
    result = plan(net, args.from_edge, args.to_edge, obstacles, start_pos=args.start_pos,
                  end_pos=args.end_pos, vclass=args.vclass, weight=args.weight, avoid=args.avoid,
                  roadmap_params=rp, trajectory_params=tp)
    tr = result.trajectory
    _clear_outputs(out, _PLAN_OUTPUTS)
    save_plan(out, corridor=result.corridor, obstacles=obstacles, roadmaps=list(result.roadmaps),
              trajectory=tr, trajectory_params=tp,
              meta={"source": "network", "network": str(Path(args.net).resolve()),
                    "route": list(result.route.edges), "blocked": list(result.blocked)})
    if picture is not None:
        from splineplan.plot import plot_trajectory

        plot_trajectory(tr, result.corridor, obstacles, list(result.roadmaps),
                        path=_make_parent(picture), s_max=tp.s_max)
    print(f"route: {' '.join(result.route.edges)} ({result.route.length:.1f} m)")
    if result.blocked:
        print(f"closed and avoided: {' '.join(result.blocked)}")
    print(f"trajectory: {tr.length:.1f} m in {tr.duration:.1f} s, "
          f"min clearance {tr.min_clearance:.2f} m, feasible: {'yes' if tr.feasible else 'no'}")
    print(f"time: level 1 {1e3 * result.route_seconds:.1f} ms, level 2 "
          f"{1e3 * result.roadmap_seconds:.1f} ms, level 3 "
          f"{1e3 * result.trajectory_seconds:.1f} ms")
    print(f"written to {out}/ (trajectory.csv, plan.json)"
          + (f" and {args.plot}" if args.plot else ""))
    _report_infeasible("plan", tr, result.corridor)
    return 0


def _add_bench(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("bench", help="run a suite of scenarios with the planner and SUMO's "
                                     "drivers, and compare",
                       description="Run each case of a suite (bundled scenarios and seeded "
                                   "obstacle fields on straight and curved roads) with the "
                                   "splineplan ego, SUMO's default driver and SUMO's sublane "
                                   "driver; write runs.csv, runs.json, summary.md and figures.")
    p.add_argument("suite", metavar="SUITE", nargs="?", default="default",
                   help="default, quick, fields, a scenario file or a folder of them (default)")
    p.add_argument("--seeds", type=_int_in(1), default=1, metavar="N", help="seeds 0..N-1 (1)")
    p.add_argument("--workers", type=_int_in(1), default=None, metavar="N",
                   help="runs at a time on this machine (default: number of cores)")
    p.add_argument("--address", metavar="HOST:PORT",
                   help="run on a Ray cluster instead (its head's address, or ray://HOST:PORT "
                        "for Ray Client; needs splineplan[ray])")
    p.add_argument("--scheduler", help=argparse.SUPPRESS)
    p.add_argument("--shares", nargs="+", type=float, metavar="SHARE",
                   help="a penetration sweep of the scenario SUITE (.sumocfg or .toml) at "
                        "these shares of planned vehicles, e.g. 0 0.1 0.25 0.5 1, over "
                        "--seeds seeds: sweep.csv, sweep.json, sweep.md, sweep.png")
    p.add_argument("--out", default="bench_out", metavar="DIR", help="output folder (bench_out)")
    p.add_argument("--tiers", nargs="+", metavar="TIER",
                   help="only these tiers: bundled, empty, sparse, medium, dense, blocked")
    p.add_argument("--drivers", nargs="+", default=None, metavar="DRIVER",
                   choices=("planner", "sumo", "sublane"), help="planner, sumo, sublane (all)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=_cmd_bench)


def _cmd_bench(args: argparse.Namespace) -> int:
    from splineplan.bench import DRIVERS, build_suite, exit_status, run_suite, summarise
    from splineplan.errors import Interrupted, ParameterError

    if args.scheduler:
        raise ParameterError("--scheduler (Dask) is gone: bench runs on Ray clusters, "
                             "give the cluster's address with --address")
    _out_dir(args.out)
    if args.shares is not None:
        return _sweep(args)
    cases = build_suite(args.suite, seeds=args.seeds, tiers=args.tiers, out_dir=args.out)
    try:
        res = run_suite(cases, out_dir=args.out, drivers=tuple(args.drivers or DRIVERS),
                        workers=args.workers, address=args.address,
                        progress=not args.no_progress)
    except Interrupted as stop:  # Ctrl-C: the finished runs are written
        print(f"splineplan bench: {stop}", file=sys.stderr)
        return 130
    for s in summarise(res.rows):
        print(f"{s['tier']:>8} {s['driver']:>8}: {s['safe']}/{s['runs']} arrived safely "
              f"({s['arrived']} arrived, {s['collisions']} collisions)")
    failed = [r for r in res.rows if r["error"]]
    for r in failed:
        print(f"failed: {r['case']} ({r['driver']}): {r['error']}")
    print(f"{len(res.cases)} cases, {len(res.rows)} runs in {res.wall_time:.1f} s on "
          f"{res.executor}: {res.cases_per_minute:.1f} cases/min")
    print(f"written to {args.out}/ (runs.csv, runs.json, summary.md, figures)")
    return exit_status(res.rows)


def _add_commonroad(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "commonroad", help="solve a CommonRoad scenario's planning problem",
        description="Read a CommonRoad scenario, plan its planning problem (lanelet route, "
                    "corridor, trajectory timed for the goal, among its static and dynamic "
                    "obstacles) for CommonRoad's kinematic single-track car, and write the "
                    "solution in CommonRoad's solution format into --out (and a picture with "
                    "--plot). Exit status 0 when the solution reaches the goal, 1 when not.")
    p.add_argument("scenario", metavar="SCENARIO.xml", help="CommonRoad scenario file")
    p.add_argument("--out", metavar="DIR", default="commonroad_out",
                   help="output folder (commonroad_out)")
    p.add_argument("--plot", action="store_true",
                   help="also draw the scenario and the trajectory (<scenario id>.png)")
    p.add_argument("--vehicle-type", type=_int_in(0), default=2, metavar="N",
                   help="CommonRoad vehicle type: 1 Ford Escort, 2 BMW 320i, 3 VW Vanagon (2)")
    p.add_argument("--planning-problem", type=_int_in(0), default=None, metavar="ID",
                   help="which planning problem (default: the first)")
    p.add_argument("--speed-limits", action="store_true",
                   help="keep to the speed limits that the scenario's traffic signs post")
    p.set_defaults(func=_cmd_commonroad)


def _cmd_commonroad(args: argparse.Namespace) -> int:
    from splineplan import commonroad as cr

    out = _out_dir(args.out)
    car = cr.vehicle(args.vehicle_type)  # an unknown type is refused before any work
    problem = cr.read(args.scenario, planning_problem_id=args.planning_problem)
    res = cr.plan(problem, vehicle_type=car.type_id, speed_limits=args.speed_limits)
    written = cr.write_solution(res, out)
    name = str(problem.scenario.scenario_id)
    if args.plot:
        from splineplan.plot import plot_commonroad

        net = problem.scenario.lanelet_network
        picture = out / f"{name}.png"
        plot_commonroad(
            cr.lanelet_polygons(problem.scenario), res.obstacles, cr.driven(res),
            route=[cr.lanelet_outline(net.find_lanelet_by_id(i)) for i in res.route.lanelets],
            goal=cr.goal_outlines(res.goal), moving=cr.moving_paths(problem.scenario),
            body=(car.length, car.width), s_max=res.trajectory.speed.max(),
            title=f"{problem.scenario.scenario_id}: goal "
                  + ("reached" if res.goal_reached else "NOT reached"),
            path=picture)
    last = res.states[-1]
    print(f"route: lanelets {' '.join(map(str, res.route.lanelets))} ({res.route.length:.1f} m, "
          f"{res.route.lane_changes} lane change(s))")
    print(f"trajectory: {len(res.states)} states to time step {last.time_step}, "
          f"{res.trajectory.length:.1f} m planned; goal reached: "
          f"{'yes' if res.goal_reached else 'no'}"
          + (f"; waits for {', '.join(res.yielded)}" if res.yielded else ""))
    print(f"vehicle: KS model, type {car.type_id} ({car.name}); plan time "
          f"{1e3 * res.plan_seconds:.1f} ms")
    print(f"written to {written}" + (f" and {out / (name + '.png')}" if args.plot else ""))
    return 0 if res.goal_reached else 1


def _sweep(args: argparse.Namespace) -> int:
    from splineplan.closedloop.pairs import TET_THRESHOLD
    from splineplan.errors import Interrupted, ParameterError
    from splineplan.sweep import build_sweep, run_sweep, summarise

    if args.tiers or args.drivers:
        raise ParameterError("--tiers and --drivers are for suites, not a sweep (--shares)")
    points = build_sweep(args.suite, shares=args.shares, seeds=args.seeds)
    try:
        res = run_sweep(points, out_dir=args.out, workers=args.workers, address=args.address,
                        progress=not args.no_progress)
    except Interrupted as stop:
        print(f"splineplan bench: {stop}", file=sys.stderr)
        return 130
    for s in summarise(res.rows):
        tt = s["mean_travel_time"]
        tet = s["tet"]
        print(f"share {100 * s['share']:5.1f} %: {s['runs']} runs ({s['failed']} failed), "
              f"planned {s['planned_arrived']}/{s['planned']} arrived, {s['collisions']} "
              f"collisions, mean travel time {'-' if tt is None else f'{tt:.1f} s'}, "
              f"time with TTC < {TET_THRESHOLD:g} s "
              f"{'-' if tet is None else f'{tet:.0f} s'} per vehicle-hour")
    for r in res.rows:
        if r["error"]:
            print(f"failed: {r['name']}: {r['error']}")
    print(f"{len(res.rows)} runs in {res.wall_time:.1f} s on {res.executor}")
    print(f"written to {args.out}/ (sweep.csv, sweep.json, sweep.md, sweep.png)")
    bad = any(r["status"] == "failed" or (r["collisions"] or 0) > 0
              or (r["planned_arrived"] or 0) < (r["planned"] or 0) for r in res.rows)
    return 1 if bad else 0


# ---- end of commands --------------------------------------------------------------------


class _Parser(argparse.ArgumentParser):
    """An argument parser whose errors are one line (argparse would print the usage too),
    and which takes SUMO's edge ids that start with a minus (the reverse direction of an
    edge, ``-1511#1``) as values, not as options.

    An argument with a single minus is an option only when it is one of the parser's short
    options (``-h``, ``-v``) or repeats one flag (``-vv``); anything else (``-1511#1``,
    ``-SWA0``) is a value. The commands also take the top-level ``-v`` (``splineplan route
    -v NET A B``).
    """

    def error(self, message: str) -> NoReturn:
        print(f"{self.prog}: error: {message} (see {self.prog} --help)", file=sys.stderr)
        raise SystemExit(2)

    def _parse_optional(self, arg_string: str) -> Any:
        if (arg_string.startswith("-") and not arg_string.startswith("--")
                and len(arg_string) > 1 and not self._short_option(arg_string)):
            return None
        return super()._parse_optional(arg_string)

    def _short_option(self, arg: str) -> bool:
        """Whether ``arg`` is a short option of this parser, or a flag repeated (``-vv``)."""
        return arg in self._option_string_actions or (
            len(set(arg[1:])) == 1 and arg[:2] in self._option_string_actions
            and self._option_string_actions[arg[:2]].nargs == 0)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of every command."""
    parser = _Parser(
        prog="splineplan",
        description="Spline-based multi-level planning for autonomous vehicles in SUMO.",
    )
    parser.add_argument("--version", action="version", version=f"splineplan {__version__}")
    parser.add_argument("-v", "--verbose", action="count", default=0,
                        help="log more (-v info, -vv debug)")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND",
                                parser_class=_Parser)
    for name, add in sorted(_registry().items()):
        add(sub)
        del name
    for command in sub.choices.values():  # -v after the command too, as before it
        command.add_argument("-v", "--verbose", action="count", default=argparse.SUPPRESS,
                             help="log more (-v info, -vv debug)")
    return parser


def _registry() -> dict[str, Callable[[argparse._SubParsersAction], None]]:
    """Every ``_add_<name>`` function of this module, by command name."""
    return {name[5:]: fn for name, fn in globals().items()
            if name.startswith("_add_") and callable(fn)}


#: Commands that run the planner (the first use of an install compiles its inner loops).
_PLANNING = ("plan", "plan-image", "simulate", "bench", "commonroad")


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``splineplan`` console script."""
    parser = build_parser()
    args = parser.parse_args(argv)
    level = logging.WARNING - 10 * min(args.verbose, 2)
    logging.basicConfig(level=level, format="%(levelname)s %(name)s: %(message)s")
    if args.command in _PLANNING:
        from splineplan import precompile

        todo = precompile.missing()
        if todo:
            print(f"splineplan {args.command}: compiling the planner's inner loops, once after "
                  "an install (about 17 s on two free cores, 30 s on one; cached for later "
                  "runs)", file=sys.stderr)
            precompile.ensure(modules=todo)
    try:
        return int(args.func(args))
    except SplineplanError as err:
        print(f"splineplan {args.command}: error: {err}", file=sys.stderr)
        return 2
    except OSError as err:  # a file that could not be read or written after the checks
        what = f"{err.strerror}: {err.filename}" if err.filename else str(err)
        print(f"splineplan {args.command}: error: {what}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"splineplan {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
