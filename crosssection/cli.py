"""Command line: ``python -m crosssection {analyze,steps,batch,stats} ...``.

Each subcommand lives in the module of its stage and registers itself through
``add_subparser(subparsers)``; this module only dispatches and turns expected failures
into one line on stderr (file and cause) with a non-zero exit status.
"""
from __future__ import annotations

import argparse
import importlib
import sys

from ._version import __version__
from .errors import FoldstatError

# subcommand -> module providing add_subparser(subparsers)
SUBCOMMANDS = {
    "analyze": "crosssection.commands",
    "steps": "crosssection.commands",
    "batch": "crosssection.batch",
    "stats": "crosssection.stats.cli",
}


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="python -m crosssection",
        description="Analyse scans of folded-sheet cross-sections into junctions, stacks, "
                    "branches and voids; batch them; compute ensemble statistics.")
    parser.add_argument("--version", action="version", version=f"foldstat {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    seen = set()
    for modname in dict.fromkeys(SUBCOMMANDS.values()):
        if modname in seen:
            continue
        seen.add(modname)
        try:
            module = importlib.import_module(modname)
        except ModuleNotFoundError as exc:  # a subcommand module not installed in this build
            if exc.name != modname:
                raise
            continue
        module.add_subparser(sub)
    return parser


def main(argv=None) -> int:
    """Run the CLI; return the exit status (0 success, 2 bad input, 1 unexpected error)."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except FoldstatError as exc:
        print(f"error: {exc.one_line()}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("error: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:  # noqa: BLE001 - last resort: one line, never a traceback
        print(f"error: unexpected {type(exc).__name__}: {' '.join(str(exc).split())}",
              file=sys.stderr)
        return 1
