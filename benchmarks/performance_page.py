"""Regenerate the measured part of docs/performance.md: run the page's bench command, splice its tables.

The page keeps its prose; everything between the markers ``<!-- bench:start -->`` and
``<!-- bench:end -->`` is the markdown ``denoise-bench bench --markdown`` writes (the command,
the machine, the load, the library versions and the tables), replaced by a re-run::

    python benchmarks/performance_page.py                 # the page's command (COMMAND below)
    python benchmarks/performance_page.py --print         # print the command, run nothing
    python benchmarks/performance_page.py -- eaw --resolution 640x360 --repeats 2   # another bench

Run it on an otherwise idle machine; the load average at the start and end is part of the output.
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
from pathlib import Path

from common import ROOT, parser, run

#: the bench of the page (arguments after ``denoise-bench bench``)
COMMAND = ["eaw,svgf,sbf,lbf", "--peers", "opencv_jbf,oidn", "--scene", "synthetic-moving",
           "--resolution", "1280x720,1920x1080", "--threads", "1,2", "--repeats", "5"]
START, END = "<!-- bench:start -->", "<!-- bench:end -->"
PAGE = ROOT / "docs" / "performance.md"


def splice(page: str, block: str) -> str:
    """``page`` with the text between the markers replaced by ``block``."""
    if START not in page or END not in page or page.index(START) > page.index(END):
        raise ValueError(f"the page needs the markers {START} and {END}, in that order")
    head, rest = page.split(START, 1)
    tail = rest.split(END, 1)[1]
    return f"{head}{START}\n{block.rstrip()}\n{END}{tail}"


def main(argv=None) -> int:
    ap = parser(__doc__)
    ap.add_argument("--page", type=Path, default=PAGE, help="the page to update (default docs/performance.md)")
    ap.add_argument("--print", dest="dry", action="store_true", help="print the command and stop")
    ap.add_argument("bench", nargs="*", help="after --: the bench arguments (default: the page's command)")
    args = ap.parse_args(argv)
    bench = args.bench or COMMAND
    if args.dry:
        print("denoise-bench bench " + " ".join(bench))
        return 0
    with tempfile.TemporaryDirectory() as folder:
        out = Path(folder) / "bench.md"
        done = subprocess.run([sys.executable, "-m", "harness.cli", "bench", *bench, "--markdown", str(out)])
        if done.returncode != 0 or not out.is_file():
            print(f"the bench failed (exit {done.returncode}); the page is unchanged", file=sys.stderr)
            return done.returncode or 1
        args.page.write_text(splice(args.page.read_text(), out.read_text()))
    print(f"{args.page} updated")
    return 0


if __name__ == "__main__":
    run(main)
