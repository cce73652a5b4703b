"""The user documentation cannot silently go stale.

* Every key the run-configuration reader (``bayes_disc.inference.model.config.load_config``) accepts appears in
  ``docs/configuration.md`` with its default, and every key documented there is accepted.
* Every relative link between the documentation pages resolves.
* No ``--help`` text points to the internal specification.

The accepted keys are not listed by hand: a configuration that uses every section (every physics term and
data explanation, a per-flight option) is loaded while the strict YAML reader records each key it asks for.
"""
from __future__ import annotations

import math
import re
from pathlib import Path

import pytest
import yaml

from bayes_disc.observation import config_io
from bayes_disc.observation.explanations import EXPLANATIONS
from bayes_disc.physics.terms import TERMS

from conftest import REPO

DOCS = REPO / "docs"
CONFIG_DOC = DOCS / "configuration.md"
MARKER_IDS = ("mk0", "mk1", "mk2")
FLIGHT = "someflight"
REQUIRED = object()


def _normalise(key: str) -> str:
    """Concrete key → documented form: list indices, marker ids and flight names become placeholders."""
    key = re.sub(r"\[\d+\]", "[]", key)
    key = re.sub(r"mk\d", "<id>", key)
    key = re.sub(r"^prior\.sd\.\w+$", "prior.sd.<coefficient>", key)
    return key.replace(f"flight_options.{FLIGHT}.", "flight_options.<flight>.")


def accepted_keys(tmp_path: Path) -> dict:
    """{documented key form: default (REQUIRED when required)} of every key ``load_config`` asks for."""
    from bayes_disc.inference.model.config import load_config
    (tmp_path / "f.csv").write_text("flight,t,marker,x,y,z\n")
    (tmp_path / "truth.json").write_text("{}")
    (tmp_path / "log.csv").write_text("flight,t,gx,gy,gz,ax,ay,az\n")
    physics = {tid: {} for tid in TERMS} | {eid: {} for eid in EXPLANATIONS}
    cfg = {"name": "keys", "flights": [{"file": "f.csv"}],
           "markers": {m: [0.1 * i, 0.0, -0.015] for i, m in enumerate(MARKER_IDS)},
           "physics": physics, "flight_options": {FLIGHT: {"t_start": 0.0}}, "truth": "truth.json",
           "imu": [{"file": "log.csv", "format": "imu-csv", "throws": [[0, 100]]}]}
    seen: dict = {}
    original = config_io.Section.raw

    def recording(self, name, default=None, required=False):
        seen.setdefault(self.key(name), REQUIRED if required else default)
        return original(self, name, default, required)

    # the prior's two forms: a named set, and the mapping {around, relative_sd, sd}
    for i, prior in enumerate(("potts_crowther", {"around": "hummel2002", "sd": {"CNr": 1e-5}})):
        path = tmp_path / f"config{i}.yaml"
        path.write_text(yaml.safe_dump(cfg | {"prior": prior}))
        with pytest.MonkeyPatch.context() as mp:
            mp.setattr(config_io.Section, "raw", recording)
            load_config(path)
    return {_normalise(k): v for k, v in seen.items()}


def leaves(keys) -> set:
    """Keys that are not the parent of another key (the settings themselves, not their sections)."""
    keys = set(keys)
    return {k for k in keys if not any(o != k and (o.startswith(k + ".") or o.startswith(k + "[")) for o in keys)}


def documented_rows(text: str) -> dict:
    """{key: default cell} of every table row of the form ``| `key` | type | default | meaning |``."""
    rows = {}
    for line in text.splitlines():
        m = re.match(r"\|\s*`([^`]+)`\s*\|[^|]*\|([^|]*)\|", line)
        if m:
            rows[m.group(1)] = m.group(2).strip()
    return rows


