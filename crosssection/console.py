"""The ``foldstat`` console command: every subcommand of ``python -m crosssection`` and
``python -m simulate`` under one name, plus ``samples`` (copy the bundled sample scans).

The subcommands are those registered in ``crosssection.cli.SUBCOMMANDS`` and
``simulate.cli.SUBCOMMANDS`` (subcommand -> module with ``add_subparser``), read when the
command runs, so a subcommand registered there appears here without further change.

Start-up stays light: ``foldstat --help`` reads each module's one-line help from its source
(``add_parser("name", help="...")``) instead of importing it, and only the module of the
subcommand that runs is imported. A registered module that is missing or broken is listed as
unavailable in ``foldstat --help`` and leaves the other subcommands working.
"""
from __future__ import annotations

import argparse
import ast
import importlib
import importlib.util
import re
import sys
from pathlib import Path

from crosssection._version import __version__

__all__ = ["main", "build_parser", "registered_subcommands", "EXIT_STATUS"]

#: modules holding a ``SUBCOMMANDS`` dict, in the order their subcommands are listed
SOURCES = ("crosssection.cli", "simulate.cli")
#: subcommands of the console alone
CONSOLE_SUBCOMMANDS = {"samples": "crosssection.samples"}

EXIT_STATUS = """\
exit status:
  0    success
  2    bad input or parameters: one line on stderr naming the file and the cause
  3    a batch, an ensemble or a validation finished but some images, configurations or
       scenes failed (listed in OUT_DIR/failures.csv; a re-run tries them again)
  130  interrupted (re-run the same command to resume; stats leaves its report as it was)
  143  terminated by SIGTERM (as 130)
  1    a bug (one line on stderr, never a traceback)
Doubtful results are printed as 'warning: FILE: ...' lines on stderr."""

DESCRIPTION = (
    "Folding statistics of confined elastic sheets and rods: analyse scans of cut "
    "cross-sections (analyze, steps, batch), compute ensemble statistics (stats), simulate "
    "the folding of a confined rod (quench, anneal) and compact it (compact), render "
    "simulations as scans and validate the analysis on them (render, validate), chart "
    "accuracy and speed (benchmark). 'foldstat COMMAND --help' lists every option "
    "of a command with its unit and default.")


def registered_subcommands() -> tuple[dict, dict]:
    """Subcommand -> module of both command-line tools and of the console.

    Each ``SUBCOMMANDS`` dict is read from its module's source when it is a plain literal
    that nothing in the module changes afterwards (no import of numpy for ``--help``), else
    the module is imported.

    Returns
    -------
    (commands, unavailable) : (dict, dict)
        ``commands`` maps each subcommand to its module, in listing order; ``unavailable``
        maps a source (``crosssection.cli`` or ``simulate.cli``) that cannot be imported to
        the reason.
    """
    commands, unavailable = {}, {}
    for source in SOURCES:
        try:
            table = _literal_table(source)
            if table is None:
                table = importlib.import_module(source).SUBCOMMANDS
        except Exception as exc:  # noqa: BLE001 - one broken tool must not hide the other
            unavailable[source] = _reason(exc)
            continue
        for name, module in table.items():
            commands.setdefault(name, module)
    for name, module in CONSOLE_SUBCOMMANDS.items():
        commands.setdefault(name, module)
    return commands, unavailable


