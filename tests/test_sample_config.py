"""Bad run configurations fail up front with one clear message naming the key or file (exit 2)."""
import shutil

import pytest

from bayes_disc.cli import main
from bayes_disc.inference.model.config import load_config
from bayes_disc.observation.config_io import ConfigError

from conftest import REPO

DEMO = REPO / "runs/demo"


@pytest.fixture
def demo_copy(tmp_path):
    for f in ("config.yaml", "flights.csv", "truth.json"):
        shutil.copy(DEMO / f, tmp_path / f)
    return tmp_path


def _edit(path, old, new):
    text = path.read_text()
    assert old in text
    path.write_text(text.replace(old, new, 1))


CASES = {
    "unknown key": (("prior: potts_crowther", "prior: potts_crowther\nwalkerz: 10"), "key 'walkerz': unknown key"),
    "unknown nested key": (("prior: potts_crowther", "prior: potts_crowther\nsampler: {stepz: 3}"),
                           "key 'sampler.stepz': unknown key"),
    "missing data file": (("file: flights.csv", "file: nope.csv"), "key 'flights[0].file': file not found"),
    "bad number": (("prior: potts_crowther", "prior: potts_crowther\nsampler: {ensembles: two}"),
                   "key 'sampler.ensembles': must be a number"),
    "negative mass": (("prior: potts_crowther", "prior: potts_crowther\ndisc: {mass: -1}"),
                      "key 'disc.mass': must be positive"),
    "unknown prior": (("prior: potts_crowther", "prior: flat"), "key 'prior': must be one of"),
    "missing markers": (('  "0": [0.100, 0.000, -0.015]\n  "1": [-0.0308, 0.0846, -0.015]\n'
                         '  "2": [-0.0707, -0.0778, -0.015]', '  "0": [0.100, 0.000, -0.015]'),
                        "key 'markers'"),
    "unknown physics term": (("prior: potts_crowther", "prior: potts_crowther\nphysics: {magic: {}}"),
                             "key 'physics.magic'"),
    "prior around an unknown set": (("prior: potts_crowther", "prior: {around: hummel2003}"),
                                    "key 'prior.around': unknown coefficient set"),
    "prior around without a width": (("prior: potts_crowther", "prior: {around: hummel2002, relative_sd: 0}"),
                                     "key 'prior.relative_sd': must be positive"),
    "prior around a zero value": (("prior: potts_crowther",
                                   "prior: {around: {CL0: 0.2, CLa: 2.9, CD0: 0.08, CDa: 2.6, CM0: 0.0, CMa: 0.1, "
                                   "CMq: -0.01, CRr: 0.01, CRp: -0.01, CNr: -1.0e-5}}"),
                                  "sd of CM0 is not positive"),
    "prior unknown sub-key": (("prior: potts_crowther", "prior: {around: hummel2002, width: 1}"),
                              "key 'prior.width': unknown key"),
}


def test_prior_around_a_published_set(demo_copy):
    """``prior: {around: ...}``: Gaussians at the set's values with sd relative_sd·|value| unless given."""
    from bayes_disc.inference.model.data import build_problem
    from bayes_disc.inference.model.priors import coefficient_prior
    from bayes_disc.physics import COEFFICIENT_NAMES, literature_coefficients
    cfg = demo_copy / "config.yaml"
    _edit(cfg, "prior: potts_crowther", "prior: {around: hummel2002, relative_sd: 0.2, sd: {CNr: 3.0e-6}}")
    c = load_config(cfg)
    cp = coefficient_prior(c.prior)
    hh = literature_coefficients("hummel2002").as_dict()
    assert cp.name == "around" and cp.mean == pytest.approx(hh)
    assert cp.sd["CLa"] == pytest.approx(0.2 * abs(hh["CLa"])) and cp.sd["CNr"] == 3.0e-6
    p = build_problem(c)
    i = list(COEFFICIENT_NAMES)
    assert p.prior_mean[: len(i)] == pytest.approx([hh[n] for n in i])
    assert p.prior_sd[: len(i)] == pytest.approx([cp.sd[n] for n in i])


@pytest.mark.parametrize("kind", sorted(CASES))
def test_bad_config_names_the_key(demo_copy, kind, capsys):
    (old, new), words = CASES[kind]
    cfg = demo_copy / "config.yaml"
    _edit(cfg, old, new)
    with pytest.raises(ConfigError) as e:
        load_config(cfg)
    assert words in str(e.value), str(e.value)
    assert main(["sample", str(cfg), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and words in err[0]
    assert not (demo_copy / "out").exists()


def test_marker_id_not_in_config_is_rejected_with_file_and_line(demo_copy, capsys):
    _edit(demo_copy / "config.yaml", '  "2": [-0.0707, -0.0778, -0.015]', '  "7": [-0.0707, -0.0778, -0.015]')
    assert main(["sample", str(demo_copy / "config.yaml"), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip()
    assert "flights.csv:4: unknown marker '2'" in err, err


def test_flight_option_for_unknown_flight(demo_copy, capsys):
    _edit(demo_copy / "config.yaml", "prior: potts_crowther", "prior: potts_crowther\nflight_options: {zz: {t_end: 0.5}}")
    assert main(["sample", str(demo_copy / "config.yaml"), "--no-progress"]) == 2
    assert "flight_options.zz" in capsys.readouterr().err


def test_missing_config_file(tmp_path, capsys):
    assert main(["sample", str(tmp_path / "none.yaml")]) == 2
    assert "file not found" in capsys.readouterr().err
