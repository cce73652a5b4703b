"""A calibration campaign on Dask: replicates as tasks, records streamed to disk, then the summary.

Layout of the output folder:

* ``campaign.json`` — what the finished replicates depend on (:meth:`.config.CalConfig.key`); a campaign
  resumed in the same folder must have the same (only N and the output may change);
* ``replicates/replicate_<i>.json`` — one record per finished replicate (:func:`.replicate.run_replicate`),
  written by the client as each task finishes (atomically: a temporary file, then a rename);
* ``calibration.json`` — docs/outputs.md (``replicates``, per coefficient ``coverage_50``, ``coverage_90``,
  ``rank_uniformity_p``) plus rank counts, the binomial bands and the failed / unconverged replicates;
* ``calibration.html`` — the report page (:func:`bayes_disc.report.calibration.build_calibration_page`).

Resuming: replicates whose record exists are not run again; a record of a failed replicate counts as
finished (delete its file to retry it). Dask: a ``LocalCluster`` of ``workers`` single-threaded worker
processes by default, or the running scheduler at ``scheduler``; records travel back to the client, so
the workers need no shared file system, only the same bayes-disc installed. Each worker process compiles
the simulator kernels on its first replicate (seconds once the on-disk kernel cache
:mod:`bayes_disc.physics.kernel_cache` holds them); BLAS/OpenMP threads are 1 per worker (Dask's nanny
sets ``OMP_NUM_THREADS``, ``MKL_NUM_THREADS``, ``OPENBLAS_NUM_THREADS`` to 1 before it starts a worker).
"""
from __future__ import annotations

import contextlib
import json
import logging
import os
from collections import Counter
from pathlib import Path

from ..observation.config_io import ConfigError
from .config import CalConfig
from .replicate import replicate_task
from .stats import summarize

