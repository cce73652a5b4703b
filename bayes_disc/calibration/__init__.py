"""Simulation-based calibration of the whole inference (``bayes-disc calibrate CAL.yaml``, docs/outputs.md).

Orchestration at the top of the layers, beside :mod:`bayes_disc.jobs`: it uses synthetic flights
(:mod:`~bayes_disc.observation.synth`), the sampling job (:func:`bayes_disc.api.sample`) and a report page
(:mod:`bayes_disc.report.calibration`, given plain data). Modules: :mod:`.config` (CAL.yaml),
:mod:`.stats` (ranks, coverage, uniformity test), :mod:`.replicate` (one data set, one fit: a Dask task),
:mod:`.campaign` (tasks on Dask, records on disk, resume, summary). docs/calibration.md explains it all.
"""
from .campaign import run_campaign
from .config import CalConfig, cal_config_from_mapping, load_cal_config

__all__ = ["CalConfig", "cal_config_from_mapping", "load_cal_config", "run_campaign"]
