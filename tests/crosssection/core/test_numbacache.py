"""A read-only install run from a read-only home still has a numba cache folder."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from crosssection.core.numbacache import numba_cache_dir


def _no_write(path, mode):
    return not mode & os.W_OK


def test_nothing_is_set_where_numba_has_a_place(tmp_path):
    pkg = tmp_path / "pkg"
    pkg.mkdir()
    assert numba_cache_dir({}, package_dirs=[pkg], user_cache=tmp_path / "cache") is None
    # the packages read-only, the user's cache folder writable: numba's own fallback
    assert numba_cache_dir({}, package_dirs=[pkg], user_cache=tmp_path / "cache",
                           access=lambda p, m: Path(p) != pkg) is None
    # a cache folder the user set is theirs
    assert numba_cache_dir({"NUMBA_CACHE_DIR": "/x"}, package_dirs=[pkg],
                           user_cache=tmp_path, access=_no_write) is None


def test_a_folder_of_its_own_where_nothing_can_be_written(tmp_path):
    folder = numba_cache_dir({}, package_dirs=[tmp_path], user_cache=Path("/nonexistent/.cache"),
                             access=_no_write)
    assert folder is not None and "foldstat-numba-cache" in folder
    assert Path(folder).parent == Path(__import__("tempfile").gettempdir())


def test_a_home_that_cannot_be_entered_is_no_place(tmp_path, monkeypatch):
    # another user's HOME (sudo -u, a container's --user): Path.exists raised PermissionError
    # and every command died on import
    from crosssection.core import numbacache

    real = Path.exists

    def exists(self, **kw):
        if "locked" in self.parts:
            raise PermissionError(13, "Permission denied", str(self))
        return real(self, **kw)

    monkeypatch.setattr(Path, "exists", exists)
    folder = numbacache.numba_cache_dir({}, package_dirs=[tmp_path],
                                        user_cache=tmp_path / "locked" / ".cache" / "numba",
                                        access=_no_write)
    assert folder is not None and "foldstat-numba-cache" in folder


def test_the_package_sets_it_before_numba_is_imported(tmp_path):
    """``import crosssection`` in a process where nothing is writable: the variable is set,
    and numba (imported after) reads it."""
    code = (
        "import os\n"
        "import crosssection.core.numbacache as nc\n"
        "nc._writable = lambda folder, access=None: False\n"
        "nc.use_writable_cache()\n"
        "import numba.core.config as c\n"
        "print(os.environ['NUMBA_CACHE_DIR'] == c.CACHE_DIR and 'foldstat' in c.CACHE_DIR)\n")
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env)
    assert r.returncode == 0 and r.stdout.strip() == "True", r.stderr
