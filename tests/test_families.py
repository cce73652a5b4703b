"""Term families and forms of nature: effects whose form in nature differs from every formula of
the library.

Fast: each family's shape parameters at their off values give the original formula exactly; each form of
nature changes the flight and differs from its family's formula. Slow: data made with a form of nature
(concealed from the run) are diagnosed with the four families a form could belong to; the top-ranked
family is the form's own, and after the refit the residual RMS is within 15 % of the noise.
"""
import json

import numpy as np
import pytest

from bayes_disc.observation.config_io import ConfigError
from bayes_disc.observation.synth import LaunchSpec, SynthSpec, synthesize
from bayes_disc.observation.synth_config import synth_spec_from_mapping
from bayes_disc.physics import TERMS, get_terms, literature_coefficients, simulate
from bayes_disc.physics.nature import FAMILY, NATURE, get_nature
from bayes_disc.physics.windtunnel import wind_tunnel_shape

from test_missing_physics import NOISE_MM, diagnose, make_run, pooled_ratio

#: the original formulas (before the families): one parameter set per term, shape parameters absent
ORIGINAL = {"side_force": {"CY": 0.05}, "wind": {"wind_x": 2.0, "wind_y": -1.0, "wind_z": 0.2},
            "ground_effect": {"CL_ge": 0.4, "CD_ge": 0.1}, "nonlinear_aero": {"CL2": -1.0, "CD3": 1.0, "CM2": -0.1},
            "spin_lift": {"CLr": 0.2}, "roll_spin_coupling": {"CRmu": 0.01}}


def _flight(z0=0.6):
    return LaunchSpec(name="f", speed=13.0, launch_angle_deg=3, alpha_deg=8, spin=-60, duration=1.0, noise_mm=0.0,
                      position=(0.0, 0.0, z0))


def _positions(**kw):
    return synthesize(SynthSpec(name="s", flights=(_flight(),), **kw)).flights[0].positions


def _term_flight(term_id, values):
    """States (n, 13) of one flight with the term at ``values`` (other parameters at their off values)."""
    (term,) = get_terms([term_id])
    ext = np.array([values.get(p.name, p.off_value) for p in term.parameters])
    y0 = _flight().initial_state()
    coef = literature_coefficients("hummel2002").as_array()
    return simulate(y0, coef, np.arange(121) / 120.0, terms=(term,), extension=ext).states[0]


@pytest.mark.parametrize("term_id", sorted(ORIGINAL))
def test_family_at_off_shape_is_the_original_formula(term_id):
    """Shape parameters at their off values reproduce the formula of the term in docs/conventions.md; moving one
    changes the flight."""
    term = TERMS[term_id]
    shape = [p for p in term.parameters if p.name not in ORIGINAL[term_id]]
    assert shape, f"{term_id} has no shape parameter"
    base = _term_flight(term_id, ORIGINAL[term_id])
    explicit = _term_flight(term_id, {**ORIGINAL[term_id], **{p.name: p.off_value for p in shape}})
    assert np.array_equal(base, explicit)
    for p in shape:
        moved = _term_flight(term_id, {**ORIGINAL[term_id], p.name: p.off_value + 0.5})
        assert np.max(np.abs(moved - base)) > 1e-4, p.name


def test_original_formulas_hold_as_written():
    """Ground effect at ln_h = 0 decays over one diameter; the side force is linear in the advance ratio."""
    from bayes_disc.physics.terms import CTX_AREA, CTX_DIAM, CTX_Q, CTX_R, CTX_SIZE, CTX_SPEED, CTX_Z
    ctx = np.zeros(CTX_SIZE)
    ctx[[CTX_Z, CTX_SPEED, CTX_Q, CTX_AREA, CTX_DIAM, CTX_R]] = [0.269, 10.0, 61.5, 0.057, 0.269, 40.0]
    ctx[16] = 1.0                                      # d3 = z
    ctx[7] = 10.0                                      # v_a along x
    ctx[13:16] = [0.0, 1.0, 0.0]                       # d2 = y
    E = np.array([0.4, 0.0, 0.0])
    fx, fy, fz, *_ = TERMS["ground_effect"].loads(E, 0, ctx)
    assert np.isclose(np.hypot(fx, fz), 0.4 * np.exp(-1.0) * 61.5 * 0.057)
    E = np.array([0.05, 1.0])
    _, fy, *_ = TERMS["side_force"].loads(E, 0, ctx)
    mu = 40.0 * 0.269 / 20.0
    assert np.isclose(fy, 0.05 * mu * 61.5 * 0.057)
    E = np.array([0.05, 0.5])
    _, fy_half, *_ = TERMS["side_force"].loads(E, 0, ctx)
    assert np.isclose(fy_half, 0.05 * np.sqrt(mu) * 61.5 * 0.057)


