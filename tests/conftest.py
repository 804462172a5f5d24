"""Fixtures shared across the test tree (it mirrors the packages: tests/crosssection/...,
tests/simulate/...).

Scenes are generated, never read from fixtures on disk, so every test states the conditions it
runs under; session-scoped fixtures are generated once per worker.
"""
from __future__ import annotations

import os
from pathlib import Path

import pytest
from hypothesis import settings

REPO = Path(__file__).resolve().parents[1]

# The suite draws the same property-test examples on every run, so a clean clone passes or fails
# reproducibly; HYPOTHESIS_PROFILE=explore draws fresh ones on each run to look for new failures.
settings.register_profile("suite", derandomize=True, print_blob=True)
settings.register_profile("explore", derandomize=False, print_blob=True)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "suite"))


@pytest.fixture(scope="session")
def sample_dir() -> Path:
    """The bundled sample scans (``sample_images/``, with ``set.toml`` and truth scenes)."""
    return REPO / "sample_images"


@pytest.fixture(scope="session")
def scene_folder(tmp_path_factory):
    """A generated scene written in the scene-folder layout: ``(folder, scene)``.

    30 stacks of 1-4 layers, clean (seed 31).
    """
    from crosssection.truth.network import make_scene
    from crosssection.truth.scene import write_scene

    scene = make_scene(seed=31, n_stacks=30, max_layers=4)
    folder = tmp_path_factory.mktemp("scene")
    write_scene(scene, folder)
    return folder, scene


def _child_pids(pid: int) -> list[int]:
    """Every descendant of process ``pid`` (read from /proc)."""
    kids = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            ppid = int(stat.read_text().rsplit(")", 1)[1].split()[1])
        except (OSError, IndexError, ValueError):  # gone meanwhile
            continue
        if ppid == pid:
            kids.append(int(stat.parent.name))
    return kids + [g for k in kids for g in _child_pids(k)]


def _alive(pid: int) -> bool:
    """Whether process ``pid`` exists and is not a zombie."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except (OSError, IndexError):
        return False


@pytest.fixture
def signalled_run():
    """Run ``python ARGV`` in a subprocess, send ``sig`` to that process alone (as ``kill``,
    ``timeout`` or a job runner do) once ``ready(pid)`` holds, and return what came of it.

    The call is ``signalled_run(argv, sig, ready, env=None, within=20.0)``; it fails the test
    when the command ends before it is ready, or is still running ``within`` seconds after the
    signal (a hang check, not a speed measurement: the command is then killed with its
    children). Returns a namespace: ``returncode``, ``stderr``, ``children`` (the descendants
    at the signal), ``left`` (those still alive a few seconds after the exit; killed).
    """
    import os
    import signal
    import subprocess
    import sys
    import time
    from contextlib import suppress
    from types import SimpleNamespace

    if not Path("/proc/self/stat").exists():
        pytest.skip("needs /proc to find the command's child processes")

    def run(argv, sig, ready, env=None, within=20.0):
        # SIGINT as a terminal's job has it: a suite started in the background of a
        # non-interactive shell passes SIG_IGN on, which the command line rightly keeps
        proc = subprocess.Popen([sys.executable, *map(str, argv)], stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, text=True,
                                env=None if env is None else {**os.environ, **env},
                                preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
        start = time.monotonic()
        try:
            while not ready(proc.pid):
                if proc.poll() is not None:
                    pytest.fail(f"ended before the signal ({proc.returncode}): "
                                f"{proc.stderr.read()}")
                if time.monotonic() - start > 60:
                    pytest.fail("never got to work")
                time.sleep(0.05)
            children = _child_pids(proc.pid)
            proc.send_signal(sig)
            try:
                _, err = proc.communicate(timeout=within)
            except subprocess.TimeoutExpired:
                pytest.fail(f"still running {within:g} s after signal {sig}")
        finally:
            if proc.poll() is None:
                for pid in [proc.pid, *_child_pids(proc.pid)]:
                    with suppress(ProcessLookupError):
                        os.kill(pid, signal.SIGKILL)
                proc.communicate()
        # the resource tracker ends when the pipe of its (ended) parent closes
        end = time.monotonic() + 5
        while any(map(_alive, children)) and time.monotonic() < end:
            time.sleep(0.05)
        left = [pid for pid in children if _alive(pid)]
        for pid in left:
            with suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)
        return SimpleNamespace(returncode=proc.returncode, stderr=err, children=children,
                               left=left)

    return run
