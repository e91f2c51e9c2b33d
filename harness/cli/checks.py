"""Checks of ``denoise-bench`` options that need more than the parser: each a one-line ``ValueError``."""

from __future__ import annotations

import os
import socket
from pathlib import Path

import pandas as pd

from harness.rows import metric_columns, per_frame_column


def check_rank_by(df: pd.DataFrame, rank_by: str | None) -> None:
    """A ``--rank-by`` that the stored table does not score is a one-line error before any output."""
    scored = metric_columns(df)
    if rank_by is not None and rank_by not in scored:
        raise ValueError(f"--rank-by {rank_by!r}: the run scores {sorted(scored)}")


def markdown_file(path: Path, run_dir: Path | None = None) -> Path:
    """A ``--markdown`` file that writes nothing but itself: not a folder, not a file of the run in ``run_dir``.

    Inside the run folder only a ``.md`` file is accepted (the run's own files, ``results.parquet``
    or ``manifest.json``, are never overwritten).
    """
    if not str(path).strip() or path.is_dir():
        raise ValueError(f"--markdown {str(path)!r} is a folder; name a file")
    if run_dir is not None:
        run, where = Path(run_dir).resolve(), path.resolve()
        if run in where.parents and path.suffix.lower() != ".md":
            raise ValueError(f"--markdown {path} is inside the run folder {run_dir} and not a .md file: the run's "
                             "own files are never overwritten")
    return path


def check_run_options(registry, args) -> None:
    """Options of ``run`` that name metrics: each must be a metric the run scores, before any work."""
    metrics = args.metrics or sorted(registry.metrics)
    specs = [registry.get("metric", m) for m in metrics]
    columns = [*metrics, *(per_frame_column(s.name) for s in specs if s.per_frame)]
    for option, names in (("--rank-by", [args.rank_by] if args.rank_by else []),
                          ("--plot-metrics", args.plot_metrics or [])):
        unknown = [n for n in names if n not in columns]
        if unknown:
            raise ValueError(f"{option} {', '.join(map(repr, unknown))}: not a metric this run scores; it scores "
                             f"{columns}")


#: seconds to wait for a dask scheduler named by address to accept a connection
SCHEDULER_PROBE_S = 10.0


def check_scheduler(address: str, timeout: float = SCHEDULER_PROBE_S) -> None:
    """A one-line ``ValueError`` when nothing accepts connections at a scheduler's ``tcp://host:port``.

    Other protocols (``inproc://``, ``ucx://``, ...) are left to Dask.
    """
    scheme, _, rest = address.rpartition("://")
    if scheme not in ("", "tcp", "tls"):
        return
    host, _, port = rest.rpartition(":")
    host = host.strip("[]")
    if not host or not port.isdigit():
        raise ValueError(f"--scheduler {address!r}: expected an address like tcp://HOST:PORT")
    try:
        with socket.create_connection((host, int(port)), timeout=timeout):
            return
    except socket.gaierror as exc:
        why = f"unknown host {host!r} ({exc.strerror or exc})"
    except TimeoutError:
        why = f"no answer within {timeout:g} s"
    except OSError as exc:
        why = exc.strerror or str(exc)
    raise ValueError(f"--scheduler {address}: cannot reach the dask scheduler: {why}")


def check_scheduler_option(args) -> None:
    """With ``--executor dask`` and a scheduler address (``--scheduler`` or ``$DASK_SCHEDULER_ADDRESS``),
    the scheduler must accept connections (before the plugins are loaded)."""
    if getattr(args, "executor", None) != "dask":
        return
    address = getattr(args, "scheduler", None) or os.environ.get("DASK_SCHEDULER_ADDRESS")
    if address:
        check_scheduler(address)
