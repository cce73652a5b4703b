"""The Python API (``import bayes_disc as bd``), in-memory flights, docs/api.md, and command-line logging."""
import json
import logging
import re

import arviz as az
import numpy as np
import pandas as pd
import pytest

import bayes_disc as bd
from bayes_disc._logging import cli_logging
from bayes_disc.cli import build_parser, main, verbosity
from bayes_disc.observation.config_io import ConfigError
from bayes_disc.observation.markers import MarkerFileError, load_flights, read_marker_csv
from bayes_disc.observation.tables import flights_from_columns, marker_table_from_columns

from conftest import MARKERS, REPO

DEMO = REPO / "runs/demo"
SMALL = {"sampler": {"ensembles": 2, "max_steps": 45, "adapt_steps": 15, "check_every": 15, "min_steps": 10,
                     "seed": 5},
         "least_squares": {"starts": 1},
         "flight_options": {"bsfl5": {"t_end": 0.5}, "ffsl5": {"t_end": 0.5}}}
TWO = ["bsfl5", "ffsl5"]          # the two shortest demo flights (cut to 0.5 s by SMALL: a fast test)


@pytest.fixture
def demo_rows() -> pd.DataFrame:
    rows = pd.read_csv(DEMO / "flights.csv")
    return rows[rows["flight"].isin(TWO)].reset_index(drop=True)


def test_public_api_is_declared():
    assert set(bd.__all__) >= {"sample", "identifiability", "diagnose", "load", "SampleResult", "__version__"}
    for name in bd.__all__:
        obj = getattr(bd, name)
        if callable(obj):
            doc = obj.__doc__ or ""
            assert "Returns" in doc or isinstance(obj, type), f"{name}: numpydoc Returns section missing"
    assert (REPO / "bayes_disc/py.typed").is_file()


# -- round trip -------------------------------------------------------------------------------------------

def test_sample_from_dataframe_then_load_gives_the_same_summary(tmp_path, monkeypatch, demo_rows, caplog):
    """sample (flights as a DataFrame) → load → identical summary table; one report line; input persisted."""
    monkeypatch.chdir(tmp_path)
    config = {"name": "rt", "flights": [{"data": demo_rows}], "markers": MARKERS, "prior": "potts_crowther", **SMALL}
    with caplog.at_level(logging.INFO, logger="bayes_disc"):
        run = bd.sample(config, output=tmp_path / "out", progress=False, report=True)
    loaded = bd.load(tmp_path / "out")
    pd.testing.assert_frame_equal(run.summary, loaded.summary, check_exact=True)
    names = ["CL0", "CLa", "CD0", "CDa", "CM0", "CMa", "CMq", "CRr", "CRp", "CNr", "sigma_bsfl5", "sigma_ffsl5"]
    assert set(names) <= set(run.summary.index)
    assert list(run.summary.columns) == ["mean", "sd", "q05", "q50", "q95", "r_hat", "ess_bulk"]
    assert 1e-4 < run.summary.loc["sigma_bsfl5", "mean"] < 1e-2          # metres (the demo's noise: mm)
    # idata is the posterior the summary describes
    post = loaded.idata.posterior
    assert post["CLa"].shape[0] * post["CLa"].shape[1] > 100
    assert float(post["CLa"].mean()) == pytest.approx(run.summary.loc["CLa", "mean"],
                                                      abs=0.2 * run.summary.loc["CLa", "sd"])
    # the documented ArviZ view: ensembles as chains, so ArviZ's R-hat is summary.json's
    coefs = names[:10]
    view = az.summary(loaded.ensembles, var_names=coefs, kind="diagnostics", round_to="none")
    np.testing.assert_allclose(view.loc[coefs, "r_hat"], loaded.summary.loc[coefs, "r_hat"], rtol=1e-12)
    assert loaded.ensembles.posterior.sizes["chain"] == run.convergence["ensembles"]
    # the report was built once, and said so once
    html_lines = [r.getMessage() for r in caplog.records if ".html" in r.getMessage()]
    assert len(html_lines) == 1 and "rt.html" in html_lines[0], html_lines
    assert (tmp_path / "out" / "reports" / "rt.html").is_file()       # with the run, as `--output` does
    assert not (tmp_path / "reports").exists()
    # the in-memory flights were persisted and read back as the same observations
    cfg_path = tmp_path / "out/input/config.yaml"
    assert json.loads((tmp_path / "out/summary.json").read_text())["config"] == str(cfg_path)
    mine = flights_from_columns(demo_rows, list(MARKERS), source="df")
    disk = load_flights(tmp_path / "out/input/flights_0.csv", list(MARKERS))
    assert [f.name for f in mine] == [f.name for f in disk] == TWO
    for a, b in zip(mine, disk):
        np.testing.assert_allclose(a.times, b.times, rtol=0, atol=1e-9)
        np.testing.assert_allclose(a.positions, b.positions, rtol=0, atol=1e-9)
        np.testing.assert_array_equal(a.observed, b.observed)


