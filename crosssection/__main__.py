"""``python -m crosssection``: the subcommands of :mod:`crosssection.cli` and the console's
own ``samples`` (:data:`crosssection.console.CONSOLE_SUBCOMMANDS`), as ``foldstat`` offers
them."""
from __future__ import annotations

import sys

from crosssection import cli
from crosssection.console import CONSOLE_SUBCOMMANDS


def build_parser(argv=None):
    """The parser of :func:`crosssection.cli.build_parser` with ``samples`` registered too.

    Parameters
    ----------
    argv : list of str, optional
        The command line (default ``sys.argv[1:]``): only the module of the subcommand it
        names is imported.

    Returns
    -------
    argparse.ArgumentParser
    """
    argv = sys.argv[1:] if argv is None else list(argv)
    # the tool's name and description come from its own parser, built with one subcommand
    # (crosssection.commands: a few milliseconds beyond crosssection.cli's own imports)
    tool = cli.build_parser(["analyze"])
    return cli.make_parser(tool.prog, tool.description,
                           {**cli.SUBCOMMANDS, **CONSOLE_SUBCOMMANDS}, argv)


def main(argv=None) -> int:
    """Run ``python -m crosssection``; return the exit status."""
    argv = sys.argv[1:] if argv is None else list(argv)
    return cli.run_parsed(build_parser(argv), argv)


if __name__ == "__main__":
    sys.exit(main())
