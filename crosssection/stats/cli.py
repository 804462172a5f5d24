"""``stats DIR... --out REPORT_DIR``: ensemble statistics and report.

Each DIR is a batch output (every set folder inside becomes a set), a single ``analyze``
output, or a simulation ensemble from ``python -m simulate quench``, ``anneal`` or
``compact`` (one set named after the folder, or after ``--name``). ``--name exp`` for a batch of several sets ``A``, ``B`` names
them ``exp/A``, ``exp/B`` (a batch of one set: ``exp``); sets are never pooled. Sets of the
same name from different DIRs (two folders both named ``run``) are kept apart as ``run``,
``run#2``, ... (``#k``: the DIR's position); give ``--name`` once per DIR to name them.

REPORT_DIR is created, or replaced whole when it holds an earlier report: the new report is
written beside it and swapped in at the end, so an interrupted run leaves it as it was.
"""
from __future__ import annotations

import argparse
import math
import os
import sys
import warnings
from pathlib import Path

from crosssection.core.errors import ParameterError, one_line_path
from crosssection.core.fileio import check_out
from crosssection.stats.data import RECORDED
from crosssection.stats.fits import N_BOOT, N_BOOT_MIN, N_MC

#: resamples of ``--fast``, a quick look: bootstrap draws and goodness-of-fit samples
FAST_N_BOOT = 50
FAST_N_MC = 49
#: most resamples ``--n-boot`` and ``--n-mc`` take: each one refits every family to every
#: quantity of every set (about 0.3 s for one small set), so this many already runs for hours
MAX_RESAMPLES = 100_000