def test_identifiability_from_a_dict_config(tmp_path, demo_rows):
    config = {"name": "idf", "flights": demo_rows, "markers": MARKERS, **SMALL}      # flights: one table
    result = bd.identifiability(config, output=tmp_path / "out", design=False)
    table = result.summary
    assert list(table.index) == ["CL0", "CLa", "CD0", "CDa", "CM0", "CMa", "CMq", "CRr", "CRp", "CNr"]
    assert set(table["verdict"]) <= {"identified", "weak", "unidentified"}
    assert result.verdicts == dict(table["verdict"]) and result.recommendation is None
    again = bd.IdentifiabilityResult.from_dir(tmp_path / "out")
    pd.testing.assert_frame_equal(again.summary, table, check_exact=True)
    with pytest.raises(FileNotFoundError, match="posterior.nc|summary.json"):
        result.report(tmp_path / "r.html")                  # no sampled run in that folder


def test_load_of_a_folder_without_a_run_is_an_error(tmp_path):
    with pytest.raises(FileNotFoundError, match="summary.json"):
        bd.load(tmp_path)


# -- in-memory rows: the checks of a file --------------------------------------------------------------------

def _set(df, row, col, value):
    df = df.copy()
    df[col] = df[col].astype(object) if isinstance(value, str) else df[col]
    df.loc[row, col] = value
    return df


BAD_ROWS = {
    "unknown marker": lambda d: _set(d, 5, "marker", 7),
    "partly NaN": lambda d: _set(d, 5, "x", np.nan),
    "NaN time": lambda d: _set(d, 9, "t", np.nan),
    "millimetres": lambda d: d.assign(x=d.x * 1000, y=d.y * 1000, z=d.z * 1000),
    "time goes back": lambda d: _set(d, 7, "t", -1.0),
    "repeated point": lambda d: _set(_set(d, 3, "t", d.t[0]), 3, "marker", d.marker[0]),
    "two markers": lambda d: d[d.marker != 2].reset_index(drop=True),
    "not a number": lambda d: _set(d, 4, "y", "abc"),
}


@pytest.mark.parametrize("case", sorted(BAD_ROWS))
def test_in_memory_rows_are_rejected_like_file_lines(tmp_path, demo_rows, case):
    bad = BAD_ROWS[case](demo_rows)
    path = tmp_path / "bad.csv"
    bad.to_csv(path, index=False, na_rep="nan")
    with pytest.raises(MarkerFileError) as from_file:
        read_marker_csv(path, list(MARKERS))
    with pytest.raises(MarkerFileError) as from_memory:
        marker_table_from_columns(bad, list(MARKERS), source="flights[0].data")
    same_words = re.sub(r"line \d+", "line N", from_file.value.problem)       # "repeats line N" counts rows
    assert re.sub(r"line \d+", "line N", from_memory.value.problem) == same_words
    assert from_memory.value.line == from_file.value.line - 2          # header line, lines count from 1
    assert str(from_memory.value).startswith("flights[0].data:")


def test_arrays_and_dataframe_give_the_same_flights(demo_rows):
    arrays = {c: demo_rows[c].to_numpy() for c in demo_rows.columns}
    a = flights_from_columns(arrays, list(MARKERS))
    b = flights_from_columns(demo_rows, list(MARKERS))
    assert [f.name for f in a] == TWO
    for fa, fb in zip(a, b):
        np.testing.assert_array_equal(fa.positions, fb.positions)


def test_missing_column_and_wrong_type(demo_rows):
    with pytest.raises(MarkerFileError, match=r"lacks column\(s\) \['z'\]"):
        marker_table_from_columns(demo_rows.drop(columns="z"), list(MARKERS))
    with pytest.raises(TypeError, match="DataFrame"):
        marker_table_from_columns(np.zeros((3, 6)), list(MARKERS))


# -- dict configurations ---------------------------------------------------------------------------------

