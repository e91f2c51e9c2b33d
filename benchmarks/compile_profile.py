"""Where the first run's Numba compile time goes: per compile unit and per kernel, in one process.

Runs ``denoise-bench run`` in this process (``--executor inline``) with the harness's Numba cache
pointed at an empty temporary folder (``XDG_CACHE_HOME``; the real cache is not touched), records
every ``numba:compile`` event, and prints per kernel its exclusive compile CPU seconds
(process CPU time, nested compiles of callees subtracted) and its specializations (signatures),
then the seconds per compile unit::

    python benchmarks/compile_profile.py -- --filters eaw --scenes synthetic-moving --timing-at none

Everything after ``--`` goes to ``denoise-bench run`` (``--executor inline --no-cache --out TMP``
are added). ``--json FILE`` writes the figures as JSON; ``--cache-home DIR`` uses that cache home
instead of an empty one (e.g. a second, cached run).
"""

from __future__ import annotations

import json
import os
import tempfile
import time
from collections import defaultdict
from pathlib import Path

from common import machine_line, parser, run


def main(argv=None) -> int:
    ap = parser(__doc__)
    ap.add_argument("--json", type=Path)
    ap.add_argument("--cache-home", type=Path, help="cache home to use (default: a new empty folder)")
    ap.add_argument("run_args", nargs="*")
    args = ap.parse_args(argv)
    home = args.cache_home or Path(tempfile.mkdtemp(prefix="compile-profile-"))
    os.environ["XDG_CACHE_HOME"] = str(home)
    os.environ.pop("NUMBA_CACHE_DIR", None)

    from numba.core import event

    from harness.cli import main as cli_main
    from harness.numba_cache import compile_unit

    stack: list[list] = []
    own = defaultdict(float)  # (unit, qualname) -> exclusive seconds
    sigs: dict = {}

    class Recorder(event.Listener):
        def on_start(self, ev):
            stack.append([time.process_time(), 0.0])

        def on_end(self, ev):
            start, nested = stack.pop()
            spent = time.process_time() - start
            if stack:
                stack[-1][1] += spent
            disp = ev.data["dispatcher"]
            unit = compile_unit(disp.py_func.__code__.co_filename)
            key = (unit[0] if unit else "other", f"{disp.py_func.__module__}.{disp.py_func.__qualname__}")
            own[key] += spent - nested
            sigs[key] = disp

    out = Path(tempfile.mkdtemp(prefix="compile-profile-out-"))
    cpu0 = time.process_time()
    with event.install_listener("numba:compile", Recorder()):
        rc = cli_main(["run", *args.run_args, "--executor", "inline", "--no-cache", "--out", str(out)])
    cpu = time.process_time() - cpu0
    per_unit = defaultdict(float)
    rows = []
    for (unit, name), seconds in sorted(own.items(), key=lambda kv: -kv[1]):
        per_unit[unit] += seconds
        signatures = [str(s) for s in sigs[(unit, name)].signatures]
        rows.append({"unit": unit, "kernel": name, "seconds": round(seconds, 3), "signatures": signatures})
    print(f"\n{machine_line()}")
    print(f"run rc {rc}: {cpu:.1f} CPU-s in this process; compile "
          f"{sum(own.values()):.1f} CPU-s in {len(own)} kernels (cache home {home})")
    for unit, seconds in sorted(per_unit.items(), key=lambda kv: -kv[1]):
        print(f"{unit:28s} {seconds:7.1f} s")
    for row in rows[:40]:
        print(f"{row['seconds']:7.2f} s {len(row['signatures'])} sig  {row['kernel']}")
    for row in rows:
        if len(row["signatures"]) > 1:
            print(f"several specializations: {row['kernel']}: {row['signatures']}")
    if args.json:
        args.json.write_text(json.dumps({"cpu_s": cpu, "units": per_unit, "kernels": rows}, indent=1))
    return rc


if __name__ == "__main__":
    run(main)
