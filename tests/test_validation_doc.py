"""docs/validation.md is generated from the committed result files and must not go stale.

``tools/make_validation.py --check`` rebuilds the page from the JSON files under ``runs/`` and
``benchmarks/results/`` and compares it with the committed page. Needs only numpy and scipy.
"""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def test_validation_page_matches_the_committed_results():
    r = subprocess.run([sys.executable, str(REPO / "tools" / "make_validation.py"), "--check"],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, ("docs/validation.md differs from what the committed result files give "
                               "(run python tools/make_validation.py):\n" + r.stdout[-4000:] + r.stderr[-2000:])


def test_every_verdict_comes_with_a_claim_and_a_command():
    text = (REPO / "docs" / "validation.md").read_text()
    sections = text.split("\n## ")[1:]
    assert len(sections) >= 7
    for s in sections:
        title = s.splitlines()[0]
        assert "**Claim.**" in s, title
        assert "Verdict:" in s, title
        assert "Reproduce" in s or "measured by" in s.lower(), title
