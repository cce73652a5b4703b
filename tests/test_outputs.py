"""Where the commands write: the run folder only, never over earlier results unless asked; the shipped demo."""
import hashlib

import pytest

from bayes_disc.cli import main
from bayes_disc.inference.model.config import load_config
from bayes_disc.jobs.outputs import JOB_FILES, check_fresh_output, existing_results, reports_dir
from bayes_disc.observation.config_io import ConfigError
from bayes_disc.observation.demo import DEMO_FILES, demo_file, write_demo

from conftest import REPO


def _digest(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def test_the_packaged_demo_is_the_repository_demo():
    """`bayes-disc demo` ships exactly runs/demo (config, flights, launch description, truth)."""
    for name in DEMO_FILES:
        assert _digest(demo_file(name)) == _digest((REPO / "runs/demo" / name).read_bytes()), name


def test_demo_command_writes_a_runnable_folder_and_refuses_to_overwrite(tmp_path, capsys):
    folder = tmp_path / "d"
    assert main(["demo", str(folder)]) == 0
    assert sorted(p.name for p in folder.iterdir()) == sorted(DEMO_FILES)
    cfg = load_config(folder / "config.yaml")                  # a valid run configuration there
    assert cfg.output == folder / "out" and len(cfg.files) == 1
    (folder / "flights.csv").write_text("edited")
    capsys.readouterr()
    assert main(["demo", str(folder)]) == 2                    # nothing is lost without --overwrite
    err = capsys.readouterr().err
    assert "already holds" in err and "--overwrite" in err and err.count("\n") == 1
    assert (folder / "flights.csv").read_text() == "edited"
    assert main(["demo", str(folder), "--overwrite"]) == 0
    assert (folder / "flights.csv").read_bytes() == demo_file("flights.csv")


def test_demo_into_a_file_is_refused(tmp_path):
    (tmp_path / "f").write_text("x")
    with pytest.raises(ConfigError, match="is a file"):
        write_demo(tmp_path / "f")


@pytest.mark.parametrize("job", sorted(JOB_FILES))
def test_a_folder_with_earlier_results_is_refused_unless_asked(tmp_path, job):
    write_demo(tmp_path)
    cfg = load_config(tmp_path / "config.yaml")
    check_fresh_output(cfg, job)                              # a new folder: fine
    cfg.output.mkdir()
    (cfg.output / JOB_FILES[job][0]).write_text("{}")
    assert existing_results(cfg.output, job) == [JOB_FILES[job][0]]
    with pytest.raises(ConfigError, match=f"earlier `{job}`.*--overwrite") as err:
        check_fresh_output(cfg, job)
    assert ("--resume" in str(err.value)) == (job == "sample")
    check_fresh_output(cfg, job, overwrite=True)
    if job == "sample":
        check_fresh_output(cfg, job, resume=True)


def test_the_command_line_refuses_a_folder_with_an_earlier_run(tmp_path, capsys):
    write_demo(tmp_path)
    (tmp_path / "out").mkdir()
    (tmp_path / "out/summary.json").write_text("{}")
    assert main(["sample", str(tmp_path / "config.yaml"), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "earlier `sample`" in err and "--resume" in err and "--overwrite" in err
    assert (tmp_path / "out/summary.json").read_text() == "{}"


def test_reports_go_inside_the_run_folder(tmp_path):
    assert reports_dir(tmp_path / "out") == tmp_path / "out" / "reports"
