"""A user's first contact, as CI checks it: the wheel alone, outside the repository; and a plain run of the
shipped demo that leaves the repository as it was."""
import os
import subprocess
import sys
import venv
from pathlib import Path

import pytest

from conftest import REPO

pytestmark = pytest.mark.slow


def _run(cmd, cwd, env=None, timeout=1800) -> subprocess.CompletedProcess:
    out = subprocess.run([str(c) for c in cmd], cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)
    assert out.returncode == 0, f"{cmd} exited {out.returncode}\n{out.stdout[-3000:]}\n{out.stderr[-3000:]}"
    return out


def test_the_wheel_installs_into_a_fresh_environment_and_runs_the_demo_outside_the_repository(tmp_path):
    dist = tmp_path / "dist"
    _run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", dist, REPO], cwd=tmp_path)
    wheels = list(dist.glob("bayes_disc-*.whl"))
    assert len(wheels) == 1, wheels
    env_dir = tmp_path / "env"
    venv.create(env_dir, with_pip=True)                          # fresh: no site packages of this environment
    bin_dir = env_dir / ("Scripts" if os.name == "nt" else "bin")
    _run([bin_dir / "python", "-m", "pip", "install", "-q", wheels[0]], cwd=tmp_path)
    work = tmp_path / "elsewhere"
    work.mkdir()
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    env["BAYES_DISC_CACHE_DIR"] = str(tmp_path / "cache")       # a cold kernel cache, as on a new machine
    where = _run([bin_dir / "python", "-c", "import bayes_disc; print(bayes_disc.__file__)"], cwd=work, env=env)
    assert Path(where.stdout.strip()).is_relative_to(env_dir)   # the installed package, not the checkout
    _run([bin_dir / "bayes-disc", "demo", "demo"], cwd=work, env=env)
    ran = _run([bin_dir / "bayes-disc", "sample", "demo/config.yaml", "--no-progress"], cwd=work, env=env)
    assert "compiling the simulator (once" in ran.stderr          # the cold start is said, not silent
    out = work / "demo" / "out"
    assert (out / "summary.json").is_file() and (out / "posterior.nc").is_file()
    assert (out / "reports" / "demo.html").is_file()
    assert sorted(p.name for p in work.iterdir()) == ["demo"]     # nothing written beside the run folder
    meta = _run([bin_dir / "python", "-c", "from importlib.metadata import metadata; "
                 "print('\\n'.join(metadata('bayes-disc').get_all('Project-URL')))"], cwd=work, env=env)
    assert "Documentation, " in meta.stdout and "Source, " in meta.stdout


def _git(*args, cwd) -> str:
    return _run(["git", *args], cwd=cwd).stdout


@pytest.mark.skipif(not (REPO / ".git").exists(), reason="needs the git checkout of the repository")
def test_plain_commands_on_the_shipped_demo_leave_the_repository_clean(tmp_path):
    """`sample`, `identifiability` and `diagnose` of runs/demo, as the README gives them, in a clone of the
    repository: every file they write is inside the ignored run folder."""
    clone = tmp_path / "clone"
    _run(["git", "clone", "-q", REPO, clone], cwd=tmp_path)
    assert _git("status", "--porcelain", "--untracked-files=all", cwd=clone) == ""
    for command in (["sample", "--no-progress"], ["identifiability"], ["diagnose", "--no-progress"]):
        _run([sys.executable, "-m", "bayes_disc", command[0], "runs/demo/config.yaml", *command[1:]], cwd=clone)
    assert (clone / "runs/demo/out/reports/demo.html").is_file()
    assert (clone / "runs/demo/out/diagnosis.json").is_file()
    assert (clone / "runs/demo/out/identifiability.json").is_file()
    assert _git("status", "--porcelain", "--untracked-files=all", cwd=clone) == ""