def add_subparser(subparsers) -> argparse.ArgumentParser:
    """Register the ``stats`` subcommand on an ``argparse`` subparsers object."""
    p = subparsers.add_parser(
        "stats", help="ensemble statistics, fits and report of batch outputs or simulations",
        description=__doc__.replace("``", ""),  # the docstring's markup is not for a terminal
        formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("dirs", nargs="+", metavar="DIR",
                   help="batch output, analyze output or simulation ensemble folder")
    p.add_argument("--out", required=True, metavar="REPORT_DIR",
                   help="report folder (created, or replaced whole when it holds a "
                        "previous report)")
    p.add_argument("--name", action="append", default=None,
                   help="set name for each DIR in order (repeat, once per DIR, each name "
                        "different, of ASCII letters, digits and . _ + -; default: the folder "
                        "names, a repeated one as NAME#k); the sets A, B of a batch DIR become "
                        "NAME/A, NAME/B")
    p.add_argument("--seed", type=int, default=0,
                   help="seed of bootstrap and GOF (default 0). Each set draws from its own "
                        "stream, derived from this seed and the set's name (stats.json "
                        "records it per set, sets.NAME.seed): a set's intervals and p-values "
                        "do not depend on the other sets, but the same data under another "
                        "set name (another folder name or --name) gives other ones; to "
                        "reproduce a report give the same --seed and the same set names "
                        "(--name)")
    # None: not given, so that --fast can tell a default from an explicit value
    p.add_argument("--n-boot", type=int, default=None,
                   help="bootstrap resamples for parameter intervals, 0 (none) to "
                        f"{MAX_RESAMPLES} (default {N_BOOT}); fewer than {N_BOOT_MIN} give "
                        "a warning: a 95 %% interval's ends are then the extreme draws")
    p.add_argument("--n-mc", type=int, default=None,
                   help="parametric-bootstrap samples of the GOF p-values, at most "
                        f"{MAX_RESAMPLES} (default {N_MC})")
    p.add_argument("--fast", action="store_true",
                   help=f"quick look: {FAST_N_BOOT} bootstrap resamples and {FAST_N_MC} GOF "
                        "samples, unless --n-boot or --n-mc is given, which wins "
                        "(default: off)")
    p.add_argument("--no-gof", action="store_true",
                   help="skip goodness-of-fit p-values (default: computed)")
    # None: not given, so that each scan keeps the limit its analysis used
    p.add_argument("--l-min-mm", type=float, default=None,
                   help="branch detection limit of images in mm, for every scan (default: "
                        "the l_min each scan was analysed with, from its summary.json; "
                        "0 = none; below the analysis' own it gives a warning)")
    p.add_argument("--s-min-mm2", type=float, default=None,
                   help="void detection limit of images in mm^2, for every scan (default: "
                        "the s_min each scan was analysed with, from its summary.json; "
                        "0 = none; below the analysis' own it gives a warning)")
    p.add_argument("--no-figures", action="store_true",
                   help="tables only, no PNG figures (default: figures drawn)")
    p.add_argument("--progress", action=argparse.BooleanOptionalAction, default=None,
                   help="progress bars of the fits and figures on stderr (default: only when "
                        "stderr is a terminal)")
    p.set_defaults(func=run)
    return p


def resamples(args) -> tuple[int, int]:
    """``(n_boot, n_mc)`` of the run: a value given on the command line, else that of
    ``--fast`` when given, else the default.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed ``stats`` options (``n_boot`` and ``n_mc`` None when not given).

    Returns
    -------
    (int, int)
    """
    fast = getattr(args, "fast", False)
    n_boot = args.n_boot if args.n_boot is not None else FAST_N_BOOT if fast else N_BOOT
    n_mc = args.n_mc if args.n_mc is not None else FAST_N_MC if fast else N_MC
    return n_boot, n_mc


def check_options(args) -> None:
    """Refuse absurd option values before any input is read.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed ``stats`` options.

    Raises
    ------
    ParameterError
        Naming the option: a count or seed below 0, a resample count above
        :data:`MAX_RESAMPLES`, ``--n-mc 0`` with p-values asked for, a detection limit that
        is negative or not finite, or ``--name`` not given once per DIR or giving one name
        to two DIRs.
    """
    if args.name and len(args.name) != len(args.dirs):
        raise ParameterError(f"given {len(args.name)} times for {len(args.dirs)} DIRs", "--name")
    if args.name:
        from crosssection.core.errors import ConfigError
        from crosssection.setconfig import valid_set_name

        for name in args.name:
            try:  # a set name is a folder of the report's tables: as a set.toml's name
                valid_set_name(name, None)
            except ConfigError as exc:
                raise ParameterError(exc.cause, "--name") from None
        seen = {}
        for d, name in zip(args.dirs, args.name):
            # the loader keeps the second apart as NAME#k, so a repeated name cannot pool two
            # DIRs: it would only hide which set is which (one folder given twice is read
            # once, whatever its names)
            if name in seen and Path(seen[name]).resolve() != Path(d).resolve():
                raise ParameterError(f"{name!r} given for both {seen[name]} and {d}: give "
                                     "each DIR its own set name", "--name")
            seen.setdefault(name, d)
    check_out(args.out)
    n_boot, n_mc = resamples(args)
    # a p-value needs a resample: --n-mc takes 1 or more (0 is refused below, saying why)
    for flag, v, least in (("--seed", args.seed, 0), ("--n-boot", n_boot, 0),
                           ("--n-mc", n_mc, 1)):
        if v < 0:
            raise ParameterError(f"must be an integer >= {least}, got {v}", flag)
    for flag, v in (("--n-boot", n_boot), ("--n-mc", n_mc)):
        if v > MAX_RESAMPLES:
            raise ParameterError(f"must be at most {MAX_RESAMPLES}, got {v}", flag)
    if args.no_gof and args.n_mc is not None:
        # quench refuses an option that has no effect too: its value would be recorded and
        # nothing done with it
        raise ParameterError("has no effect with --no-gof (no goodness-of-fit test is run): "
                             "give one of the two", "--n-mc")
    if n_mc == 0 and not args.no_gof:
        # without a resample there is no p-value to give
        raise ParameterError("0 resamples give no p-value: give an integer >= 1, or "
                             "--no-gof", "--n-mc")
    for flag, v in (("--l-min-mm", args.l_min_mm), ("--s-min-mm2", args.s_min_mm2)):
        if v is not None and not (math.isfinite(v) and v >= 0):
            raise ParameterError(f"must be a finite number >= 0 (0 = no limit), got {v:g}",
                                 flag)


def run(args) -> int:
    """Load every DIR, compute the statistics and write the report.

    An interrupt leaves the report folder as it was (the report is swapped in whole at the
    end): one ``error:`` line saying so and exit status 130. Warnings about the inputs are
    then dropped with the run, as they are with an error.
    """
    had_report = os.path.lexists(args.out)
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            status = _run(args)
    except KeyboardInterrupt as exc:
        from crosssection.cli import INTERRUPTED, TERMINATED, Terminated

        how = "terminated" if isinstance(exc, Terminated) else "interrupted"
        left = ("the report folder was left as it was" if had_report
                else "no report was written")
        print(f"error: {one_line_path(args.out)}: {how}; {left} (re-run the command to write "
              "it)", file=sys.stderr)
        return TERMINATED if isinstance(exc, Terminated) else INTERRUPTED
    for w in caught:  # hand them on to the command line, which prints ours as lines
        message = w.message
        if issubclass(w.category, Warning) and not _names_a_file(str(message)):
            # a warning about a set or an option: the report it is about is the FILE
            message = w.category(f"{args.out}: {message}")
        warnings.warn_explicit(message, w.category, w.filename, w.lineno)
    return status


def _names_a_file(message: str) -> bool:
    """Whether ``message`` starts with a file or folder (``FILE: ...``)."""
    head = message.split(": ", 1)[0]
    try:
        return bool(head) and Path(head).expanduser().exists()
    except (OSError, ValueError):
        return False


def _run(args) -> int:
    import matplotlib

    matplotlib.use("Agg")  # a command line draws files, never windows
    from crosssection.stats.data import load_inputs
    from crosssection.stats.report import check_report_dir, write_report
    from crosssection.stats.tables import StatsOptions

    check_options(args)
    check_report_dir(args.out, args.dirs)  # before the work, not after it
    ens = load_inputs(args.dirs, names=args.name,
                      l_min_mm=RECORDED if args.l_min_mm is None else args.l_min_mm,
                      s_min_mm2=RECORDED if args.s_min_mm2 is None else args.s_min_mm2)
    n_boot, n_mc = resamples(args)
    opts = StatsOptions(seed=args.seed, n_boot=n_boot, n_mc=n_mc, gof=not args.no_gof)
    given = {k: v for k, v in (("l_min_mm", args.l_min_mm), ("s_min_mm2", args.s_min_mm2))
             if v is not None}
    paths = write_report(ens, args.out, opts=opts, inputs=args.dirs,
                         figures=not args.no_figures, progress=args.progress,
                         limits_given=given)
    print(f"stats: {len(ens.sets)} set(s), {len(ens.configs)} configurations, "
          f"{len(ens.branches)} branches -> {one_line_path(Path(args.out) / 'report.html')} "
          f"({len(paths)} files)")
    return 0
