"""Honest progress and outputs of `bayes-disc sample`: stages with durations, progress toward convergence
(not toward the step cap), resume that says what it resumes and keeps the ensembles aligned, and reports
that go with the run when ``--output`` is given (so the README's demo leaves the repository clean)."""
import fnmatch
import json
import logging
import re
import shutil
import subprocess
from pathlib import Path

import emcee
import h5py
import numpy as np
import pytest

from bayes_disc.cli import main
from bayes_disc.jobs import sample as run_module
from bayes_disc.inference.model.config import SamplerSettings, load_config
from bayes_disc.jobs.sample import run_sample
from bayes_disc.inference.sampling.progress import Progress, _Bar
from bayes_disc.inference.sampling.stopping import convergence_fraction
from bayes_disc.observation.config_io import ConfigError

from conftest import REPO, run_config, write_short_flight

pytestmark = pytest.mark.xdist_group("progress_run")   # one worker builds the module's shared run

CONFIG = run_config("prog", "prior: potts_crowther", "output: out",
                    "sampler: {ensembles: 3, max_steps: 45, adapt_steps: 15, check_every: 15, min_steps: 10, seed: 5}",
                    "least_squares: {starts: 2}")


class _Records(logging.Handler):
    """Keeps the package's log messages (the command line stops propagation to the root logger)."""

    def __init__(self):
        super().__init__(logging.DEBUG)
        self.messages = []

    def emit(self, record):
        self.messages.append(record.getMessage())


def _small_run_folder(folder: Path) -> Path:
    write_short_flight(folder)
    cfg = folder / "config.yaml"
    cfg.write_text(CONFIG)
    return cfg


@pytest.fixture(scope="module")
def first_run(tmp_path_factory):
    """A short run through the command line (3 ensembles, 45 steps, cap reached), with its log messages."""
    d = tmp_path_factory.mktemp("progress")
    cfg = _small_run_folder(d)
    records = _Records()
    root = logging.getLogger("bayes_disc")
    root.addHandler(records)
    mp = pytest.MonkeyPatch()
    mp.chdir(d)
    try:
        assert main(["sample", str(cfg)]) == 0          # progress on: stderr is not a terminal under pytest
    finally:
        mp.undo()
        root.removeHandler(records)
    return d, records.messages


def _copy(first_run, tmp_path) -> Path:
    src, _ = first_run
    dst = tmp_path / "run"
    shutil.copytree(src, dst)
    return dst


def _steps(folder: Path) -> list:
    return [emcee.backends.HDFBackend(str(p), read_only=True).iteration
            for p in sorted((folder / "out/chains").glob("ensemble_*.h5"))]


# ------------------------------------------------------------------------------------ progress figures
def test_convergence_fraction_is_the_worst_criterion_and_one_only_when_converged():
    s = SamplerSettings(rhat=1.01, ess=400, n_tau=10, min_steps=400)
    v = {"rhat_max": 1.02, "ess_min_coef": 300.0, "n_over_tau": 20.0, "converged": False}
    assert convergence_fraction(v, s, 800) == pytest.approx(0.5)        # R-hat: 0.01 / 0.02
    assert convergence_fraction({**v, "rhat_max": 1.005}, s, 800) == pytest.approx(0.75)   # ESS 300 / 400
    assert convergence_fraction({**v, "rhat_max": 1.005, "ess_min_coef": 500, "n_over_tau": 4}, s,
                                800) == pytest.approx(0.4)                # N/τ 4 / 10
    assert convergence_fraction({**v, "rhat_max": 1.005, "ess_min_coef": 500}, s, 100) == pytest.approx(0.25)
    # every figure at its target but the verdict says no (R-hat must be strictly below): not 100 %
    edge = {"rhat_max": 1.01, "ess_min_coef": 400.0, "n_over_tau": 10.0, "converged": False}
    assert convergence_fraction(edge, s, 400) < 1.0
    assert convergence_fraction({**edge, "rhat_max": 1.009, "converged": True}, s, 400) == 1.0
    assert convergence_fraction({**v, "rhat_max": float("nan")}, s, 800) == 0.0


