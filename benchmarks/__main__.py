"""Run the benchmarks: ``python -m benchmarks [NAME [args ...]]`` (default: all).

Each ``bench_<name>.py`` module has a ``main(argv)`` that prints its medians and ratios.
With a name, the arguments after it go to that benchmark's ``main``
(``python -m benchmarks pipeline --routes 6``); several names without arguments run in
turn.
"""

from __future__ import annotations

import importlib
import pkgutil
import sys

import benchmarks


def main(argv: list[str]) -> int:
    names = sorted(m.name[6:] for m in pkgutil.iter_modules(benchmarks.__path__)
                   if m.name.startswith("bench_"))
    if not argv:
        runs: list[tuple[str, list[str]]] = [(name, []) for name in names]
    elif any(a.startswith("-") for a in argv):
        runs = [(argv[0], argv[1:])]  # one benchmark with its own arguments
    else:
        runs = [(name, []) for name in argv]
    unknown = {name for name, _ in runs} - set(names)
    if unknown:
        print(f"unknown benchmark(s): {', '.join(sorted(unknown))}; have: {', '.join(names)}")
        return 2
    for name, args in runs:
        print(f"== {name} ==", flush=True)
        importlib.import_module(f"benchmarks.bench_{name}").main(args)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
