"""Plugin names checked before any plugin is imported, from an index of what each entry point registers.

Loading the plugins imports all of them (PyTorch, Numba, VTK: 5 to 45 seconds), so a misspelt
``--filters`` name would be refused only after that. Entry-point names are known without
importing anything, but not the names their specs register (``error_metrics`` registers
``rmse``, ``psnr``, ...). So every full load records, per entry point, the spec names it
registered, in an index file (:func:`index_path`) keyed by a fingerprint of the installed
plugins: the entry points, every installed distribution and version (a plugin may register only
where a package is installed), and the size and modification time of every source file of the
plugin packages and of ``harness``. While the fingerprint matches, a name that no entry point
and no indexed spec has is refused at once, with the message a full load would give; any other
name goes on to the full load, which checks it again. Without an index (the first run after an
install or an edit) names are checked after the full load, as before.
"""

from __future__ import annotations

import hashlib
import importlib.metadata as importlib_metadata
import importlib.util
import json
import os
import sys
from pathlib import Path

from harness.plugins import ENTRY_POINT_GROUP, disabled_names

#: environment variable naming the index file (default: under ``$XDG_CACHE_HOME`` or ``~/.cache``)
INDEX_ENV = "DENOISE_HARNESS_NAME_INDEX"
#: option attribute -> the kind of plugin it names (each a name, a list of names, or None)
OPTION_KINDS = {"filters": "filter", "filter": "filter", "peers": "filter", "metrics": "metric",
                "plot_metrics": "metric", "scenes": "scene", "scene": "scene", "renderer": "renderer"}
KINDS = ("filter", "renderer", "metric", "scene")
#: the suffix of a sequence metric's per-frame column (a ``--rank-by`` may name one)
PER_FRAME_SUFFIX = "_per_frame"


def index_path() -> Path:
    """Where the index is kept: ``$DENOISE_HARNESS_NAME_INDEX``, else the user's cache folder (one file
    per Python environment)."""
    given = os.environ.get(INDEX_ENV)
    if given:
        return Path(given)
    base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    environment = hashlib.sha256(sys.prefix.encode()).hexdigest()[:12]
    return base / "denoise-harness" / f"plugin-names-{environment}.json"


def fingerprint() -> str | None:
    """A digest of everything that decides which names the plugins register (None: cannot tell)."""
    h = hashlib.sha256()
    try:
        eps = sorted(importlib_metadata.entry_points(group=ENTRY_POINT_GROUP), key=lambda e: (e.name, e.value))
        h.update(json.dumps([[e.name, e.value] for e in eps] + _distributions()).encode())
        tops = sorted({e.value.split(":")[0].split(".")[0] for e in eps} | {"harness"})
        for top in tops:
            spec = importlib.util.find_spec(top)
            if spec is None:
                return None
            for place in spec.submodule_search_locations or [spec.origin]:
                _stat_sources(h, Path(place))
    except (OSError, ValueError, ImportError, TypeError, KeyError):
        return None
    return h.hexdigest()


def _distributions() -> list[str]:
    """Every installed distribution's metadata folder (``name-version.dist-info``) on the import path."""
    found = []
    for entry in sys.path:
        try:
            names = os.listdir(entry or ".")
        except OSError:
            continue
        found += [f"{entry}/{n}" for n in names if n.endswith((".dist-info", ".egg-info"))]
    return sorted(found)


def _stat_sources(h, place: Path) -> None:
    files = sorted(place.rglob("*.py")) if place.is_dir() else [place]
    for path in files:
        stat = path.stat()
        h.update(f"{path}:{stat.st_size}:{stat.st_mtime_ns};".encode())


def write_index(registry, digest: str | None) -> None:
    """Record what each entry point registered in this full load (nothing where it cannot be written)."""
    if digest is None:
        return
    eps = importlib_metadata.entry_points(group=ENTRY_POINT_GROUP)
    by_value = {}
    for ep in eps:
        by_value.setdefault(ep.value, ep.name)
    entries: dict = {ep.name: {} for ep in eps}  # an entry point that registered nothing: known, empty
    for record in registry.records:
        if record.kind == "module":  # broken: registers nothing; disabled: its names are unknown from this load
            if record.status == "disabled":
                entries[record.name] = None
            continue
        ep_name = by_value.get(record.entry_point)
        if ep_name is not None and entries.get(ep_name) is not None:
            entries[ep_name].setdefault(record.kind, []).append(record.name)
    old = _read(digest)
    for ep_name, names in (old or {}).items():
        if entries.get(ep_name) is None and names is not None:
            entries[ep_name] = names
    if old == entries:
        return
    try:
        from harness.cache import atomic_write_bytes

        atomic_write_bytes(index_path(), json.dumps({"fingerprint": digest, "entry_points": entries}).encode())
    except OSError:
        return


def _read(digest: str | None) -> dict | None:
    if digest is None:
        return None
    try:
        data = json.loads(index_path().read_text())
    except (OSError, ValueError):
        return None
    if not isinstance(data, dict) or data.get("fingerprint") != digest:
        return None
    if not isinstance(data.get("entry_points"), dict):
        return None
    return data["entry_points"]


def known_names(digest: str | None) -> dict | None:
    """Kind -> every spec name the index knows, plus ``"entry_point"``; None without a usable index.

    None too when an entry point that is not disabled now has no known names (it was disabled in
    the load that wrote the index).
    """
    entries = _read(digest)
    if entries is None:
        return None
    off = disabled_names()
    known = {kind: set() for kind in (*KINDS, "entry_point")}
    for ep_name, names in entries.items():
        known["entry_point"].add(ep_name)
        if names is None:
            if ep_name not in off:
                return None
            continue
        for kind, values in names.items():
            known.setdefault(kind, set()).update(values)
    eps = {e.name for e in importlib_metadata.entry_points(group=ENTRY_POINT_GROUP)}
    if eps - known["entry_point"]:
        return None
    return known


def refusal(args, known: dict) -> str | None:
    """The one-line message for the first name in ``args`` that no plugin has, or None."""
    everything = set().union(*known.values())
    unknown = [n for n in getattr(args, "disable", []) or [] if n not in everything]
    if unknown:
        return f"--disable: unknown plugin name(s) {unknown}; plugins: {sorted(everything)}"
    for attribute, kind in OPTION_KINDS.items():
        value = getattr(args, attribute, None)
        for name in [value] if isinstance(value, str) else list(value or []):
            if name not in known[kind] and name not in known["entry_point"]:
                return f"no {kind} named {name!r}; registered: {sorted(known[kind])}"
    rank_by = getattr(args, "rank_by", None)
    if rank_by and rank_by not in known["metric"] and rank_by.removesuffix(PER_FRAME_SUFFIX) not in known["metric"]:
        return f"--rank-by {rank_by!r}: no metric of that name; metrics: {sorted(known['metric'])}"
    return None


def unknown_disabled(registry, names) -> list[str]:
    """The ``--disable`` names that name no plugin (entry point or spec) of the loaded registry."""
    known = {r.name for r in registry.records}
    known |= {e.name for e in importlib_metadata.entry_points(group=ENTRY_POINT_GROUP)}
    return [n for n in names if n not in known]


__all__ = ["INDEX_ENV", "fingerprint", "index_path", "known_names", "refusal", "unknown_disabled", "write_index"]
