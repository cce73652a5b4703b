"""Command line: ``bayes-disc COMMAND ...`` (docs/outputs.md). Bad input: one-line reason on stderr, exit 2.

Progress messages go to stderr, results (tables, the diagnosis in words) to stdout; ``-v`` shows more,
``-q`` less (:mod:`._logging`). The commands run the jobs of :mod:`.jobs` (job, then report), as the API
does. Every job writes into its run folder; a folder that already holds that job's results is refused
unless ``--overwrite`` (or, for ``sample``, ``--resume``) is given.
"""
from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

from ._logging import cli_logging
from ._version import DOCUMENTATION_URL, __version__
from .jobs.progress import RESULT
from .observation.cases import CaseFileError, load_case, simulate_case
from .observation.config_io import ConfigError
from .observation.imu.formats import ImuFileError
from .observation.markers import MarkerFileError, write_marker_csv

logger = logging.getLogger(__name__)

#: exceptions that mean "bad input" rather than a bug: reported in one line, exit status 2
INPUT_ERRORS: tuple[type[Exception], ...] = (ConfigError, MarkerFileError, CaseFileError, ImuFileError,
                                              FileNotFoundError)


def _cmd_simulate(args) -> int:
    case = load_case(args.case)
    table, _ = simulate_case(case)
    out = Path(args.output)
    write_marker_csv(out, table)
    logger.info(f"wrote {out} ({len(table)} rows, {case.times.size} samples at {case.sample_rate_hz:g} Hz)")
    return 0


def _cmd_synth(args) -> int:
    from .observation.synth_config import load_synth_spec
    from .observation.synth import synthesize, write_synth
    spec, markers_path, truth_path = load_synth_spec(args.config)
    result = synthesize(spec)
    write_synth(result, markers_path, truth_path)
    for name, f in result.truth["flights"].items():
        lo, hi = f["alpha_range_deg"]
        logger.info(f"{name}: α {lo:.1f}…{hi:.1f}°, range {f['range_m']:.1f} m, noise {f['noise_m'] * 1e3:.1f} mm, "
                    f"{f['n_dropped']} points dropped", extra=RESULT)
    logger.info(f"wrote {markers_path} and {truth_path}")
    return 0


def _cmd_demo(args) -> int:
    from .observation.demo import write_demo
    folder = Path(args.folder)
    written = write_demo(folder, overwrite=args.overwrite)
    logger.info(f"wrote {', '.join(p.name for p in written)} into {folder}: four synthetic flights "
                f"(`bayes-disc sample {folder / 'config.yaml'}` samples their posterior)")
    return 0


def _run_config(args, job: str):
    """The run configuration of ``args.config`` with ``--output``, refused when its folder already holds
    ``job``'s results and neither ``--overwrite`` nor ``--resume`` was given."""
    from .inference.model.config import load_config
    from .jobs.outputs import check_fresh_output
    cfg = load_config(args.config, output_override=args.output)
    check_fresh_output(cfg, job, overwrite=args.overwrite, resume=getattr(args, "resume", False))
    return cfg


def _cmd_sample(args) -> int:
    from .jobs.sample import sample
    cfg = _run_config(args, "sample")
    summary = sample(cfg, resume=args.resume, progress=not args.no_progress).result
    return 0 if summary["convergence"]["converged"] or not args.strict else 3


def _cmd_identifiability(args) -> int:
    from .jobs.identifiability import identifiability
    identifiability(_run_config(args, "identifiability"), profiles=args.profiles, design=not args.no_design)
    return 0


def _cmd_diagnose(args) -> int:
    from .jobs.diagnose import diagnose
    diagnose(_run_config(args, "diagnose"), sample=not args.no_sample, processes=args.processes,
             progress=not args.no_progress, learn=not args.no_learn)
    return 0


def _cmd_predict(args) -> int:
    from .jobs.predict import run_predict
    cfg = _run_config(args, "predict")
    result = run_predict(cfg, args.run_dir, output=args.output)
    for name, f in result["flights"].items():
        words = f["reason"] if f["status"] != "ok" else ", ".join(
            f"{c} RMS {v['rms_fixed']:.4g} (fixed) / {v['rms_free']:.4g} (free) {v['unit']}"
            for c, v in f["channels"].items())
        logger.info(f"{name}: {f['status']}: {words}", extra=RESULT)
    return 0


