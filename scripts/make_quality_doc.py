#!/usr/bin/env python
"""Write docs/quality.md, the table of every quality check, from the table of
``crosssection/quality.py``'s docstring (the one source of the checks' limits).

Usage: python scripts/make_quality_doc.py [--out docs/quality.md]
"""
from __future__ import annotations

import argparse
import importlib
import inspect
import re
from pathlib import Path

#: The modules that define the categories of QualityWarning that are no check of one scan
OTHER_MODULES = ("crosssection.quality", "crosssection.batch", "crosssection.stats.data",
                 "crosssection.stats.fits", "simulate.ensemble", "simulate.compact",
                 "simulate.render")

OTHER_HEAD = """
## Other warnings

Categories of `QualityWarning` raised on a set, a batch, the statistics or the simulator rather
than by the checks of one scan (each class's docstring). `SetWarning` is raised by `analyze`
when the scan's set (its `set.toml`, or a `calibration.csv` beside it) holds values the
analysis was not given (`batch` reads the set; in Python,
`crosssection.setconfig.load_set_config(toml_path).params_for(image)` gives them).

| category | module | raised when |
|---|---|---|
"""

HEAD = """# Quality checks

Every analysis runs these checks (`crosssection/quality.py`, where each limit is derived). A
failed check is a `warning: FILE: ...` line on stderr, a `warnings.warn` of its own category
(a subclass of its group's, itself a `crosssection.QualityWarning`), an entry of the `quality`
block of `summary.json` (`code`, `message`, `value`, `limit`) and a code in the `quality`
column of a batch's `index.csv`. Silence one check in Python with
`warnings.simplefilter("ignore", crosssection.quality.NoCalibrationWarning)`, or a group with
`CalibrationWarning`. The other categories of `QualityWarning` are no checks of one scan
(section "Other warnings" below); ignoring `QualityWarning` silences them too.

| code | category (group) | measured | flagged when |
|---|---|---|---|
"""


def check_rows() -> list[tuple[str, str, str]]:
    """(code, what is measured, limit) of each row of the docstring's table."""
    import crosssection.quality as q

    lines = q.__doc__.split("\n")
    rules = [i for i, line in enumerate(lines) if line.startswith("=====")]
    widths = [len(w) for w in lines[rules[0]].split()]
    a, b = widths[0] + 2, widths[0] + 2 + widths[1] + 2
    rows = []
    for line in lines[rules[1] + 1:rules[2]]:
        code, what, limit = line[:a].strip(), line[a:b].strip(), line[b:].strip()
        if code:
            rows.append([code, what, limit])
        else:
            rows[-1][1] += f" {what}" if what else ""
            rows[-1][2] += f" {limit}" if limit else ""
    return [tuple(r) for r in rows]


def other_warnings() -> list[type]:
    """The subclasses of QualityWarning that are neither a check's category nor a group of
    them, in the order of :data:`OTHER_MODULES` and of their definition."""
    import crosssection.quality as q

    checks = set(q.CHECK_WARNINGS.values())
    groups = {c.__mro__[1] for c in checks}
    out = []
    for name in OTHER_MODULES:
        mod = importlib.import_module(name)
        classes = [c for c in vars(mod).values() if inspect.isclass(c)
                   and issubclass(c, q.QualityWarning) and c.__module__ == name
                   and c is not q.QualityWarning and c not in checks and c not in groups]
        out += sorted(classes, key=lambda c: inspect.getsourcelines(c)[1])
    return out


def _markdown(rst: str) -> str:
    """A docstring's roles and literals as markdown code."""
    text = re.sub(r":\w+:`~?([^`]+)`", r"`\1`", " ".join(rst.split()))
    return text.replace("``", "`")


def page() -> str:
    import crosssection.quality as q

    out = []
    for code, what, limit in check_rows():
        cls = q.CHECK_WARNINGS[code]
        out.append(f"| `{code}` | `{cls.__name__}` (`{cls.__mro__[1].__name__}`) | "
                   f"{what.replace('``', '`')} | {limit.replace('``', '`')} |")
    other = [f"| {c.__name__} | `{c.__module__}` | {_markdown(c.__doc__ or '')} |"
             for c in other_warnings()]
    return HEAD + "\n".join(out) + "\n" + OTHER_HEAD + "\n".join(other) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", default=str(Path(__file__).resolve().parents[1] / "docs" /
                                         "quality.md"))
    args = ap.parse_args(argv)
    Path(args.out).write_text(page())
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
