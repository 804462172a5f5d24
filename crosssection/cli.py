"""Command line: ``python -m crosssection {analyze,steps,batch,stats} ...``.

Each subcommand lives in the module of its stage and registers itself through
``add_subparser(subparsers)``; this module only dispatches and turns expected failures
into one line on stderr (file and cause) with a non-zero exit status.
"""
from __future__ import annotations

import argparse
import importlib
import sys
import warnings

from crosssection._version import __version__
from crosssection.core.errors import FoldstatError
from crosssection.quality import QualityWarning

# subcommand -> module providing add_subparser(subparsers)
SUBCOMMANDS = {
    "analyze": "crosssection.commands",
    "steps": "crosssection.commands",
    "batch": "crosssection.batch",
    "stats": "crosssection.stats.cli",
}


class OneLineParser(argparse.ArgumentParser):
    """An ``ArgumentParser`` whose usage errors are one ``error:`` line and exit status 2
    (argparse's default prints the usage block as well)."""

    def error(self, message):
        print(f"error: {self.prog}: {' '.join(message.split())}", file=sys.stderr)
        raise SystemExit(2)


def make_parser(prog: str, description: str, subcommands: dict,
                argv=None) -> argparse.ArgumentParser:
    """A parser whose subcommands are registered by their modules' ``add_subparser``.

    When ``argv`` (default ``sys.argv[1:]``) starts with a subcommand, only that subcommand's
    module is imported: ``analyze`` does not pay for the statistics' or the simulator's
    imports (about 1.5 s); otherwise (``--help``, a usage error) every subcommand is
    registered.
    """
    argv = sys.argv[1:] if argv is None else list(argv)
    parser = OneLineParser(prog=prog, description=description)
    parser.add_argument("--version", action="version", version=f"foldstat {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    chosen = argv[0] if argv and argv[0] in subcommands else None
    modules = [subcommands[chosen]] if chosen else list(dict.fromkeys(subcommands.values()))
    for modname in modules:
        importlib.import_module(modname).add_subparser(sub)
    return parser


def run_parsed(parser: argparse.ArgumentParser, argv=None) -> int:
    """Parse ``argv`` and run the chosen subcommand.

    Returns the exit status: 0 success, 2 bad input (one line naming the file and the cause),
    3 a batch finished with some images failed, 130 interrupted (re-running resumes; stats leaves its report as it was),
    1 unexpected error (one line, never a traceback). Quality warnings are printed as
    ``warning: FILE: ...`` lines on stderr.
    """
    args = parser.parse_args(argv)
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            status = int(args.func(args) or 0)
        _print_warnings(caught)
        return status
    except FoldstatError as exc:
        print(f"error: {exc.one_line()}", file=sys.stderr)
        return 2
    except OSError as exc:
        # the output (or an input) path cannot be used: the user's to fix, not a bug
        where = exc.filename if exc.filename is not None else "output"
        why = exc.strerror or str(exc)
        if isinstance(exc, (FileExistsError, NotADirectoryError)):
            why = f"{why}: a file is in the way of a folder (give another --out)"
        print(f"error: {where}: {why}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("error: interrupted (re-run the same command to resume)", file=sys.stderr)
        return 130
    except Exception as exc:  # noqa: BLE001 - last resort: one line, never a traceback
        print(f"error: unexpected {type(exc).__name__}: {' '.join(str(exc).split())}",
              file=sys.stderr)
        return 1


def _print_warnings(caught) -> None:
    """Our quality warnings as ``warning: FILE: ...`` lines; library warnings are dropped
    (what matters of them is already in our own checks)."""
    seen = set()
    for w in caught:
        if issubclass(w.category, QualityWarning):
            line = f"warning: {' '.join(str(w.message).split())}"
            if line not in seen:
                seen.add(line)
                print(line, file=sys.stderr)


def build_parser(argv=None) -> argparse.ArgumentParser:
    return make_parser(
        "python -m crosssection",
        "Analyse scans of folded-sheet cross-sections into junctions, stacks, branches and "
        "voids; batch them; compute ensemble statistics.", SUBCOMMANDS, argv)


def main(argv=None) -> int:
    """Run the ``crosssection`` CLI; return the exit status."""
    return run_parsed(build_parser(argv), argv)
