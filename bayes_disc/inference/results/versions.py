"""Versions of the software that produced a run (recorded in ``run_info.json``, shown in the report)."""
from __future__ import annotations

import platform
from importlib import metadata

from ..._version import __version__

#: the numerical packages whose versions a run records
RECORDED_PACKAGES = ("numpy", "scipy", "numba", "emcee", "arviz", "corner", "matplotlib", "h5py")


def software_versions() -> dict[str, str]:
    """Versions of bayes-disc, Python and the numerical packages.

    Returns
    -------
    dict of str to str
        ``{"bayes-disc": ..., "Python": ..., package: version}`` for every package of
        :data:`RECORDED_PACKAGES`; ``"not installed"`` for a package that is absent.
    """
    out = {"bayes-disc": __version__, "Python": platform.python_version()}
    for pkg in RECORDED_PACKAGES:
        try:
            out[pkg] = metadata.version(pkg)
        except metadata.PackageNotFoundError:
            out[pkg] = "not installed"
    return out