def test_progress_line_shows_the_cap_but_measures_convergence():
    s = SamplerSettings(max_steps=3000, adapt_steps=150, check_every=50)
    warm = Progress(steps=100, cap=3000, fraction=0.0, verdict=None).describe(s)
    assert "step 100 (cap 3000)" in warm and "warm-up until step 350" in warm
    v = {"rhat_max": 1.034, "ess_min_coef": 210.0, "n_over_tau": 8.0, "converged": False}
    line = Progress(steps=700, cap=3000, fraction=0.29, verdict=v).describe(s)
    assert line == "step 700 (cap 3000), R-hat 1.034 (< 1.01), ESS 210 (≥ 400), N/τ 8.0 (≥ 10)"


def test_no_bar_when_asked_or_when_stderr_is_not_a_terminal(capsys):
    s = SamplerSettings()
    for progress in (True, False):     # under pytest stderr is captured: not a terminal
        bar = _Bar(s, progress)
        bar.show(Progress(400, 3000, 0.5, {"rhat_max": 1.02, "ess_min_coef": 300.0, "n_over_tau": 12.0,
                                            "converged": False}), checked=True)
        bar.close()
        assert not bar.shown
    assert capsys.readouterr().err == ""


def test_stages_are_logged_with_durations_and_the_report_once(first_run):
    d, messages = first_run
    for name in ("reading flights and checks", "least squares", "profile likelihoods", "sampling", "outputs",
                 "report"):
        assert any(m.startswith(f"{name}") and m.endswith("…") for m in messages), name
        assert any(re.match(rf"{name} done in \d+\.\d s", m) for m in messages), name
    assert [m for m in messages if m.startswith("least squares: start")] == [
        m for m in messages if re.match(r"least squares: start [12]/2 cost \d", m)]
    assert len([m for m in messages if m.startswith("least squares: start")]) == 2
    # no bar (not a terminal): one line per profile and per convergence check instead
    assert len([m for m in messages if m.startswith("profile likelihood ")]) == 10
    checks = [m for m in messages if m.startswith("convergence check: step 45 (cap 45), R-hat")]
    assert len(checks) == 1
    wrote = [m for m in messages if m.startswith("wrote ") and "prog.html" in m]
    assert len(wrote) == 1 and (d / "out/reports/prog.html").is_file()      # the report goes with its run


# --------------------------------------------------------------------------------------------- resume
def test_resume_says_what_it_resumes_aligns_ensembles_and_keeps_the_history(first_run, tmp_path, caplog,
                                                                            monkeypatch):
    d = _copy(first_run, tmp_path)
    assert _steps(d) == [45, 45, 45]
    first_history = json.loads((d / "out/run_info.json").read_text())["history"]
    assert first_history and first_history[-1]["steps"] == 45
    # an interruption in the middle of a round: ensemble 1 saved only 33 steps
    with h5py.File(d / "out/chains/ensemble_1.h5", "a") as f:
        f["mcmc"].attrs["iteration"] = 33
    assert _steps(d) == [45, 33, 45]

    def fail(*args, **kwargs):
        raise AssertionError("resume must reuse the saved least squares and proposals")
    monkeypatch.setattr(run_module, "fit_least_squares", fail)
    monkeypatch.setattr(run_module, "posterior_approximation", fail)
    cfg = d / "config.yaml"
    cfg.write_text(cfg.read_text().replace("max_steps: 45", "max_steps: 60"))
    with caplog.at_level(logging.INFO, logger="bayes_disc"):
        summary = run_sample(load_config(cfg), resume=True, progress=False)
    assert ("resuming prog from step 45 of each ensemble (ensembles at 45, 33, 45 steps; the shorter ones are "
            "first advanced to 45)") in caplog.messages
    assert any(m.startswith("resume: reusing the saved least-squares optimum") for m in caplog.messages)
    assert _steps(d) == [60, 60, 60]
    assert summary["convergence"]["total_steps"] == 60
    info = json.loads((d / "out/run_info.json").read_text())
    history = info["history"]
    assert history[: len(first_history)] == first_history          # nothing dropped
    new = history[len(first_history):]
    assert new[0] == {"steps": 45, "resumed": True, "ensemble_steps": [45, 33, 45]}
    assert new[1] == {"steps": 45, "aligned": True, "ensemble_steps": [45, 45, 45]}
    assert [h["steps"] for h in new if "converged" in h] == [45, 60]
    assert [s["resumed_from_steps"] for s in info["sessions"]] == [None, [45, 33, 45]]
    assert json.loads((d / "out/chains/history.json").read_text()) == history


