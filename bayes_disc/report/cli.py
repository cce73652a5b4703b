"""``bayes-disc report RUN_DIR [--reports-dir DIR]``: register into the main parser with :func:`register`."""
from __future__ import annotations

import sys

from .errors import ReportInputError


def _report(args) -> int:
    from .run import build_report
    if args.processes < 1:
        print(f"bayes-disc report: --processes must be ≥ 1, got {args.processes}", file=sys.stderr)
        return 2
    try:
        build_report(args.run_dir, reports_dir=args.reports_dir, seed=args.seed,
                     processes=args.processes)   # logs the path written
    except ReportInputError as e:
        print(f"bayes-disc report: {e}", file=sys.stderr)
        return 2
    return 0


def register(subparsers, parents=()) -> None:
    """Add the ``report`` subcommand to an argparse subparsers object.

    Parameters
    ----------
    subparsers : argparse._SubParsersAction
        From ``ArgumentParser.add_subparsers``.
    parents : sequence of argparse.ArgumentParser
        Parsers whose options the subcommand shares (the main CLI's verbosity options).
    """
    p = subparsers.add_parser("report", parents=list(parents), help="HTML report and figures of a `sample` run folder",
                              description="Write RUN_DIR/reports/<name>.html (self-contained) and the figures as "
                                          "PNG and PDF in RUN_DIR/figures.")
    p.add_argument("run_dir", help="output folder of `bayes-disc sample` (holds summary.json, posterior.nc)")
    p.add_argument("--reports-dir", default=None, help="folder for <name>.html (default: RUN_DIR/reports)")
    p.add_argument("--seed", type=int, default=0, help="seed for the posterior draws of bands (default 0)")
    p.add_argument("--processes", type=int, default=2,
                   help="worker processes drawing the figures (default 2; 1: none started)")
    p.set_defaults(func=_report)