logger = logging.getLogger(__name__)
REPLICATES_DIR = "replicates"
CAMPAIGN_FILE = "campaign.json"
#: environment of LocalCluster workers: one BLAS/OpenMP/numba thread each (the workers are the parallelism)
WORKER_ENV = {"OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "NUMBA_NUM_THREADS": "1"}


def replicate_path(output, index: int) -> Path:
    """File of replicate ``index``'s record."""
    return Path(output) / REPLICATES_DIR / f"replicate_{index:05d}.json"


def write_json_atomic(path: Path, data: dict) -> None:
    """Write JSON so that a reader (or an interrupted campaign) never sees a partial file."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    tmp.write_text(json.dumps(data, indent=1))
    os.replace(tmp, path)


def check_campaign(cal: CalConfig) -> None:
    """Record the campaign's key in its folder, or refuse a folder that holds another campaign's replicates.

    Raises
    ------
    ConfigError
        If ``campaign.json`` exists with another key (naming the parts that differ).
    """
    out = Path(cal.output)
    path = out / CAMPAIGN_FILE
    key = json.loads(json.dumps(cal.key()))
    if path.is_file():
        old = json.loads(path.read_text())
        if old != key and old not in [json.loads(json.dumps(k)) for k in cal.earlier_keys()]:
            diff = sorted(k for k in set(old) | set(key) if old.get(k) != key.get(k))
            raise ConfigError(cal.path, "output", f"{out} holds replicates of another campaign (differs in "
                              f"{', '.join(diff)}); use another output folder or remove this one")
        return
    write_json_atomic(path, key)


def pending(cal: CalConfig) -> list[int]:
    """Replicates of 0…N−1 without a record."""
    return [i for i in range(cal.replicates) if not replicate_path(cal.output, i).is_file()]


@contextlib.contextmanager
def dask_client(scheduler: str | None = None, workers: int = 2):
    """A Dask client: of the scheduler at ``scheduler``, else of a new LocalCluster of ``workers`` processes.

    Parameters
    ----------
    scheduler : str, optional
        Address of a running scheduler (``tcp://host:8786``).
    workers : int
        Worker processes of the LocalCluster (one thread each).

    Yields
    ------
    distributed.Client
    """
    from distributed import Client, LocalCluster
    if scheduler:
        with Client(scheduler) as client:
            yield client
        return
    with LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None,
                      env=dict(WORKER_ENV)) as cluster, Client(cluster) as client:
        yield client


def run_replicates(cal: CalConfig, indices: list[int], client, progress: bool = True) -> int:
    """Submit replicates as tasks and write each record as it arrives.

    Parameters
    ----------
    cal : CalConfig
    indices : list of int
        Replicates to run.
    client : distributed.Client
    progress : bool
        Show a tqdm bar of finished replicates.

    Returns
    -------
    int
        Replicates written.
    """
    from distributed import as_completed
    from tqdm import tqdm
    cal_future = client.scatter(cal, broadcast=True)
    futures = [client.submit(replicate_task, cal_future, i, key=f"replicate-{cal.name}-{i}", pure=False)
               for i in indices]
    done = 0
    with tqdm(total=len(indices), desc="replicates", unit="replicate", disable=None if progress else True) as bar:
        for fut in as_completed(futures):
            rec = fut.result()
            write_json_atomic(replicate_path(cal.output, rec["index"]), rec)
            done += 1
            bar.update(1)
            if rec["status"] != "ok":
                logger.warning(f"replicate {rec['index']} failed: {rec['error']}")
            if bar.disable:
                logger.info(f"replicate {rec['index']} finished ({done}/{len(indices)}, {rec['wall_time_s']:.0f} s)")
    return done


def read_records(cal: CalConfig) -> list[dict]:
    """Records of replicates 0…N−1 found on disk, in index order."""
    out = []
    for i in range(cal.replicates):
        p = replicate_path(cal.output, i)
        if p.is_file():
            out.append(json.loads(p.read_text()))
    return out


def calibration_result(cal: CalConfig, records: list[dict]) -> dict:
    """``calibration.json`` of the records (failed replicates are counted, not ranked)."""
    ok = [r for r in records if r["status"] == "ok"]
    res = summarize(ok, cal.names, cal.draws, cal.bins)
    res.update({"name": cal.name, "requested": cal.replicates,
                "failed": [{"index": r["index"], "error": r["error"]} for r in records if r["status"] != "ok"],
                "not_converged": [r["index"] for r in ok if not r["convergence"]["converged"]],
                "noise_chosen": dict(Counter(label for r in ok for label in r.get("noise", {}).values())),
                "truth_draw": cal.truth.draw, "seed": cal.seed,
                "wall_time_s_per_replicate": ([min(r["wall_time_s"] for r in ok),
                                               sum(r["wall_time_s"] for r in ok) / len(ok),
                                               max(r["wall_time_s"] for r in ok)] if ok else None)})
    return res


def run_campaign(cal: CalConfig, *, scheduler: str | None = None, workers: int = 2, progress: bool = True,
                 report: bool = True, summary_only: bool = False) -> dict:
    """``bayes-disc calibrate``: run the missing replicates, then write calibration.json and the page.

    Parameters
    ----------
    cal : CalConfig
        The campaign.
    scheduler : str, optional
        Dask scheduler address; default a LocalCluster.
    workers : int
        LocalCluster worker processes.
    progress : bool
        Progress bar of finished replicates.
    report : bool
        Write ``calibration.html``.
    summary_only : bool
        Run nothing: summarise the replicates already finished (``requested`` still says how many the campaign
        asks for).

    Returns
    -------
    dict
        The calibration.json content.
    """
    out = Path(cal.output)
    out.mkdir(parents=True, exist_ok=True)
    check_campaign(cal)
    todo = pending(cal)
    where = f"on {scheduler}" if scheduler else f"on {workers} local worker{'s' if workers != 1 else ''}"
    logger.info(f"{cal.name}: {cal.replicates - len(todo)} of {cal.replicates} replicates already done, "
                + (f"{len(todo)} not run (summary only)" if summary_only else f"{len(todo)} to run {where}"))
    if todo and not summary_only:
        with dask_client(scheduler, workers) as client:
            run_replicates(cal, todo, client, progress=progress)
    records = read_records(cal)
    result = calibration_result(cal, records)
    write_json_atomic(out / "calibration.json", result)
    logger.info(f"wrote {out / 'calibration.json'} ({result['replicates']} replicates, "
                f"{len(result['failed'])} failed)")
    if report:
        from ..report.calibration import build_calibration_page
        page = build_calibration_page(result, out / "calibration.html", figures_dir=out / "figures")
        logger.info(f"wrote {page}")
    return result
