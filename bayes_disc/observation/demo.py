"""The shipped demo: four synthetic flights and their run configuration, packaged with bayes-disc.

``bayes-disc demo FOLDER`` (:func:`write_demo`) writes them into a folder of the user's, so that
``bayes-disc sample FOLDER/config.yaml`` runs from an installed package, outside the source repository:

* ``flights.csv`` — four flights in the marker format (docs/data-formats.md), 120 Hz, 1–3 mm noise, 2 %
  dropped points, made by ``synth.yaml`` with the Hummel & Hubbard (2002) coefficients;
* ``truth.json`` — their true coefficients and initial conditions (the report compares the posterior with it);
* ``synth.yaml`` — the launch description that made them (``bayes-disc synth FOLDER/synth.yaml``);
* ``config.yaml`` — the run configuration (docs/configuration.md), output folder ``out`` beside it.

The source repository's ``runs/demo/`` holds the same files (a test keeps them identical).
"""
from __future__ import annotations

from importlib import resources
from pathlib import Path

from .config_io import ConfigError

#: the demo's files, in the order they are written
DEMO_FILES = ("config.yaml", "flights.csv", "synth.yaml", "truth.json")


def demo_file(name: str) -> bytes:
    """The content of one of the packaged demo files.

    Parameters
    ----------
    name : str
        One of :data:`DEMO_FILES`.

    Returns
    -------
    bytes
    """
    return resources.files("bayes_disc").joinpath("data", "demo", name).read_bytes()


def write_demo(folder, overwrite: bool = False) -> list[Path]:
    """Write the demo's flights and configuration into ``folder`` (created if missing).

    Parameters
    ----------
    folder : str or Path
        Where to write.
    overwrite : bool
        Replace demo files already there; otherwise a folder that holds any of them is refused.

    Returns
    -------
    list of Path
        The files written.

    Raises
    ------
    ConfigError
        When ``folder`` is a file, or already holds demo files and ``overwrite`` is False (nothing is written).
    """
    folder = Path(folder)
    if folder.exists() and not folder.is_dir():
        raise ConfigError(folder, None, "is a file; give a folder for the demo")
    present = [n for n in DEMO_FILES if (folder / n).exists()]
    if present and not overwrite:
        raise ConfigError(folder, None, f"already holds {', '.join(present)}; use --overwrite to replace them, "
                                        "or give another folder")
    folder.mkdir(parents=True, exist_ok=True)
    written = []
    for name in DEMO_FILES:
        (folder / name).write_bytes(demo_file(name))
        written.append(folder / name)
    return written
