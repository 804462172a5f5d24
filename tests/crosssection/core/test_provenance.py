"""The scan's SHA-256, hashed on a thread while the scan is analysed."""
from __future__ import annotations

import os
import threading
import time

import pytest

from crosssection.core.provenance import file_sha256, sha256_in_background


def _hashing_threads():
    return [t for t in threading.enumerate() if t.name == "foldstat-sha256" and t.is_alive()]


def test_a_regular_file_is_hashed_on_a_thread(tmp_path):
    f = tmp_path / "scan.png"
    f.write_bytes(os.urandom(3 << 20))
    digest, problem = sha256_in_background(f)()
    assert problem is None and digest == file_sha256(f)
    assert _hashing_threads() == []


def test_a_file_changed_meanwhile_is_not_recorded(tmp_path):
    f = tmp_path / "scan.png"
    f.write_bytes(b"a" * 1000)
    waiting = sha256_in_background(f)
    time.sleep(0.01)
    f.write_bytes(b"b" * 2000)
    assert waiting() == (None, "the file changed while it was analysed")


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="named pipes are POSIX")
def test_a_named_pipe_is_not_opened(tmp_path):
    """Opening a pipe waits for a writer: a thread hashing one never ended, and an analysis
    waiting for it on its way out hung."""
    pipe = tmp_path / "pipe.png"
    os.mkfifo(pipe)
    t0 = time.perf_counter()
    digest, problem = sha256_in_background(pipe)()
    assert time.perf_counter() - t0 < 5
    assert digest is None and "not a regular file" in problem
    assert _hashing_threads() == []


def test_a_missing_file_says_why(tmp_path):
    digest, problem = sha256_in_background(tmp_path / "missing.png")()
    assert digest is None and "could not be read" in problem
