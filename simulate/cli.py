"""Command line: ``python -m simulate {quench,anneal,render,validate} ...``."""
from __future__ import annotations

import argparse
import importlib
import sys

from crosssection._version import __version__
from crosssection.errors import FoldstatError

SUBCOMMANDS = {
    "quench": "simulate.ensemble",
    "anneal": "simulate.ensemble",
    "render": "simulate.render",
    "validate": "simulate.validate",
}


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="python -m simulate",
        description="Quench simulator of a confined inextensible rod; renders configurations "
                    "into synthetic scans with exact ground truth and validates the pipeline.")
    parser.add_argument("--version", action="version", version=f"foldstat {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    for modname in dict.fromkeys(SUBCOMMANDS.values()):
        try:
            module = importlib.import_module(modname)
        except ModuleNotFoundError as exc:  # a subcommand module not installed in this build
            if exc.name != modname:
                raise
            continue
        module.add_subparser(sub)
    return parser


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except FoldstatError as exc:
        print(f"error: {exc.one_line()}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("error: interrupted (re-run the same command to resume)", file=sys.stderr)
        return 130
    except Exception as exc:  # noqa: BLE001
        print(f"error: unexpected {type(exc).__name__}: {' '.join(str(exc).split())}",
              file=sys.stderr)
        return 1
