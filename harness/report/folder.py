"""The report's output folder: written only where the report owns it.

A report folder is created fresh, or is an empty folder, or is one an earlier report wrote: it
holds the marker file :data:`MARKER`, which lists every file that report wrote. Rewriting a report
removes only the files its marker lists (and folders they leave empty); any other file in the
folder stays. A non-empty folder without the marker is refused, as are the current directory, the
run folder itself, a folder that contains the run folder, and the run's own stored parts
(``jobs/``, ``report-frames/``, ...): a report never deletes or overwrites a run's inputs.
"""

from __future__ import annotations

import json
from pathlib import Path

#: the file in a report folder listing the files the report wrote (relative paths)
MARKER = ".denoise-bench-report.json"


def check_report_folder(out: str | Path, run_dir: str | Path) -> Path:
    """The report folder ``out`` for the run in ``run_dir``, checked before anything is written.

    Raises
    ------
    ValueError
        One line naming the folder and why it cannot hold the report.
    """
    if not str(out).strip():
        raise ValueError("--out must name a folder, got ''")
    out, run_dir = Path(out), Path(run_dir)
    where, run = out.resolve(), run_dir.resolve()
    if where == Path.cwd().resolve():
        raise ValueError(f"--out {out} is the current directory; name a folder for the report")
    if where == run or where in run.parents:
        raise ValueError(f"--out {out} is or contains the run folder {run_dir}; name a folder for the report")
    if out.exists() and not out.is_dir():
        raise ValueError(f"--out {out} is a file, not a folder")
    if run in where.parents and where.relative_to(run).parts[0] != "report":
        raise ValueError(f"--out {out} is inside the run folder {run_dir} but not its report/ folder: the run's "
                         "own files are never replaced; name another folder")
    if out.is_dir() and any(out.iterdir()) and not (out / MARKER).is_file() and not _legacy(out):
        raise ValueError(f"--out {out} holds files and is no report folder (no {MARKER}); choose a new or an "
                         "empty folder")
    return out


def prepare(out: Path) -> set:
    """Remove the files the folder's previous report wrote; returns the files left (not the report's).

    The marker then lists those other files until :func:`finish` lists the report's, so a report
    that stops half-way is still recognised and replaced by the next one.
    """
    for path in _listed(out):
        path.unlink(missing_ok=True)
        for parent in path.parents:
            if parent == out or not parent.is_dir() or any(parent.iterdir()):
                break
            parent.rmdir()
    out.mkdir(parents=True, exist_ok=True)
    foreign = _files(out) - {out / MARKER}
    (out / MARKER).write_text(json.dumps({"kept": sorted(str(p.relative_to(out)) for p in foreign)}, indent=1))
    return foreign


def finish(out: Path, foreign: set) -> None:
    """Write the marker listing every file in ``out`` but ``foreign`` (what :func:`prepare` left)."""
    written = sorted(str(p.relative_to(out)) for p in _files(out) - foreign - {out / MARKER})
    (out / MARKER).write_text(json.dumps({"files": written}, indent=1))


def _files(out: Path) -> set:
    return {p for p in out.rglob("*") if p.is_file() or p.is_symlink()}


def _legacy(out: Path) -> bool:
    """A report written before the marker existed: ``index.html`` (a denoise-bench report) and ``img/*.png`` only."""
    files = _files(out)
    index = out / "index.html"
    pictures = {p for p in files if p.parent == out / "img" and p.suffix == ".png" and not p.is_symlink()}
    if files - pictures != {index} or index.is_symlink():
        return False
    try:
        return "<title>denoise-bench report</title>" in index.read_text(errors="replace")[:4096]
    except OSError:
        return False


def _listed(out: Path) -> list[Path]:
    """The marker's files, each inside ``out`` (an entry leading elsewhere is ignored); a legacy report's files."""
    if not (out / MARKER).is_file():
        return sorted(_files(out)) if out.is_dir() and _legacy(out) else []
    try:
        data = json.loads((out / MARKER).read_text())
    except (OSError, ValueError):
        return []
    if not isinstance(data, dict):
        return []
    if "files" in data:
        names = data["files"] if isinstance(data["files"], list) else []
    else:  # a report that stopped before finishing: everything but the files that were there before it
        kept = set(map(str, data.get("kept", []))) if isinstance(data.get("kept"), list) else None
        if kept is None:
            return []
        names = [str(p.relative_to(out)) for p in _files(out) if p != out / MARKER and
                 str(p.relative_to(out)) not in kept]
    root = out.resolve()
    listed = []
    for name in names:
        path = out / str(name)
        parent = path.parent.resolve()
        if (parent == root or root in parent.parents) and (path.is_file() or path.is_symlink()):
            listed.append(path)
    return listed


__all__ = ["MARKER", "check_report_folder", "finish", "prepare"]