def default_matches(cell: str, default) -> bool:
    if default is REQUIRED:
        return cell == "required"
    if default is None:
        return cell.startswith("—")
    m = re.match(r"`([^`]*)`", cell)
    if m is None:
        return False
    if isinstance(default, bool):                      # YAML's spelling
        return m.group(1) == ("true" if default else "false")
    if isinstance(default, (int, float)):
        try:
            return math.isclose(float(m.group(1)), float(default), rel_tol=1e-12, abs_tol=0.0)
        except ValueError:
            return False
    return m.group(1) == str(default)


def test_accepted_keys_are_recorded(tmp_path):
    """The recorder sees nested keys, placeholders and physics parameters (else the next tests prove nothing)."""
    keys = accepted_keys(tmp_path)
    for k in ("name", "flights[].file", "markers.<id>", "sampler.ensembles", "simulator.step_factor",
              "physics.side_force.CY", "physics.marker_geometry.marker_b3_<id>", "physics.time_offset.dt_<id>",
              "flight_options.<flight>.t_end", "truth"):
        assert k in keys, k
    assert keys["name"] is REQUIRED and keys["sampler.ensembles"] == 4 and keys["output"] is None
    assert "sampler" not in leaves(keys) and "sampler.seed" in leaves(keys)


def test_every_accepted_config_key_is_documented_with_its_default(tmp_path):
    keys = accepted_keys(tmp_path)
    rows = documented_rows(CONFIG_DOC.read_text())
    missing = sorted(k for k in leaves(keys) if k not in rows)
    assert not missing, f"keys accepted by bayes_disc/inference/model/config.py but not documented in {CONFIG_DOC}: {missing}"
    wrong = {k: (rows[k], keys[k]) for k in leaves(keys)
             if not default_matches(rows[k], keys[k])}
    assert not wrong, f"documented default differs from the code (doc cell, code default): {wrong}"


def test_every_documented_config_key_is_accepted(tmp_path):
    keys = accepted_keys(tmp_path)
    stale = sorted(k for k in documented_rows(CONFIG_DOC.read_text()) if k not in keys)
    assert not stale, f"{CONFIG_DOC} documents keys the configuration reader does not accept: {stale}"


def test_the_checks_catch_an_undocumented_key_and_a_wrong_default(tmp_path):
    """Negative control: a key missing from the page, or a changed default, is reported."""
    keys = accepted_keys(tmp_path)
    rows = documented_rows(CONFIG_DOC.read_text())
    del rows["sampler.max_steps"]
    assert [k for k in leaves(keys) if k not in rows] == ["sampler.max_steps"]
    assert default_matches("`3000`", 3000) and not default_matches("`2000`", 3000)
    assert default_matches("required", REQUIRED) and not default_matches("`x`", REQUIRED)
    assert default_matches("— (whole flight)", None) and not default_matches("`0`", None)
    assert default_matches("`vern7`", "vern7") and not default_matches("`rk4`", "vern7")


def heading_anchors(text: str) -> set:
    """GitHub's anchors of the Markdown headings: lower case, punctuation dropped, spaces → hyphens."""
    return {re.sub(r"[^\w\- ]", "", h.strip().lower()).replace(" ", "-")
            for h in re.findall(r"^#+ (.+)$", text, flags=re.M)}


def broken_links(page: Path) -> list:
    """Relative links of a Markdown page whose file or heading anchor does not exist."""
    broken = []
    for target in re.findall(r"\]\(([^)\s]+)\)", page.read_text()):
        if re.match(r"[a-z]+://", target):
            continue
        name, _, anchor = target.partition("#")
        file = (page.parent / name).resolve() if name else page
        if not file.exists():
            broken.append(target)
        elif anchor and file.suffix == ".md" and anchor not in heading_anchors(file.read_text()):
            broken.append(target)
    return broken