def _literal_table(source: str) -> dict | None:
    """``source.SUBCOMMANDS`` read from the module's source, or None when it is not one
    literal ``{str: str}`` assignment left unchanged (no item assignment, method call or
    second assignment in the module)."""
    path = _module_file(source)
    if path is None:
        return None
    try:
        tree = ast.parse(path.read_text(encoding="utf-8"))
    except (OSError, SyntaxError, UnicodeDecodeError):
        return None
    table = None
    for node in tree.body:
        if (isinstance(node, ast.Assign) and len(node.targets) == 1
                and isinstance(node.targets[0], ast.Name)
                and node.targets[0].id == "SUBCOMMANDS"):
            if table is not None:
                return None
            try:
                table = ast.literal_eval(node.value)
            except ValueError:
                return None
    if not isinstance(table, dict) or not all(isinstance(k, str) and isinstance(v, str)
                                              for k, v in table.items()):
        return None
    for node in ast.walk(tree):
        if isinstance(node, (ast.Attribute, ast.Subscript)) and \
                isinstance(node.value, ast.Name) and node.value.id == "SUBCOMMANDS":
            return None  # SUBCOMMANDS.update(...), SUBCOMMANDS["x"] = ...
        if isinstance(node, (ast.AugAssign, ast.AnnAssign, ast.Global)) and \
                "SUBCOMMANDS" in ast.dump(node):
            return None
    return table


def _reason(exc: BaseException) -> str:
    return f"{type(exc).__name__}: {' '.join(str(exc).split())}"


def _module_file(modname: str) -> Path | None:
    """The source file of ``modname`` without importing it (nor its parent packages below
    the top level: ``crosssection.stats`` imports scipy and pandas)."""
    top, *rest = modname.split(".")
    try:
        spec = importlib.util.find_spec(top)
    except (ImportError, ValueError):
        return None
    if spec is None:
        return None
    if not rest:
        return Path(spec.origin) if spec.origin else None
    for base in spec.submodule_search_locations or ():
        path = Path(base, *rest[:-1])
        for cand in (path / rest[-1] / "__init__.py", path / f"{rest[-1]}.py"):
            if cand.is_file():
                return cand
    return None


def _helps_from_source(modname: str) -> dict | None:
    """``{subcommand: help}`` of the ``add_parser`` calls of a module, read from its source;
    None when the module cannot be found or a name or help is not a plain string."""
    path = _module_file(modname)
    if path is None:
        return None
    try:
        text = path.read_text(encoding="utf-8")
        # the calls sit in add_subparser: parsing only that function (up to the next line
        # at column 0) keeps --help fast on big modules; a cut too early misses a name and
        # the caller falls back to importing the module
        start = re.search(r"^def add_subparser\b", text, re.M)
        if start is not None:
            text = text[start.start():]
            end = re.compile(r"^\S", re.M).search(text, text.find("\n") + 1)
            text = text[:end.start()] if end else text
        tree = ast.parse(text)
    except (OSError, SyntaxError, UnicodeDecodeError):
        return None
    helps = {}
    for node in ast.walk(tree):
        if (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
                and node.func.attr == "add_parser"):
            if not (node.args and isinstance(node.args[0], ast.Constant)
                    and isinstance(node.args[0].value, str)):
                return None
            kw = {k.arg: k.value for k in node.keywords}
            text = kw.get("help")
            if not (isinstance(text, ast.Constant) and isinstance(text.value, str)):
                return None
            helps[node.args[0].value] = text.value
    return helps


def _helps_by_import(modname: str) -> dict:
    """``{subcommand: help}`` registered by a module's ``add_subparser`` (imports it)."""
    scratch = argparse.ArgumentParser(add_help=False).add_subparsers()
    importlib.import_module(modname).add_subparser(scratch)
    return {a.dest: a.help or "" for a in scratch._choices_actions}


def _command_helps(commands: dict, skip_module: str | None = None) -> tuple[dict, dict]:
    """One-line help of every subcommand (``skip_module``'s are registered for real).

    Returns
    -------
    (helps, unavailable) : (dict, dict)
        Subcommand -> help, and subcommand -> why its module cannot be used.
    """
    helps, unavailable, per_module = {}, {}, {}
    for name, module in commands.items():
        if module == skip_module:
            continue
        if module not in per_module:
            found = _helps_from_source(module)
            if found is None or any(n not in found for n, m in commands.items()
                                    if m == module):
                try:
                    found = _helps_by_import(module)
                except Exception as exc:  # noqa: BLE001 - listed as unavailable instead
                    found = _reason(exc)
            per_module[module] = found
        found = per_module[module]
        if isinstance(found, str):
            unavailable[name] = found
        elif name in found:
            helps[name] = found[name]
        else:
            unavailable[name] = f"{module} registers no subcommand {name!r}"
    return helps, unavailable