def test_resume_refuses_a_changed_configuration(first_run, tmp_path):
    d = _copy(first_run, tmp_path)
    cfg = d / "config.yaml"
    cfg.write_text(cfg.read_text().replace('"0": [0.100, 0.000, -0.015]', '"0": [0.101, 0.000, -0.015]')
                   .replace("ensembles: 3", "ensembles: 4"))
    with pytest.raises(ConfigError, match=r"cannot resume .*configuration changed.*markers.*ensembles 3 → 4"):
        run_sample(load_config(cfg), resume=True, progress=False)
    assert _steps(d) == [45, 45, 45]                                  # untouched
    assert main(["sample", str(cfg), "--resume", "--no-progress", "--output", str(d / "out")]) == 2


def test_resume_without_chain_files_starts_afresh_and_one_without_steps_restarts_from_its_walkers(
        tmp_path, caplog, monkeypatch):
    cfg = _small_run_folder(tmp_path)
    # 15 steps, no warm-up adaptation yet: an interruption during the first round
    cfg.write_text(cfg.read_text().replace("max_steps: 45", "max_steps: 15").replace("adapt_steps: 15", "adapt_steps: 60")
                   .replace("starts: 2", "starts: 1"))
    monkeypatch.chdir(tmp_path)
    with caplog.at_level(logging.INFO, logger="bayes_disc"):
        run_sample(load_config(cfg), resume=True, progress=False)
    assert any(m.startswith("--resume: no chain files in") and m.endswith("starting a fresh run")
               for m in caplog.messages)
    assert _steps(tmp_path) == [15, 15, 15]
    original = emcee.backends.HDFBackend(str(tmp_path / "out/chains/ensemble_2.h5"), read_only=True).get_chain()
    with h5py.File(tmp_path / "out/chains/ensemble_2.h5", "a") as f:
        f["mcmc"].attrs["iteration"] = 0
    caplog.clear()
    with caplog.at_level(logging.INFO, logger="bayes_disc"):
        run_sample(load_config(cfg), resume=True, progress=False)
    assert "ensembles at 15, 15, 0 steps" in " ".join(caplog.messages)
    assert _steps(tmp_path) == [15, 15, 15]
    # the same seed redraws the same start walkers: the redone ensemble repeats its first steps exactly
    again = emcee.backends.HDFBackend(str(tmp_path / "out/chains/ensemble_2.h5"), read_only=True).get_chain()
    np.testing.assert_array_equal(again, original)


# -------------------------------------------------------------------------------------------- outputs
def _repository_state() -> tuple:
    """`git status` of the repository (when it is a git checkout) and the reports' sizes and mtimes."""
    reports = sorted((p.name, p.stat().st_mtime_ns, p.stat().st_size) for p in (REPO / "reports").glob("*"))
    status = None
    if shutil.which("git") and (REPO / ".git").exists():
        status = subprocess.run(["git", "status", "--porcelain", "--untracked-files=all"], cwd=REPO,
                                capture_output=True, text=True, check=True).stdout
    return status, reports


def test_output_dir_gets_the_report_and_the_repository_is_left_alone(first_run, tmp_path, monkeypatch):
    d = _copy(first_run, tmp_path)
    shutil.rmtree(d / "out")
    out = tmp_path / "elsewhere"
    before = _repository_state()
    monkeypatch.chdir(REPO)                # a default report would land in the repository's reports/
    assert main(["sample", str(d / "config.yaml"), "--no-progress", "--output", str(out)]) == 0
    assert (out / "reports/prog.html").is_file() and (out / "summary.json").is_file()
    assert not (REPO / "reports/prog.html").exists()
    assert _repository_state() == before


def test_readme_demo_command_writes_only_ignored_files():
    """The README's first command writes its run and report into a folder .gitignore ignores."""
    readme = (REPO / "README.md").read_text()
    first = re.search(r"```bash\n(.*?)\n```", readme, re.S).group(1)
    command = first.split("&&")[-1].split()
    assert command[:2] == ["bayes-disc", "sample"]
    override = command[command.index("--output") + 1].rstrip("/") if "--output" in command else None
    config = load_config(REPO / command[2], output_override=override)
    output = Path(config.output).resolve().relative_to(REPO).as_posix()
    ignored = [line.strip().rstrip("/") for line in (REPO / ".gitignore").read_text().splitlines()
               if line.strip() and not line.startswith("#")]
    assert any(fnmatch.fnmatch(output, pattern) for pattern in ignored), (output, ignored)
