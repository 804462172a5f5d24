"""``python -m crosssection stats DIR... --out REPORT_DIR``: ensemble statistics and report.

Each DIR is a batch output (every set folder inside becomes a set), a single ``analyze``
output, or a simulation ensemble from ``python -m simulate quench`` (one set named after the
folder, or after ``--name``).
"""
from __future__ import annotations

import argparse
from pathlib import Path

from crosssection.core.errors import ParameterError


def add_subparser(subparsers) -> argparse.ArgumentParser:
    """Register the ``stats`` subcommand on an ``argparse`` subparsers object."""
    p = subparsers.add_parser(
        "stats", help="ensemble statistics, fits and report of batch outputs or simulations",
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("dirs", nargs="+", metavar="DIR",
                   help="batch output, analyze output or simulation ensemble folder")
    p.add_argument("--out", required=True, metavar="REPORT_DIR",
                   help="report folder (created; files in it are replaced)")
    p.add_argument("--name", action="append", default=None,
                   help="set name for each DIR in order (repeat; default: the folder names)")
    p.add_argument("--seed", type=int, default=0, help="seed of bootstrap and GOF (default 0)")
    p.add_argument("--n-boot", type=int, default=200,
                   help="bootstrap resamples for parameter intervals (default 200)")
    p.add_argument("--n-mc", type=int, default=199,
                   help="parametric-bootstrap samples of the GOF p-values (default 199)")
    p.add_argument("--fast", action="store_true",
                   help="quick look: 50 bootstrap resamples and 49 GOF samples (default: off)")
    p.add_argument("--no-gof", action="store_true",
                   help="skip goodness-of-fit p-values (default: computed)")
    p.add_argument("--l-min-mm", type=float, default=1.0,
                   help="branch detection limit of images in mm (default 1; 0 = none)")
    p.add_argument("--s-min-mm2", type=float, default=1.0,
                   help="void detection limit of images in mm^2 (default (10h)^2 = 1; 0 = none)")
    p.add_argument("--no-figures", action="store_true",
                   help="tables only, no PNG figures (default: figures drawn)")
    p.add_argument("--progress", action=argparse.BooleanOptionalAction, default=None,
                   help="progress bars of the fits and figures on stderr (default: only when "
                        "stderr is a terminal)")
    p.set_defaults(func=run)
    return p


def run(args) -> int:
    """Load every DIR, compute the statistics and write the report."""
    import matplotlib

    matplotlib.use("Agg")  # a command line draws files, never windows
    from crosssection.stats.data import Ensemble, load_any
    from crosssection.stats.report import write_report
    from crosssection.stats.tables import StatsOptions

    if args.name and len(args.name) != len(args.dirs):
        raise ParameterError(f"--name given {len(args.name)} times for {len(args.dirs)} DIRs")
    for v, flag in ((args.n_boot, "--n-boot"), (args.n_mc, "--n-mc")):
        if v < 0:
            raise ParameterError(f"{flag} must be >= 0, got {v}")
    parts, seen = [], set()
    for i, d in enumerate(args.dirs):
        ens = load_any(d, set_name=args.name[i] if args.name else None,
                       l_min_mm=args.l_min_mm or None, s_min_mm2=args.s_min_mm2 or None)
        for s in ens.sets:  # two DIRs with the same folder name: keep the sets apart
            if s in seen:
                new = f"{s}#{i + 1}"
                for df in (ens.configs, ens.branches, ens.stacks, ens.voids):
                    df.loc[df["set"] == s, "set"] = new
                s = new
            seen.add(s)
        parts.append(ens)
    ens = Ensemble.concat(parts)
    n_boot, n_mc = (50, 49) if args.fast else (args.n_boot, args.n_mc)
    opts = StatsOptions(seed=args.seed, n_boot=n_boot, n_mc=n_mc, gof=not args.no_gof)
    paths = write_report(ens, args.out, opts=opts, inputs=args.dirs,
                         figures=not args.no_figures, progress=args.progress)
    print(f"stats: {len(ens.sets)} set(s), {len(ens.configs)} configurations, "
          f"{len(ens.branches)} branches -> {Path(args.out) / 'report.html'} "
          f"({len(paths)} files)")
    return 0