def test_dict_config_is_validated_and_persisted(tmp_path, demo_rows):
    (tmp_path / "data").mkdir()
    demo_rows[demo_rows.flight == "bsfl5"].to_csv(tmp_path / "data/one.csv", index=False)
    config = {"name": "d", "markers": MARKERS, "output": "o",
              "flights": [{"file": "data/one.csv"}, {"data": demo_rows[demo_rows.flight == "ffsl5"]}]}
    cfg = bd.run_config(config, base_dir=tmp_path)
    assert cfg.path == tmp_path / "o/input/config.yaml" and cfg.path.is_file()
    assert cfg.output == tmp_path / "o"
    assert [f.name for f in cfg.files] == ["one.csv", "flights_1.csv"]
    assert cfg.files[0] == tmp_path / "data/one.csv"
    assert bd.run_config(cfg.path).files == cfg.files                     # the written config stands alone
    with pytest.raises(ConfigError, match=r"<config dict>: key 'walkers': unknown key"):
        bd.run_config({**config, "walkers": 3}, base_dir=tmp_path)
    with pytest.raises(ConfigError, match=r"key 'flights\[1\].file': unknown key"):
        bd.run_config({**config, "flights": [{"file": "data/one.csv"}, {"data": demo_rows, "file": "x"}]},
                      base_dir=tmp_path)
    with pytest.raises(MarkerFileError, match=r"flights\[0\].data:5: unknown marker '7'"):
        bd.run_config({**config, "flights": [{"data": _set(demo_rows, 5, "marker", 7)}]}, base_dir=tmp_path)
    with pytest.raises(TypeError, match="path, a RunConfig or a dict"):
        bd.run_config(42)


# -- docs/api.md runs --------------------------------------------------------------------------------------

def test_docs_example_runs(tmp_path, monkeypatch):
    text = (REPO / "docs/api.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", text, flags=re.S)
    assert len(blocks) >= 3
    (tmp_path / "runs/demo").mkdir(parents=True)
    (tmp_path / "runs/demo/flights.csv").write_text((DEMO / "flights.csv").read_text())
    monkeypatch.chdir(tmp_path)
    namespace = {}
    for block in blocks:
        exec(compile(block, str(REPO / "docs/api.md"), "exec"), namespace)
    assert (tmp_path / "notebook-report.html").is_file()             # the report at the file asked for ...
    assert not (tmp_path / "reports/notebook.html").exists()          # ... and not at the default place
    assert (tmp_path / "runs/notebook/summary.json").is_file()


# -- command-line logging ----------------------------------------------------------------------------------

@pytest.mark.parametrize("level, progress, results", [(1, ["detail", "progress"], ["table"]),
                                                      (0, ["progress"], ["table"]), (-1, [], ["table"]),
                                                      (-2, [], [])])
def test_cli_logging_routes_progress_to_stderr_and_results_to_stdout(capsys, level, progress, results):
    log = logging.getLogger("bayes_disc.some.module")
    root = logging.getLogger("bayes_disc")
    before = list(root.handlers)
    with cli_logging(level):
        log.debug("detail")
        log.info("progress")
        log.info("table", extra={"result": True})
    assert root.handlers == before                      # handlers removed again
    captured = capsys.readouterr()
    assert captured.err.splitlines() == progress
    assert captured.out.splitlines() == results


def test_verbosity_flags_before_and_after_the_subcommand():
    parse = build_parser().parse_args
    assert verbosity(parse(["sample", "c.yaml"])) == 0
    assert verbosity(parse(["-v", "sample", "c.yaml"])) == 1
    assert verbosity(parse(["sample", "c.yaml", "-qq"])) == -2
    assert verbosity(parse(["-q", "identifiability", "c.yaml"])) == -1
    assert verbosity(parse(["-q", "render", "r.yaml"])) == -1            # video's own -q does not clash
    assert parse(["render", "r.yaml", "-q"]).quiet is True


def test_cli_simulate_logs_to_stderr_and_quiet_silences(tmp_path, capsys, reference_dir):
    case = reference_dir / "typical_backhand.json"
    assert main(["simulate", str(case), "-o", str(tmp_path / "a.csv")]) == 0
    cap = capsys.readouterr()
    assert cap.out == "" and re.fullmatch(r"wrote .*a\.csv \(\d+ rows, .*\)\n", cap.err)
    assert main(["-q", "simulate", str(case), "-o", str(tmp_path / "b.csv")]) == 0
    cap = capsys.readouterr()
    assert cap.out == "" and cap.err == ""
    assert main(["simulate", str(tmp_path / "none.json"), "-o", str(tmp_path / "c.csv"), "-q"]) == 2
    assert len(capsys.readouterr().err.strip().splitlines()) == 1          # errors stay one line