def _cmd_calibrate(args) -> int:
    from .calibration import load_cal_config, run_campaign
    cal = load_cal_config(args.config, output_override=args.output)
    result = run_campaign(cal, scheduler=args.scheduler, workers=args.workers, progress=not args.no_progress,
                          summary_only=args.summary_only)
    if result["replicates"] == 0:
        logger.error(f"no replicate succeeded ({len(result['failed'])} failed; errors in {cal.output}/replicates/)")
        return 3
    for name, c in result["coefficients"].items():
        logger.info(f"{name}: coverage 50 % {c['coverage_50']:.2f}, 90 % {c['coverage_90']:.2f}, "
                    f"rank uniformity p {c['rank_uniformity_p']:.3g}", extra=RESULT)
    return 0


def _cmd_compare(args) -> int:
    import json
    from .api import compare
    from .inference.results.compare import run_label
    try:
        table = compare(args.run_dirs)
    except (ValueError, FileNotFoundError) as e:
        logger.error(f"bayes-disc compare: {e}")
        return 2
    head = f"{'run':<24}{'elpd_loo':>11}{'se':>8}{'elpd_diff':>11}{'dse':>8}{'p_loo':>8}{'weight':>8}{'k high':>7}"
    lines = [head] + [f"{str(label)[:23]:<24}{r.elpd_loo:>11.1f}{r.se:>8.1f}{r.elpd_diff:>11.1f}{r.dse:>8.1f}"
                      f"{r.p_loo:>8.1f}{r.weight:>8.2f}{int(r.pareto_k_high):>7d}" for label, r in table.iterrows()]
    logger.info("\n".join(lines), extra=RESULT)
    best = table.index[0]
    for label, r in list(table.iterrows())[1:]:
        clear = r.elpd_diff > 2 * r.dse
        logger.info(f"{label}: {r.elpd_diff:.1f} ± {r.dse:.1f} below {best} in expected log predictive density "
                    + ("(more than twice its standard error: a clear difference)" if clear else
                       "(within twice its standard error: not distinguished by these data)"), extra=RESULT)
    high = [str(label) for label, r in table.iterrows() if r.pareto_k_high]
    if high:
        logger.warning(f"Pareto k̂ above ArviZ's threshold at some points of {', '.join(high)}: their PSIS-LOO "
                       "values are unreliable (influential points; see docs/outputs.md)")
    if args.output:
        out = Path(args.output)
        out.parent.mkdir(parents=True, exist_ok=True)
        kinds = {"warning": bool, "rank": int, "pareto_k_high": int}
        rows = {str(label): {k: kinds.get(k, float)(v) for k, v in r.items() if k != "scale"}
                for label, r in table.iterrows()}
        record = {"criterion": "loo", "scale": "log",
                  "runs": {run_label(d): str(Path(d)) for d in args.run_dirs}, "comparison": rows}
        out.write_text(json.dumps(record, indent=1) + "\n")
        logger.info(f"wrote {out}")
    return 0


def _verbosity_options(parser, default) -> None:
    """``-v/--verbose`` and ``-q/--quiet`` (repeatable); ``default`` SUPPRESS on subcommands so that a flag
    given before the subcommand is not reset by the subcommand's defaults."""
    parser.add_argument("-v", "--verbose", dest="log_more", action="count", default=default,
                        help="more messages (debug details); repeatable")
    parser.add_argument("-q", "--quiet", dest="log_less", action="count", default=default,
                        help="fewer messages: -q only results and problems, -qq only problems")


def build_parser() -> argparse.ArgumentParser:
    """The ``bayes-disc`` argument parser with every subcommand.

    Returns
    -------
    argparse.ArgumentParser
    """
    parser = argparse.ArgumentParser(prog="bayes-disc",
                                     description="Estimate flying-disc aerodynamic coefficients from tracked "
                                                 f"flights. Documentation: {DOCUMENTATION_URL}")
    parser.add_argument("--version", action="version", version=f"bayes-disc {__version__}")
    _verbosity_options(parser, 0)
    common = argparse.ArgumentParser(add_help=False)
    _verbosity_options(common, argparse.SUPPRESS)
    sub = parser.add_subparsers(dest="command", required=True)
    for add in (_data_commands, _run_commands, _campaign_commands):
        add(sub, common)
    _register_optional(sub, common)
    return parser


