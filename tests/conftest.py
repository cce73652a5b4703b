import os
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared"
REFERENCE_DIR = SHARED / "reference"
REFERENCE_MISSING = "../shared/reference not found beside the checkout: CI provides it"

#: the demo disc's three markers in the body frame [m] (as in runs/demo/config.yaml)
MARKERS = {"0": [0.100, 0.000, -0.015], "1": [-0.0308, 0.0846, -0.015], "2": [-0.0707, -0.0778, -0.015]}
#: the ``markers:`` block of a run configuration with :data:`MARKERS`
MARKERS_YAML = """markers:
  "0": [0.100, 0.000, -0.015]
  "1": [-0.0308, 0.0846, -0.015]
  "2": [-0.0707, -0.0778, -0.015]
"""


def run_config(name: str, *lines: str) -> str:
    """A run configuration (YAML text): ``name``, the marker file ``flights.csv`` beside it, :data:`MARKERS`,
    then ``lines`` (one key each, e.g. ``"output: out"``)."""
    return f"name: {name}\nflights:\n  - file: flights.csv\n{MARKERS_YAML}" + "".join(f"{line}\n" for line in lines)


def write_short_flight(folder: Path) -> None:
    """One synthetic 0.5-s flight ``short`` (seed 3): ``flights.csv`` and ``truth.json`` in ``folder``."""
    from bayes_disc.observation.synth import LaunchSpec, SynthSpec, synthesize, write_synth
    f = LaunchSpec(name="short", speed=12.0, launch_angle_deg=4, alpha_deg=8, spin=55, duration=0.5,
                   noise_mm=1.5, dropout=0.02)
    write_synth(synthesize(SynthSpec(name="s", flights=(f,), seed=3)), folder / "flights.csv", folder / "truth.json")


def write_two_flights(folder: Path, duration: float) -> None:
    """Two synthetic flights ``a`` and ``b`` of ``duration`` seconds (seed 4, 1.5 and 2.5 mm noise):
    ``flights.csv`` and ``truth.json`` in ``folder``."""
    from bayes_disc.observation.synth import LaunchSpec, SynthSpec, synthesize, write_synth
    flights = (LaunchSpec(name="a", speed=12.0, launch_angle_deg=4, alpha_deg=8, spin=55, duration=duration,
                          noise_mm=1.5, dropout=0.05),
               LaunchSpec(name="b", speed=10.0, launch_angle_deg=8, alpha_deg=14, spin=-50, duration=duration,
                          noise_mm=2.5, dropout=0.0))
    write_synth(synthesize(SynthSpec(name="s", flights=flights, seed=4)), folder / "flights.csv", folder / "truth.json")


def in_ci(environ=None) -> bool:
    """True when the environment says this is a CI run (``CI=true``, as CI services and ``.ci/run`` set it)."""
    return (os.environ if environ is None else environ).get("CI", "").strip().lower() in ("true", "1", "yes")


def require_outside_input(present: bool, reason: str, environ=None) -> None:
    """Skip the calling test when an input that lives outside the repository is absent, except in CI.

    Parameters
    ----------
    present : bool
        Whether the input (a folder beside the checkout, a system program) is there.
    reason : str
        Why it may be absent on a user's machine; the skip (or CI failure) message.
    environ : mapping, optional
        Environment to read ``CI`` from (default ``os.environ``).

    Raises
    ------
    pytest.skip.Exception
        Absent on a user's machine: the test is skipped with ``reason``.
    pytest.fail.Exception
        Absent in CI (``CI=true``): CI must run the test, so this is a failure.
    """
    if present:
        return
    if in_ci(environ):
        pytest.fail(f"{reason}; CI=true, so this is an error, not a skip")
    pytest.skip(reason)


def locate_reference(path: Path = REFERENCE_DIR, environ=None) -> Path:
    """The reference-trajectory folder ``../shared/reference`` (skips outside CI when absent).

    Parameters
    ----------
    path : Path
        Where the folder is expected (default: ``shared/reference`` beside the checkout).
    environ : mapping, optional
        Environment to read ``CI`` from (default ``os.environ``).

    Returns
    -------
    Path
        ``path``, when it is a folder.
    """
    require_outside_input(Path(path).is_dir(), REFERENCE_MISSING, environ)
    return Path(path)


def reference_case_names(path: Path = REFERENCE_DIR) -> list:
    """Stems of the ``NAME.json`` cases in ``path`` (empty when the folder is absent)."""
    return sorted(p.stem for p in Path(path).glob("*.json")) if Path(path).is_dir() else []


@pytest.fixture(scope="session")
def reference_dir() -> Path:
    """The reference trajectories (``../shared/reference``); skipped with the reason when absent, failed in CI."""
    return locate_reference()


@pytest.fixture(scope="module")
def two_flights(tmp_path_factory):
    """Two 1-s synthetic flights with white marker noise: (Problem, its least-squares result)."""
    from bayes_disc.inference.fitting.leastsq import fit_least_squares
    from bayes_disc.inference.model.config import load_config
    from bayes_disc.inference.model.data import build_problem
    d = tmp_path_factory.mktemp("two")
    write_two_flights(d, 1.0)
    (d / "config.yaml").write_text(run_config("two", "output: out", "noise: {model: gaussian}"))
    problem = build_problem(load_config(d / "config.yaml"))
    return problem, fit_least_squares(problem, starts=1, max_nfev=200, seed=1)


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


def keep_flights(csv_path: Path, names) -> None:
    """Rewrite a marker CSV keeping only the rows of the named flights."""
    import csv
    rows = list(csv.reader(Path(csv_path).open()))
    with Path(csv_path).open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(rows[0])
        w.writerows(r for r in rows[1:] if r[0] in names)
