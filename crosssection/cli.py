"""Command line: ``python -m crosssection {analyze,steps,batch,stats} ...``.

Each subcommand lives in the module of its stage and registers itself through
``add_subparser(subparsers)``; this module only dispatches and turns expected failures
into one line on stderr (file and cause) with a non-zero exit status.
"""
from __future__ import annotations

import argparse
import contextlib
import importlib
import os
import signal
import sys
import threading
import warnings
from contextlib import contextmanager

from crosssection._version import __version__
from crosssection.console import _Parser
from crosssection.core.errors import FoldstatError, printable
from crosssection.quality import QualityWarning

#: exit status of a command stopped by SIGINT (Ctrl-C), and by SIGTERM (128 + signal number, as
#: a shell reports a process killed by the signal)
INTERRUPTED = 130
TERMINATED = 128 + int(signal.SIGTERM)

# subcommand -> module providing add_subparser(subparsers)
SUBCOMMANDS = {
    "analyze": "crosssection.commands",
    "steps": "crosssection.commands",
    "batch": "crosssection.batch",
    "stats": "crosssection.stats.cli",
    "samples": "crosssection.samples",
}


class OneLineParser(argparse.ArgumentParser):
    """An ``ArgumentParser`` whose usage errors are one ``error:`` line and exit status 2
    (argparse's default prints the usage block as well)."""

    parse_known_args = _Parser.parse_known_args

    def error(self, message):
        print(f"error: {self.prog}: {' '.join(message.split())}{_dash_hint(self, message)}",
              file=sys.stderr)
        raise SystemExit(2)

    _print_message = _Parser._print_message


def _dash_hint(parser, message: str) -> str:
    """A hint, for an argument missing or not recognised, where the words parsed hold an
    option of ``parser`` after ``--`` (argparse reads it as a file name) or a scan's file name
    starting with '-' before it (argparse reads it as an option); else ''."""
    from crosssection.core.schema import IMAGE_SUFFIXES

    if not message.startswith(("the following arguments are required",
                               "unrecognized arguments")):
        return ""
    words = getattr(parser, "_words", [])
    cut = words.index("--") if "--" in words else len(words)
    options = parser._option_string_actions
    if any(w.split("=", 1)[0] in options for w in words[cut + 1:]):
        return " (every word after '--' is read as a file name: give the options before it)"
    named = [w for w in words[:cut] if w.startswith("-") and not w.startswith("--")
             and w.lower().endswith(IMAGE_SUFFIXES)]
    if not named:
        return ""
    return (f" ({named[0]} is read as an option: name a file starting with '-' as "
            f"./{named[0]})")


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


class Terminated(KeyboardInterrupt):
    """SIGTERM received while a command runs (:func:`signals_as_interrupts`).

    A ``KeyboardInterrupt``, so that whatever stops cleanly on Ctrl-C (a pool's workers
    terminated, atomic writes left whole, a batch's index written) stops the same way when a
    job runner or ``kill`` ends the command.
    """


#: the signals received by each command running (innermost last): :func:`interrupt_received`
_RUNNING: list[list[int]] = []


@contextmanager
def signals_as_interrupts():
    """Raise :class:`Terminated` in the main thread on SIGTERM inside the block, and record
    SIGINT as well as SIGTERM (:func:`interrupt_received`).

    SIGINT raises ``KeyboardInterrupt`` as Python's own handler does; it is recorded so that
    an interrupt that the code running caught and turned into another error (matplotlib
    does while it draws) or swallowed (one raised inside a garbage collector's callback) is
    still known. A SIGINT that is ignored (a background job) or handled by the caller is
    left as it is.

    The handlers are the command line's, not the library's: they are installed here, only
    in the main thread (the only one that may set handlers), and the previous ones are put
    back on leaving, so that calling ``main(argv)`` in a process leaves its signal handling
    as it was.

    Yields
    ------
    list
        The signal numbers received (empty unless SIGINT or SIGTERM arrived).
    """
    received = []
    if threading.current_thread() is not threading.main_thread():
        yield received
        return

    def on_term(signum, frame):
        received.append(signum)
        raise Terminated()

    def on_int(signum, frame):
        received.append(signum)
        raise KeyboardInterrupt

    previous = {signal.SIGTERM: signal.signal(signal.SIGTERM, on_term)}
    if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
        previous[signal.SIGINT] = signal.signal(signal.SIGINT, on_int)
    _RUNNING.append(received)
    try:
        yield received
    finally:
        del _RUNNING[next(i for i, r in enumerate(_RUNNING) if r is received)]
        for signum, handler in previous.items():
            # None: a handler set outside Python, which cannot be put back; the default is
            # closest
            signal.signal(signum, signal.SIG_DFL if handler is None else handler)


def interrupt_received() -> KeyboardInterrupt | None:
    """The interrupt the running command was sent, or None.

    Returns
    -------
    KeyboardInterrupt or None
        :class:`Terminated` after a SIGTERM, ``KeyboardInterrupt`` after a SIGINT, None
        before either (or outside :func:`signals_as_interrupts`). A new exception at each
        call, to be raised by a caller that found the interrupt caught by the code it ran.
    """
    # a command run inside another leaves SIGINT to the outer one's handler
    received = [signum for signals in _RUNNING for signum in signals]
    if signal.SIGTERM in received:
        return Terminated()
    return KeyboardInterrupt() if received else None


