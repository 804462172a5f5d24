"""The small synthetic sets of these tests lie below the sample sizes model selection and the
relations need, so every report on them carries a SmallSampleWarning; it is checked in
test_report.py (``small_samples`` tests) and ignored elsewhere, where other warnings are the
point (the project's settings turn quality warnings into errors)."""
from pathlib import Path

import pytest

HERE = Path(__file__).parent
IGNORE_SMALL = pytest.mark.filterwarnings(
    "ignore::crosssection.stats.fits.SmallSampleWarning")


def pytest_collection_modifyitems(items):
    for item in items:
        if HERE in Path(str(item.fspath)).parents and "small_samples" not in item.name:
            item.add_marker(IGNORE_SMALL)