def _data_commands(sub, common) -> None:
    """Subcommands that make or write data: ``demo``, ``simulate``, ``synth``."""
    p = sub.add_parser("demo", parents=[common],
                       help="write the demo flights and their run configuration into a folder",
                       description="Writes four synthetic flights (flights.csv, made by synth.yaml with the "
                                   "Hummel & Hubbard 2002 coefficients; truth.json holds the truth) and their run "
                                   "configuration config.yaml into FOLDER, so that `bayes-disc sample "
                                   "FOLDER/config.yaml` runs anywhere, from an installed package.")
    p.add_argument("folder", metavar="FOLDER", help="folder to write into (created if missing)")
    p.add_argument("--overwrite", action="store_true", help="replace demo files already in FOLDER")
    p.set_defaults(func=_cmd_demo)
    p = sub.add_parser("simulate", parents=[common],
                       help="simulate a case (reference JSON format) to a marker CSV")
    p.add_argument("case", help="CASE.json: disc constants, coefficients, marker body positions, initial state, "
                                "sample rate, duration (format: docs/data-formats.md)")
    p.add_argument("-o", "--output", required=True, help="marker CSV to write (format: docs/data-formats.md)")
    p.set_defaults(func=_cmd_simulate)
    p = sub.add_parser("synth", parents=[common],
                       help="make synthetic flights from a SYNTH.yaml description")
    p.add_argument("config", help="SYNTH.yaml")
    p.set_defaults(func=_cmd_synth)


def _run_commands(sub, common) -> None:
    """Subcommands that run a job on a run configuration: ``sample``, ``identifiability``, ``diagnose``,
    ``predict``."""
    p = sub.add_parser("sample", parents=[common],
                       help="least squares + emcee posterior over coefficients and initial conditions",
                       description="The main job: joint least squares, then emcee ensembles, over the ten "
                                   "coefficients and every flight's initial conditions. Writes summary.json, "
                                   "posterior.nc, least_squares.json, profiles.json, run_info.json and chains/ in the "
                                   "output folder, and the HTML report reports/<name>.html inside it "
                                   "(docs/outputs.md).")
    p.add_argument("config", help="run configuration YAML (keys: docs/configuration.md)")
    p.add_argument("--resume", action="store_true",
                   help="continue an interrupted run from its chain files (same configuration; the saved least "
                        "squares and proposals are reused)")
    p.add_argument("--output", metavar="DIR", help="override the config's output folder")
    _overwrite_option(p, "sample")
    p.add_argument("--no-progress", action="store_true",
                   help="no progress bars (stages and convergence checks are logged instead; bars are shown "
                        "only on a terminal)")
    p.add_argument("--strict", action="store_true", help="exit 3 if the cap is reached before convergence")
    p.set_defaults(func=_cmd_sample)
    p = sub.add_parser("identifiability", parents=[common],
                       help="which coefficients the flights determine, and the next throw",
                       description="Least squares and Fisher information (no MCMC): a verdict per coefficient "
                                   "(identified, weak, unidentified) with its reason, the flight envelope, and the "
                                   "most informative next throw. Writes identifiability.json in the output folder "
                                   "(docs/outputs.md).")
    p.add_argument("config", help="run configuration YAML (keys: docs/configuration.md)")
    p.add_argument("--profiles", action="store_true", help="also profile the likelihood of every coefficient")
    p.add_argument("--no-design", action="store_true", help="skip the ranking of candidate throws")
    p.add_argument("--output", metavar="DIR", help="override the config's output folder")
    _overwrite_option(p, "identifiability")
    p.set_defaults(func=_cmd_identifiability)
    p = sub.add_parser("diagnose", parents=[common],
                       help="locate a model–data mismatch, name the missing physics, refit",
                       description="Is the model missing physics? Ranks candidate terms by ΔBIC, accepts one only "
                                   "when the residuals turn white, and resamples with it. Writes diagnosis.json, "
                                   "diagnosis_residuals.npz and diagnosis_refit/ in the output folder "
                                   "(docs/outputs.md).")
    p.add_argument("config", help="run configuration YAML (keys: docs/configuration.md)")
    p.add_argument("--no-sample", action="store_true",
                   help="least-squares estimates only (no emcee resampling with the accepted terms)")
    p.add_argument("--no-learn", action="store_true",
                   help="skip the learned correction in height, α and spin when no term explains the data "
                   "(it costs several refits with up to 46 extra parameters)")
    p.add_argument("--processes", type=_positive_int, default=2, help="parallel candidate fits (default 2)")
    p.add_argument("--output", metavar="DIR", help="override the config's output folder (the rebuilt report goes "
                                                   "to DIR/reports/<name>.html when DIR holds a sampled run)")
    _overwrite_option(p, "diagnose")
    p.add_argument("--no-progress", action="store_true", help="no progress bar while resampling")
    p.set_defaults(func=_cmd_diagnose)
    p = sub.add_parser("predict", parents=[common],
                       help="held-out validation: fit flights with a run's coefficients fixed, and free",
                       description="Every flight of CONFIG is fitted with the coefficients and shared sensor "
                                   "parameters fixed at the posterior medians of RUN_DIR (only its own initial "
                                   "conditions and nuisance parameters free), and again with everything free. Writes "
                                   "prediction.json: RMS per channel, fixed and free (docs/outputs.md).")
    p.add_argument("config", help="run configuration YAML of the held-out flights (keys: docs/configuration.md)")
    p.add_argument("--from", dest="run_dir", required=True, help="output folder of a `bayes-disc sample` run")
    p.add_argument("--output", metavar="DIR", help="override the config's output folder")
    _overwrite_option(p, "predict")
    p.set_defaults(func=_cmd_predict)


