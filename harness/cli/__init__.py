"""The ``denoise-bench`` command: argument parsing (:mod:`.parser`) and printing (:mod:`.commands`,
:mod:`.stress`).

Sub-commands: ``run`` (the benchmark), ``stress`` (the numerical stress battery and fuzzing),
``plugins`` (what is registered), ``show`` (summary and leaderboard of a stored run),
``render`` (references into the cache), ``bench`` (per-frame timing of filters against peers)
and ``train`` (learned filters). Nothing in the library imports this package.
"""

from __future__ import annotations

import sys
import warnings

from harness.lock import FolderLocked
from harness.plugins import PluginConflictError, load_plugins

#: exceptions that mean the user asked for something that cannot be (exit status 2, one line)
USER_ERRORS = (KeyError, ValueError, FileNotFoundError, NotADirectoryError, FolderLocked)


def _warning_line(message, category, filename, lineno, file=None, line=None) -> None:
    print(f"denoise-bench: warning: {message}", file=sys.stderr)


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``denoise-bench``; returns the exit status."""
    from harness.cli import names
    from harness.cli.checks import check_scheduler_option
    from harness.cli.parser import build_parser

    args = build_parser().parse_args(argv)
    warnings.showwarning = _warning_line
    digest = names.fingerprint()
    known = names.known_names(digest)
    message = names.refusal(args, known) if known is not None else None
    if message:  # answered from the plugin name index, before any plugin is imported
        print(f"denoise-bench {args.command}: {message}", file=sys.stderr)
        return 2
    try:
        check_scheduler_option(args)
    except ValueError as exc:
        print(f"denoise-bench {args.command}: {exc}", file=sys.stderr)
        return 2
    from harness.cli import commands

    try:
        registry = load_plugins(disable=args.disable)
    except PluginConflictError as exc:
        print(f"denoise-bench: {exc}", file=sys.stderr)
        return 2
    names.write_index(registry, digest)
    unknown = names.unknown_disabled(registry, args.disable)
    if unknown:
        print(f"denoise-bench {args.command}: --disable: unknown plugin name(s) {unknown}", file=sys.stderr)
        return 2
    for record in registry.broken:
        if record.kind == "module" and record.error.startswith("unknown hook"):
            print(f"denoise-bench: warning: plugin {record.name!r} ({record.distribution}): {record.error}",
                  file=sys.stderr)
    handler = getattr(commands, f"cmd_{args.command}")
    try:
        return handler(registry, args)
    except USER_ERRORS as exc:
        message = exc.args[0] if isinstance(exc, KeyError) and exc.args else exc
        print(f"denoise-bench {args.command}: {message}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        resume = " (rerun with --resume)" if hasattr(args, "resume") else ""
        print(f"\ndenoise-bench {args.command}: interrupted; stored results are kept{resume}", file=sys.stderr)
        return 130
