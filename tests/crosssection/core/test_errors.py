"""Why a file could not be read, in words: a user reads "not a text file", not the name of a
Python exception."""
import io
import json

import numpy as np
import pandas as pd
import pytest

from crosssection.core.errors import why_unreadable


def _object_array():
    buf = io.BytesIO()
    np.save(buf, np.array([{"a": 1}], dtype=object), allow_pickle=True)
    buf.seek(0)
    return buf


def _raised(fn):
    try:
        fn()
    except Exception as exc:  # noqa: BLE001 - the exception is what is tested
        return exc
    raise AssertionError("nothing raised")


@pytest.mark.parametrize("read, words", [
    (lambda: json.loads(""), "empty file"),
    (lambda: json.loads("{bad"), "malformed JSON: Expecting property name enclosed in double "
                                  "quotes at line 1"),
    (lambda: b"\xff\xfe\x00".decode("utf-8"), "not a text file"),
    (lambda: pd.read_csv(io.StringIO("")), "empty file"),
    (lambda: np.load(io.BytesIO(b"junk, not an archive")), "not a NumPy archive of arrays"),
    (lambda: np.load(_object_array()), "not a NumPy archive of arrays"),
    (lambda: open("/", "rb"), "a folder, not a file"),
])
def test_reading_errors_are_said_in_words(read, words):
    exc = _raised(read)
    said = why_unreadable(exc)
    assert said == words
    assert type(exc).__name__ not in said