def test_documentation_links_resolve(tmp_path):
    pages = sorted(DOCS.glob("*.md")) + [REPO / "README.md", REPO / "bayes_disc" / "video" / "README.md",
                                         REPO / "runs" / "video_demo" / "README.md"]
    broken = {str(p.relative_to(REPO)): b for p in pages if (b := broken_links(p))}
    assert not broken, broken
    # negative control: a missing file and a missing heading are both caught
    page = tmp_path / "page.md"
    page.write_text("# Flight model (Hummel & Hubbard 2002)\n[a](#flight-model-hummel--hubbard-2002) [b](nope.md) "
                    "[c](#no-such-heading) [d](page.md#flight-model-hummel--hubbard-2002)\n")
    assert broken_links(page) == ["nope.md", "#no-such-heading"]


def test_package_and_example_reports_never_cite_the_internal_specification(tmp_path):
    """Users have no "SPEC": no module of the package and no shipped example report cites it; the check
    catches a planted citation."""
    def citing(paths):
        return [p.name for p in paths if re.search(r"\bSPEC\b", p.read_text(encoding="utf-8"))]
    files = sorted((REPO / "bayes_disc").rglob("*.py")) + sorted((REPO / "docs" / "examples").glob("*.html"))
    assert len(files) > 50
    assert citing(files) == []
    planted = tmp_path / "planted.html"
    planted.write_text("<p>Rate coefficients are per rad/s, as in SPEC §2.</p>", encoding="utf-8")
    assert citing(files[:3] + [planted]) == ["planted.html"]


#: a documented command of a job on a shipped run configuration, with its options
JOB_COMMAND = re.compile(r"bayes-disc (sample|diagnose|identifiability) (runs/[^\s`<>]+\.yaml)([^`&;\n]*)")
#: the file each job writes into its output folder (the folder holding it refuses the job without --overwrite)
JOB_RESULT = {"sample": "summary.json", "diagnose": "diagnosis.json", "identifiability": "identifiability.json"}


def unsafe_reproduce_commands(text: str, tracked: set) -> list[str]:
    """Documented job commands whose output folder holds a committed result of the same job but which carry
    neither ``--overwrite`` nor ``--output``: on a fresh checkout the job refuses them."""
    bad = []
    for job, config, options in JOB_COMMAND.findall(text):
        path = REPO / config
        output = (yaml.safe_load(path.read_text()) or {}).get("output", "out")
        result = (path.parent / output / JOB_RESULT[job]).relative_to(REPO).as_posix()
        if result in tracked and "--overwrite" not in options and "--output" not in options:
            bad.append(f"bayes-disc {job} {config}{options.rstrip()}")
    return bad


def test_reproduce_commands_replace_committed_results_explicitly():
    """Every documented command that reruns a job whose results are committed in the run folder says
    ``--overwrite`` (the job refuses a folder with an earlier job's results otherwise); a command without it is
    caught."""
    import subprocess
    tracked = set(subprocess.run(["git", "ls-files"], cwd=REPO, capture_output=True, text=True,
                                 check=True).stdout.split())
    pages = [REPO / "README.md", *sorted((REPO / "docs").glob("*.md")), REPO / "docs" / "examples" / "README.md"]
    bad = {p.relative_to(REPO).as_posix(): b for p in pages
           if (b := unsafe_reproduce_commands(p.read_text(encoding="utf-8"), tracked))}
    assert not bad, bad
    assert unsafe_reproduce_commands("`bayes-disc diagnose runs/concealed/config.yaml`", tracked) == [
        "bayes-disc diagnose runs/concealed/config.yaml"]
    assert unsafe_reproduce_commands("`bayes-disc diagnose runs/concealed/config.yaml --overwrite`", tracked) == []


def test_help_texts_speak_to_users():
    """``--help`` of every command: no reference to the internal specification ("SPEC §")."""
    from bayes_disc.cli import build_parser
    parser = build_parser()
    texts = [parser.format_help()]
    sub = next(a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction")
    texts += [p.format_help() for p in sub.choices.values()]
    assert len(texts) > 8
    offending = [t.splitlines()[0] for t in texts if "SPEC" in t]
    assert not offending, offending