def run_parsed(parser: argparse.ArgumentParser, argv=None) -> int:
    """Parse ``argv`` and run the chosen subcommand.

    Returns the exit status: 0 success, 2 bad input (one line naming the file and the cause),
    3 a batch finished with some images failed, 130 interrupted (SIGINT) and 143 terminated
    (SIGTERM) (re-running resumes; stats leaves its report as it was), 1 unexpected error
    (one line, never a traceback). Quality warnings are printed as ``warning: FILE: ...``
    lines on stderr.
    """
    with signals_as_interrupts() as received, _escaping_stdout(), _closed_pipes_ignored():
        status = _run_parsed(parser, argv)
        # a command that reports its own interrupt (stats) returns INTERRUPTED
        return (TERMINATED if signal.SIGTERM in received and status == INTERRUPTED
                else status)


@contextlib.contextmanager
def _escaping_stdout():
    """Standard output that shows what its encoding cannot hold (a file name in an ASCII
    terminal, bytes of a name that are not UTF-8) as backslash escapes, as standard error
    does, instead of failing after the work is done."""
    out = sys.stdout
    strict = getattr(out, "errors", None) == "strict" and hasattr(out, "reconfigure")
    if strict:
        out.flush()
        out.reconfigure(errors="backslashreplace")
    try:
        yield
    finally:
        if strict:
            out.flush()
            out.reconfigure(errors="strict")


class _PipeWriter:
    """A text stream whose reader may go away (``| head -1``): once a write meets a closed
    pipe, the stream's descriptor is pointed at the null device and the rest of the output is
    dropped, so that the command finishes its work (its files are its result) instead of
    failing on its messages."""

    def __init__(self, stream):
        self._stream = stream

    def _closed(self):
        try:
            null = os.open(os.devnull, os.O_WRONLY)
        except OSError:
            return
        try:
            os.dup2(null, self._stream.fileno())
        except (OSError, ValueError, AttributeError):
            pass  # a stream without a descriptor (a test's capture): dropped writes suffice
        finally:
            os.close(null)

    def write(self, text):
        try:
            return self._stream.write(text)
        except BrokenPipeError:
            self._closed()
            return len(text)

    def flush(self):
        try:
            self._stream.flush()
        except BrokenPipeError:
            self._closed()

    def __getattr__(self, name):
        return getattr(self._stream, name)


@contextlib.contextmanager
def _closed_pipes_ignored():
    """Standard output and error as :class:`_PipeWriter` for the command's run."""
    out, err = sys.stdout, sys.stderr
    sys.stdout, sys.stderr = _PipeWriter(out), _PipeWriter(err)
    try:
        yield
    finally:
        for wrapped in (sys.stdout, sys.stderr):
            try:
                wrapped.flush()
            except (OSError, ValueError):
                pass
        sys.stdout, sys.stderr = out, err


def _resume_hint(args) -> str:
    """How to resume a stopped command. A batch given --force redoes every scan again when
    re-run with it, and keeps the scans done earlier, redone or not, without it: it says
    so."""
    if getattr(args, "force", False):
        return ("re-run the same command to resume; with --force it redoes every scan again, "
                "without it keeps the scans already done, redone by this run or not")
    if getattr(args, "command", None) in _ONE_SHOT:
        # one scan's run has nothing to resume: its folder holds the earlier run's files
        return "no file was written; re-run the same command"
    return "re-run the same command to resume"


#: commands whose output is written at once at their end: a stopped run resumes nothing
_ONE_SHOT = ("analyze", "steps")


def _run_parsed(parser: argparse.ArgumentParser, argv=None) -> int:
    args = None
    try:
        try:
            args = parser.parse_args(argv)
        except SystemExit:
            # --help, --version or a usage error, printed by argparse: an output that cannot
            # take the text (a full disk) is an error too, not a silent success
            sys.stdout.flush()
            raise
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            try:
                status = int(args.func(args) or 0)
            except (KeyboardInterrupt, Terminated):
                # a stopped batch, render or ensemble shows the doubts of the work it
                # finished, which its re-run skips (a one-shot command kept nothing); an
                # error (exit 2) is one line alone
                if getattr(args, "command", None) not in _ONE_SHOT:
                    _print_warnings(caught)
                raise
        _print_warnings(caught)
        return status
    except FoldstatError as exc:
        print(f"error: {exc.one_line()}", file=sys.stderr)
        return 2
    except OSError as exc:
        # the output (or an input) path cannot be used: the user's to fix, not a bug
        where = (" ".join(printable(exc.filename).splitlines()) if exc.filename is not None
                 else "output")
        why = exc.strerror or str(exc)
        if isinstance(exc, (FileExistsError, NotADirectoryError)):
            why = f"{why}: a file is in the way of a folder (give another --out)"
        print(f"error: {where}: {why}", file=sys.stderr)
        return 2
    except Terminated:
        print(f"error: terminated ({_resume_hint(args)})", file=sys.stderr)
        return TERMINATED
    except KeyboardInterrupt:
        print(f"error: interrupted ({_resume_hint(args)})", file=sys.stderr)
        return INTERRUPTED
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
            # a file name that is not UTF-8 (surrogate escapes) is shown escaped, not fatal
            line = f"warning: {' '.join(printable(str(w.message)).split())}"
            if line not in seen:
                seen.add(line)
                print(line, file=sys.stderr)


def build_parser(argv=None) -> argparse.ArgumentParser:
    return make_parser(
        "python -m crosssection",
        "Analyse scans of folded-sheet cross-sections into junctions, stacks, branches and "
        "voids; batch them; compute ensemble statistics; copy the sample scans.", SUBCOMMANDS,
        argv)


def started(build, argv=None) -> int:
    """Build the parser (``build(argv)``, which imports the subcommands' modules) and run the
    command; an interrupt while the modules load is one line too, exit 130."""
    try:
        parser = build(argv)
    except KeyboardInterrupt:
        print("error: interrupted before the command started", file=sys.stderr)
        return INTERRUPTED
    return run_parsed(parser, argv)


def main(argv=None) -> int:
    """Run the ``crosssection`` CLI; return the exit status."""
    return started(build_parser, argv)
