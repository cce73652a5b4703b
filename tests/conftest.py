from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared"
REFERENCE_DIR = SHARED / "reference"


@pytest.fixture(scope="session")
def reference_dir() -> Path:
    assert REFERENCE_DIR.is_dir(), f"SPEC §3 reference trajectories expected at {REFERENCE_DIR} (../shared/reference)"
    return REFERENCE_DIR


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
