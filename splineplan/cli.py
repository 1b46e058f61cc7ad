"""Command-line interface: ``splineplan COMMAND ...``.

Each command has an ``_add_<name>`` function that declares its arguments and a
``_cmd_<name>`` function that runs it. Package errors print as one line on stderr with a
non-zero exit status.
"""

from __future__ import annotations

import argparse
import logging
import sys
from collections.abc import Callable, Sequence

from splineplan import __version__
from splineplan.errors import SplineplanError

Command = Callable[[argparse.Namespace], int]


# ---- commands (one _add_/_cmd_ pair each; keep them in this order) ----------------------

# ---- end of commands --------------------------------------------------------------------


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of every command."""
    parser = argparse.ArgumentParser(
        prog="splineplan",
        description="Spline-based multi-level planning for autonomous vehicles in SUMO.",
    )
    parser.add_argument("--version", action="version", version=f"splineplan {__version__}")
    parser.add_argument("-v", "--verbose", action="count", default=0,
                        help="log more (-v info, -vv debug)")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name, add in sorted(_registry().items()):
        add(sub)
        del name
    return parser


def _registry() -> dict[str, Callable[[argparse._SubParsersAction], None]]:
    """Every ``_add_<name>`` function of this module, by command name."""
    return {name[5:]: fn for name, fn in globals().items()
            if name.startswith("_add_") and callable(fn)}


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``splineplan`` console script."""
    parser = build_parser()
    args = parser.parse_args(argv)
    level = logging.WARNING - 10 * min(args.verbose, 2)
    logging.basicConfig(level=level, format="%(levelname)s %(name)s: %(message)s")
    try:
        return int(args.func(args))
    except SplineplanError as err:
        print(f"splineplan {args.command}: error: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"splineplan {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
