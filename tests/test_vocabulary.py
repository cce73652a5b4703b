"""The repository speaks to users, not about how it was developed.

Every tracked text file is free of development bookkeeping — numbered work stops, sessions, rounds and
issue numbers — and the README is a front page of at most 300 non-blank lines that does not cite the
internal specification. Failures list every offending ``file:line``.
"""
from __future__ import annotations

import re
import subprocess
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
THIS = Path(__file__).resolve()

#: a numbered stop, session, round or issue (the word, an optional '#' or '-', digits); not a decimal after
#: "round", nor "round-off" (the examples in the tests below are assembled from word and number, so that this file does not
#: itself carry the bookkeeping a reader should not meet)
DEV_WORDS = re.compile(r"\b(?:stop|session|round)s?[ -]#?\d+\b(?![.,]\d)|\bissues?[ -]#?\d+\b(?![.,]\d)",
                       re.IGNORECASE)


def tracked_text_files() -> list[Path]:
    out = subprocess.run(["git", "ls-files", "-z"], cwd=REPO, capture_output=True, check=True).stdout
    files = []
    for name in out.decode().split("\0"):
        path = REPO / name
        if not name or not path.is_file() or path.resolve() == THIS:
            continue
        head = path.read_bytes()[:8192]
        if b"\0" in head:
            continue                                    # binary
        files.append(path)
    return files


def offending_lines(path: Path) -> list[str]:
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        return []
    return [f"{path.relative_to(REPO)}:{i}: {m.group(0)!r}"
            for i, line in enumerate(text.splitlines(), 1) for m in DEV_WORDS.finditer(line)]


def test_the_pattern_flags_bookkeeping_and_spares_ordinary_words():
    flagged = [f"{w}{sep}{n}{tail}" for w, sep, n, tail in
               [("stop", " ", 31, ""), ("Stop", " ", 26, ": the sampler"), ("session", " ", 4, ""),
                ("round", " #", 2, ""), ("issue", " ", 18, ""), ("issues", " #", 16, ""), ("stop", "-", 26, " sampler"),
                ("(stops", " ", 24, ")"), ("Issue", " #", 13, "")]]
    spared = [f"{'round'} 0.5 to the nearest", "round-off error", "the sampler stops when", "round(x, 3)",
              "a stop after least squares", "issue a warning", "rounds of 50 steps", "sessions (one per run)",
              f"{'round'} 1,5 mm"]
    assert all(DEV_WORDS.search(s) for s in flagged), [s for s in flagged if not DEV_WORDS.search(s)]
    assert not any(DEV_WORDS.search(s) for s in spared), [s for s in spared if DEV_WORDS.search(s)]


def test_no_development_bookkeeping_in_tracked_files():
    hits = [h for p in tracked_text_files() for h in offending_lines(p)]
    assert not hits, f"{len(hits)} lines name development stops, sessions, rounds or issues:\n" + "\n".join(hits[:300])


def test_readme_is_a_front_page():
    text = (REPO / "README.md").read_text()
    non_blank = [line for line in text.splitlines() if line.strip()]
    assert len(non_blank) <= 300, f"README.md has {len(non_blank)} non-blank lines (at most 300)"
    assert "SPEC §" not in text and "SPEC §" not in " ".join(text.split()), "README.md cites the internal specification"
