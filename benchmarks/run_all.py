#!/usr/bin/env python
"""Run every benchmark script in this folder (one after the other) and print their output.

Usage: python benchmarks/run_all.py [--quick]   (--quick is forwarded to scripts accepting it)
"""
from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    status = 0
    for script in sorted(HERE.glob("*.py")):
        if script.name == Path(__file__).name or script.name.startswith("_"):
            continue
        args = [a for a in argv if a == "--quick" and "--quick" in script.read_text()]
        print(f"===== {script.name} {' '.join(args)}", flush=True)
        t0 = time.perf_counter()
        proc = subprocess.run([sys.executable, str(script), *args], capture_output=True, text=True)
        sys.stdout.write(proc.stdout)
        if proc.returncode:
            sys.stdout.write(proc.stderr[-3000:])
            status = 1
        print(f"===== {script.name}: exit {proc.returncode}, {time.perf_counter() - t0:.1f} s\n",
              flush=True)
    return status


if __name__ == "__main__":
    sys.exit(main())
