"""Command line: ``python -m simulate {quench,anneal,render,validate,compact,benchmark} ...``."""
from __future__ import annotations

import argparse

from crosssection.cli import make_parser, started

SUBCOMMANDS = {
    "quench": "simulate.ensemble",
    "anneal": "simulate.ensemble",
    "render": "simulate.render",
    "validate": "simulate.validate",
    "compact": "simulate.compact",
    "benchmark": "simulate.atlas",
}


def build_parser(argv=None) -> argparse.ArgumentParser:
    return make_parser(
        "python -m simulate",
        "Quench simulator of a confined inextensible rod; renders configurations into "
        "synthetic scans with exact ground truth and validates the pipeline.", SUBCOMMANDS,
        argv)


def main(argv=None) -> int:
    """Run the ``simulate`` CLI; return the exit status."""
    return started(build_parser, argv)