def test_nonlinear_prior_means_are_the_wind_tunnel_shape():
    shape = wind_tunnel_shape()
    for p in TERMS["nonlinear_aero"].parameters:
        assert p.prior_centre == getattr(shape, p.name)
        assert p.prior_sd >= 2 * abs(p.prior_centre)
        assert p.off_value == 0.0
    # the bend is what the base model's forms cannot follow: zero mean, and a fit of the bend by those forms is 0
    a = shape.alpha_rad
    for bend, cols in ((shape.bend_CL, [np.ones_like(a), a]), (shape.bend_CD, [np.ones_like(a), a ** 2])):
        coef = np.linalg.lstsq(np.column_stack(cols), bend, rcond=None)[0]
        assert np.allclose(coef, 0.0, atol=1e-12)


@pytest.mark.parametrize("form", sorted(NATURE))
def test_each_form_of_nature_changes_the_flight(form):
    values = {"ground_effect_power": {"CL_gp": 0.8, "CD_gp": 0.2}, "wind_tunnel_aero": {},
              "wind_power_shear": {"wref_x": -3.0, "wref_y": 2.0}, "side_force_saturating": {"CY_s": 0.05}}[form]
    base = _positions()
    moved = _positions(nature={form: values})
    assert np.nanmax(np.abs(moved - base)) > 2e-3
    assert FAMILY[form] in TERMS


def test_power_shear_wind_at_release_sets_the_angle_of_attack():
    spec = SynthSpec(name="s", flights=(_flight(),), nature={"wind_power_shear": {"wref_x": -3.0, "wref_y": 0.0,
                                                                                     "z_ref": 1.0}})
    w = spec.wind_at((0.0, 0.0, 0.6))
    assert np.allclose(w, [-3.0 * 0.6 ** (1 / 7), 0.0, 0.0])
    assert SynthSpec(name="s", flights=(_flight(),)).wind_at((0, 0, 1)) is None


def test_nature_block_is_read_and_recorded(tmp_path):
    data = {"name": "n", "flights": [{"speed": 12.0, "duration": 0.3}],
            "nature": {"ground_effect_power": {"CL_gp": 0.5}}}
    spec, _, _ = synth_spec_from_mapping(data, tmp_path / "s.yaml")
    assert spec.nature == {"ground_effect_power": {"CL_gp": 0.5, "CD_gp": 0.0, "h_gp": 0.3, "p_gp": 2.0}}
    assert [t.id for t in spec.terms] == ["ground_effect_power"]
    with pytest.raises(ConfigError, match="nature.ground_effect_cubic"):
        synth_spec_from_mapping({**data, "nature": {"ground_effect_cubic": {}}}, tmp_path / "s.yaml")
    with pytest.raises(ConfigError, match="nature.ground_effect_power"):
        synth_spec_from_mapping({**data, "nature": {"ground_effect_power": {"CL": 1.0}}}, tmp_path / "s.yaml")
    with pytest.raises(KeyError, match="known"):
        get_nature(["magnus"])


# -- concealed forms of nature (slow) -------------------------------------------------------------------------

#: the families a form could be taken for: every physics term that acts on the translation
TRIED = ["side_force", "wind", "ground_effect", "nonlinear_aero"]
#: forms of nature at magnitudes where the base fit is 1.5–4× the noise
FORMS = {
    "ground_effect_power": {"CL_gp": 1.0, "CD_gp": 0.3, "h_gp": 0.4, "p_gp": 2.0},
    "wind_tunnel_aero": {"s_tunnel": 2.0},        # the table's bend doubled: at 1.0 the base fit is 1.33× the noise
    "wind_power_shear": {"wref_x": 2.5, "wref_y": 1.5, "z_ref": 1.0},
    "side_force_saturating": {"CY_s": 0.03, "mu0": 0.2},
}


@pytest.mark.slow
@pytest.mark.parametrize("form", sorted(FORMS))
def test_concealed_nature_form_ranks_its_family_first_and_refit_reaches_the_noise(tmp_path, form):
    cfg = make_run(tmp_path, {}, seed=3, nature={form: FORMS[form]})
    truth = json.loads((tmp_path / "truth.json").read_text())
    assert truth["nature"] == {form: FORMS[form]}
    result = diagnose(cfg, candidates=TRIED, learn=False)        # the learned correction: test_discrepancy
    ratio = pooled_ratio(result["rms_before_mm"])
    assert 1.5 < ratio < 4.0, f"calibration drifted: base fit {ratio:.2f}× noise"
    assert result["candidates"][0]["id"] == FAMILY[form], result["words"]
    assert result["effects"][0]["id"] == FAMILY[form], result["words"]
    assert all(abs(v / NOISE_MM - 1) < 0.15 for v in result["rms_after_mm"].values()), result["rms_after_mm"]