def _campaign_commands(sub, common) -> None:
    """Subcommands over many runs: ``calibrate`` (a Dask campaign) and ``compare`` (PSIS-LOO of runs)."""
    p = sub.add_parser("calibrate", parents=[common],
                       help="simulation-based calibration over many synthetic data sets, on Dask",
                       description="Draws N truths, synthesises flights from a template, fits each (least squares "
                                   "and the sampler) as a Dask task and ranks the truth among the posterior draws. "
                                   "Writes replicates/*.json (one per finished replicate: an interrupted campaign "
                                   "resumes), calibration.json and calibration.html in the output folder "
                                   "(docs/calibration.md).")
    p.add_argument("config", help="CAL.yaml (keys: docs/calibration.md)")
    p.add_argument("--scheduler", metavar="ADDRESS",
                   help="address of a running Dask scheduler (tcp://host:8786); default: a local cluster")
    p.add_argument("--workers", type=_positive_int, default=2,
                   help="worker processes of the local cluster (default 2; ignored with --scheduler)")
    p.add_argument("--output", metavar="DIR", help="override the campaign's output folder")
    p.add_argument("--no-progress", action="store_true", help="no progress bar (finished replicates are logged)")
    p.add_argument("--summary-only", action="store_true",
                   help="run no replicate: write calibration.json and the page from those already finished")
    p.set_defaults(func=_cmd_calibrate)
    p = sub.add_parser("compare", parents=[common],
                       help="PSIS-LOO comparison of sampled runs of the same flights (az.compare)",
                       description="Compares two or more `bayes-disc sample` runs of the same observed marker "
                                   "points (e.g. the same flights with different noise models or physics terms) by "
                                   "their expected log predictive density (PSIS-LOO, az.compare): the best first, "
                                   "each other's difference with its standard error, stacking weights, and points "
                                   "with unreliable LOO values (Pareto k above min(1 - 1/log10 S, 0.7), S draws). "
                                   "Optionally writes the table as JSON (docs/outputs.md).")
    p.add_argument("run_dirs", nargs="+", metavar="RUN_DIR", help="output folders of `bayes-disc sample` (two or more)")
    p.add_argument("--output", metavar="FILE", help="write the comparison as JSON to FILE")
    p.set_defaults(func=_cmd_compare)


def _overwrite_option(parser, job: str) -> None:
    """``--overwrite``: replace the results of an earlier ``job`` in the output folder (refused otherwise)."""
    parser.add_argument("--overwrite", action="store_true",
                        help=f"replace the results of an earlier `{job}` in the output folder (without it, such a "
                             "folder is refused" + (", and --resume continues the run there)" if job == "sample"
                                                    else ")"))


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be ≥ 1, got {value}")
    return value


def _register_optional(sub, common) -> None:
    """Subcommands that live in their own packages (report, video front end; ``track`` and ``render`` have
    their own ``-q``, so the common verbosity options are given only before the subcommand)."""
    from .report.cli import register as register_report
    from .video.cli import register as register_video
    register_report(sub, parents=[common])
    register_video(sub)


def _input_errors() -> tuple[type[Exception], ...]:
    from .report.errors import ReportInputError
    from .video.errors import VideoInputError
    return INPUT_ERRORS + (ReportInputError, VideoInputError)


def verbosity(args) -> int:
    """Number of ``-v`` minus number of ``-q`` given anywhere on the command line.

    Parameters
    ----------
    args : argparse.Namespace
        Parsed arguments.

    Returns
    -------
    int
    """
    return int(getattr(args, "log_more", 0) or 0) - int(getattr(args, "log_less", 0) or 0)


def main(argv=None) -> int:
    """Run ``bayes-disc`` with ``argv`` (default: ``sys.argv[1:]``).

    Parameters
    ----------
    argv : list of str, optional
        Command-line arguments without the program name.

    Returns
    -------
    int
        Exit status: 0 success, 2 bad input (one line on stderr), 3 ``sample --strict`` without
        convergence or a ``calibrate`` campaign without a successful replicate, 130 interrupted.
    """
    args = build_parser().parse_args(argv)
    try:
        with cli_logging(verbosity(args)):
            return int(args.func(args) or 0)
    except _input_errors() as e:
        print(f"bayes-disc {args.command}: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"bayes-disc {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