class _Parser(argparse.ArgumentParser):
    """``crosssection.cli.OneLineParser``'s one-line usage errors, imported only when an
    error is reported (that module imports numpy)."""

    def parse_known_args(self, args=None, namespace=None):
        # the words parsed, for the hint on a file named like an option
        # (crosssection.cli._dash_hint)
        args = list(sys.argv[1:] if args is None else args)
        self._words = args
        return argparse.ArgumentParser.parse_known_args(self, args, namespace)

    def error(self, message):
        from crosssection.cli import OneLineParser

        OneLineParser.error(self, message)

    def _print_message(self, message, file=None):
        # argparse drops a failed write of --help or --version (a full disk): let it fail,
        # so that the command says so and exits 2
        if message:
            (file or sys.stderr).write(message)


def _chosen(argv) -> str | None:
    """The subcommand named in ``argv``: its first word not starting with '-' (the top level
    has no option that takes a value)."""
    for word in argv:
        if not word.startswith("-"):
            return word
    return None


def build_parser(argv=None) -> argparse.ArgumentParser:
    """The ``foldstat`` parser, with the subcommand named in ``argv`` fully registered.

    Parameters
    ----------
    argv : list of str, optional
        The command line (default ``sys.argv[1:]``): only the module of the subcommand it
        names is imported; the others are listed with their one-line help.

    Returns
    -------
    argparse.ArgumentParser
    """
    argv = sys.argv[1:] if argv is None else list(argv)
    commands, broken_sources = registered_subcommands()
    module = commands.get(_chosen(argv))
    real = None
    if module is not None:
        try:
            real = importlib.import_module(module)
        except Exception:  # noqa: BLE001 - reported below as an unavailable subcommand
            real = None
    helps, unavailable = _command_helps(commands, module if real is not None else None)
    epilog = EXIT_STATUS
    notes = [f"  {name}: {why}" for name, why in {**broken_sources, **unavailable}.items()]
    if notes:
        epilog += "\n\nunavailable here:\n" + "\n".join(notes)
    parser = _Parser(prog="foldstat", description=DESCRIPTION, epilog=epilog,
                           formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--version", action="version", version=f"foldstat {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND",
                                title="commands")
    done = set()
    for name, mod in commands.items():
        if mod == module and real is not None:
            if mod not in done:
                real.add_subparser(sub)
                done.add(mod)
        elif name in helps:
            sub.add_parser(name, help=helps[name], add_help=False)
    return parser


def main(argv=None) -> int:
    """Run ``foldstat``; return the exit status (see ``foldstat --help``)."""
    argv = sys.argv[1:] if argv is None else list(argv)
    commands, _ = registered_subcommands()
    name = _chosen(argv)
    if name not in commands:
        # --help, --version, no or an unknown subcommand: argparse prints and exits
        try:
            build_parser(argv).parse_args(argv)
        except OSError as exc:  # the text could not be written (a full disk)
            print(f"error: output: {exc.strerror or exc}", file=sys.stderr)
            return 2
        return 2  # pragma: no cover - parse_args exits above
    try:
        importlib.import_module(commands[name])
    except KeyboardInterrupt:
        print("error: interrupted before the command started", file=sys.stderr)
        return 130
    except Exception as exc:  # noqa: BLE001 - a broken module: one line, never a traceback
        print(f"error: foldstat {name}: unavailable ({commands[name]}: {_reason(exc)})",
              file=sys.stderr)
        return 1
    from crosssection.cli import started

    return started(build_parser, argv)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
