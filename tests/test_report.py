"""`bayes-disc report`: a self-contained HTML report that parses, whose images decode and render in a real
browser, with every section present and every figure written as PNG and PDF."""
import base64
import io
import json
import re
import shutil
import subprocess
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from bayes_disc.cli import main
from bayes_disc.report import DEFAULT_SECTION_IDS, ReportInputError, Section, build_report, default_builders
from bayes_disc.report.context import ReportContext, load_run
from bayes_disc.report.html import render_document
from bayes_disc.report.run import build_sections
from bayes_disc.report.sections import fmt_estimate
from bayes_disc.physics.windtunnel import load_wind_tunnel

from conftest import require_outside_input, run_config, write_short_flight

pytestmark = pytest.mark.xdist_group("report_run")   # one worker builds the module's shared run

CHROMIUM = "/usr/bin/chromium"
FIGURES = ("corner", "trace", "ranks", "residuals", "angle_of_attack", "trajectories", "posterior_predictive",
           "force_curves", "posterior_correlation")
CONFIG = run_config("tiny", "prior: potts_crowther", "output: out", "truth: truth.json",
                    "sampler: {ensembles: 2, max_steps: 60, adapt_steps: 20, check_every: 15, min_steps: 10, seed: 5}",
                    "least_squares: {starts: 1}")


class _Doc(HTMLParser):
    """Collects tags, ids, image sources, external references and open/close balance."""

    def __init__(self):
        super().__init__()
        self.ids, self.imgs, self.external, self.stack, self.errors = [], [], [], [], []
        self.section_ids, self.guides = [], 0

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if "id" in a:
            self.ids.append(a["id"])
        if tag == "section":
            self.section_ids.append(a.get("id"))
        if tag == "p" and "guide" in (a.get("class") or ""):
            self.guides += 1
        if tag == "img":
            self.imgs.append(a.get("src", ""))
        for k in ("src", "href"):
            v = a.get(k)
            if v and not (v.startswith("#") or v.startswith("data:")):
                self.external.append((tag, k, v))
        if tag == "link" or (tag == "script" and "src" in a):
            self.external.append((tag, "", str(a)))
        if tag not in ("meta", "img", "br", "link", "input", "hr"):
            self.stack.append(tag)

    def handle_endtag(self, tag):
        if not self.stack or self.stack[-1] != tag:
            self.errors.append(f"unbalanced </{tag}> (open: {self.stack[-3:]})")
            if tag in self.stack:
                while self.stack and self.stack.pop() != tag:
                    pass
        else:
            self.stack.pop()


def _parse(text: str) -> _Doc:
    d = _Doc()
    d.feed(text)
    d.close()
    return d


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    """A one-flight synthetic run (a few seconds of sampling) and its report."""
    d = tmp_path_factory.mktemp("tiny")
    write_short_flight(d)
    (d / "config.yaml").write_text(CONFIG)
    with pytest.MonkeyPatch.context() as mp:
        mp.chdir(d)  # nothing may land in the working directory: the report goes with the run
        assert main(["sample", str(d / "config.yaml"), "--no-progress"]) == 0
    run_dir = d / "out"
    # the sample job drew its report's sections in two worker processes (the config's default processes: 2)
    pooled = (d / "out" / "reports" / "tiny.html").read_text(encoding="utf-8")
    pooled_png = {p.name: p.read_bytes() for p in sorted((run_dir / "figures").glob("*.png"))}
    html_path = build_report(run_dir, reports_dir=d / "reports", processes=1, seed=5)  # the sampler's seed, as `sample`
    return {"dir": d, "run": run_dir, "html": html_path, "text": html_path.read_text(encoding="utf-8"),
            "pooled": pooled, "pooled_png": pooled_png}


def test_report_written_where_expected(tiny):
    """(How long a report takes is a benchmark's question, not a unit test's.)"""
    assert tiny["html"] == tiny["dir"] / "reports" / "tiny.html"


#: sections of a marker run without diagnosis.json (the missing-physics section is left out, not a
#: placeholder; the inertial section only appears with inertial data, the flagged one with robust noise)
TINY_SECTIONS = [i for i in DEFAULT_SECTION_IDS if i not in ("missing-physics", "inertial", "flagged")]


def test_html_parses_with_every_section_and_guide(tiny):
    doc = _parse(tiny["text"])
    assert not doc.errors, doc.errors[:5]
    assert doc.stack == [], doc.stack
    assert doc.section_ids == TINY_SECTIONS
    assert doc.guides == len(TINY_SECTIONS) - 1     # every section but the first screen has a reading guide
    assert len(set(doc.ids)) == len(doc.ids), "duplicate element ids"


def test_every_embedded_image_decodes(tiny):
    doc = _parse(tiny["text"])
    assert len(doc.imgs) == len(FIGURES)
    for src in doc.imgs:
        prefix = "data:image/png;base64,"
        assert src.startswith(prefix), src[:40]
        im = Image.open(io.BytesIO(base64.b64decode(src[len(prefix):], validate=True)))
        im.load()
        assert im.format == "PNG" and min(im.size) > 200, im.size
        px = np.asarray(im.convert("L"), float)
        assert px.std() > 5.0, "blank image"


def test_self_contained(tiny):
    doc = _parse(tiny["text"])
    assert doc.external == []
    assert "http://" not in tiny["text"].split("<body")[0] and "https://" not in tiny["text"].split("<body")[0]


def test_figures_as_png_and_pdf(tiny):
    fig_dir = tiny["run"] / "figures"
    for name in FIGURES:
        png, pdf = fig_dir / f"{name}.png", fig_dir / f"{name}.pdf"
        assert png.is_file() and pdf.is_file(), name
        Image.open(png).verify()
        assert pdf.read_bytes()[:5] == b"%PDF-", name
        assert pdf.stat().st_size > 5000, name


def _section(text: str, sid: str) -> str:
    start = text.index(f'<section id="{sid}">')
    return text[start: text.index("</section>", start)]


def test_content_of_key_sections(tiny):
    text = tiny["text"]
    summary = json.loads((tiny["run"] / "summary.json").read_text())
    coef = _section(text, "coefficients")
    for name in ["CL0", "CLa", "CD0", "CDa", "CM0", "CMa", "CMq", "CRr", "CRp", "CNr"]:
        assert f"<td>{name}</td>" in coef, name
    # literature (P&C 2000 and the paper's Table 2), truth column and the posterior median are shown
    assert "Potts &amp; Crowther 2000" in coef and "Hummel &amp; Hubbard 2002 (Table 2)" in coef
    assert "<td>2.96 <span" in coef and "<td>2.37 <span" in coef and "<th>truth</th>" in coef
    q = summary["parameters"]["CLa"]
    median, _ = fmt_estimate(q["q50"], q["q05"], q["q95"])
    assert f"<td>CLa</td><td>2.96 ± 1.5</td><td>{median}</td>" in coef
    assert abs(float(median) - q["q50"]) <= 0.5 * (q["q95"] - q["q05"]) / 10   # shown to 1/10 of the interval
    assert "σ [mm]" in coef and "ωz [rad/s]" in coef
    # a literature value far outside the interval is marked in neutral words (CD0: P&C 0.08, truth 0.15)
    assert '0.08 <span class="cmp cmp-out"' in coef and "✗" not in text
    assert "contours at 50 % and 90 % probability" in _section(text, "corner")
    assert "R-hat" in _section(text, "convergence")
    run = _section(text, "appendix")
    assert "flights.csv" in run and "potts_crowther" in run and "emcee" in run and "wall time" in run
    # the walkers actually used, not the configured 0 ("automatic")
    conv = summary["convergence"]
    assert f"<td>walkers</td><td>{conv['walkers_per_ensemble']} per ensemble" in run
    assert f"{conv['walkers_per_ensemble']} walkers × {conv['ensembles']} ensembles" in run
    assert "RMS" in _section(text, "residuals")
    assert "Potts (2005)" in _section(text, "force-curves")


class _Text(HTMLParser):
    """The text a reader sees: character data outside <script> and <style>."""

    def __init__(self):
        super().__init__()
        self.parts, self._skip = [], 0

    def handle_starttag(self, tag, attrs):
        self._skip += tag in ("script", "style")

    def handle_endtag(self, tag):
        self._skip -= tag in ("script", "style")

    def handle_data(self, data):
        if not self._skip:
            self.parts.append(data)


def _reader_text(html: str) -> str:
    t = _Text()
    t.feed(html)
    return " ".join(t.parts)


def test_first_screen_leads_with_the_answer(tiny):
    """The first section holds what was estimated, the three verdict lines and the coefficient table with
    every coefficient's median and 90 % interval; the run tables come last."""
    text = tiny["text"]
    summary = json.loads((tiny["run"] / "summary.json").read_text())
    doc = _parse(text)
    assert doc.section_ids[0] == "answer" and doc.section_ids[-1] == "appendix"
    first = _section(text, "answer")
    body_start = text.index("<body")
    # nothing but the header comes before it
    assert text.index('<section id="answer">') < text.index("<section", text.index('<section id="answer">') + 1)
    assert text.index('<section id="answer">') == text.index("<section", body_start)
    lines = [m for m in first.split('<li class="verdict-line')[1:]]
    topics = [ln.split("<b>")[1].split("</b>")[0] for ln in lines]
    assert topics == ["Convergence:", "Identifiability:", "Model adequacy:"]
    # the verdicts come before the table, the table before the end of the section
    assert first.index("verdict-line") < first.index('<table class="num answer">')
    assert "converged after" in lines[0] or "NOT converged" in lines[0]
    assert f"R-hat max {summary['convergence']['r_hat_max']:.4g}" in lines[0]
    # identifiability and diagnosis not run for this run: the line offers the command instead
    assert "not run" in lines[1] and f"<code>bayes-disc identifiability {tiny['dir'] / 'config.yaml'}</code>" in lines[1]
    assert "not run" in lines[2] and "<code>bayes-disc diagnose " in lines[2]
    assert "% of measured coordinates inside their 90 % interval" in lines[2]
    n_points = sum(f["points"] for f in summary["flights"].values())
    assert f"<b>{n_points} marker points</b>" in first and "<b>1 flight</b>" in first
    # each flight's marker noise and why (noise: auto), below the coefficient table
    from bayes_disc.report.answer import NOISE_WORDS
    noise = first[first.index('<table class="noise-choice">'):]
    assert first.index('<table class="num answer">') < first.index('<table class="noise-choice">')
    for flight, r in summary["noise_choice"].items():
        assert f"<tr><td>{flight}</td><td>{NOISE_WORDS[r['label']]}" in noise, (r, noise)
    table = first[first.index('<table class="num answer">'):]
    import re
    for name in summary["coefficients"]:
        q = summary["parameters"][name]
        m = re.search(rf"<td>{name}</td><td>([^<]+)</td><td>([^<]+) … ([^<]+)</td>", table)
        assert m, name
        for text_value, true in zip(m.groups(), (q["q50"], q["q05"], q["q95"])):
            # rounded to the decimals shown (or 4 significant digits): never more than half a last digit off
            last = (10.0 ** -len(text_value.split(".")[1]) if "." in text_value and "e" not in text_value
                    else abs(true) * 1e-3)
            assert abs(float(text_value) - true) <= 0.5 * last + 1e-15, (name, text_value, true)
        assert q["q05"] < q["q95"]
    assert "Potts &amp; Crowther 2000" in table and "truth" in table
    # beside the credible interval, the profile interval of summary.json, and which of the two to quote
    from bayes_disc.inference.fitting.profile_interval import profile_interval
    paths = json.loads((tiny["run"] / "profiles.json").read_text())
    for name in summary["coefficients"]:
        pi = summary["profile_intervals"][name]
        assert pi == profile_interval(paths[name])
        assert pi["q05"] < pi["q25"] < pi["q50"] < pi["q75"] < pi["q95"]
        m = re.search(rf"<td>{name}</td><td>[^<]+</td><td>[^<]+</td><td>([^<]+) … ([^<]+)</td>", table)
        assert m, name
        for text_value, true in zip(m.groups(), (pi["q05"], pi["q95"])):
            last = (10.0 ** -len(text_value.split(".")[1]) if "." in text_value and "e" not in text_value
                    else abs(true) * 1e-3)
            assert abs(float(text_value) - true) <= 0.5 * last + 1e-15, (name, text_value, true)
    assert "profile 90 % interval" in table and "Which interval to quote" in first
    # each published set tested as a whole: its values, W on as many degrees of freedom, inside or outside
    from scipy.stats import chi2
    from bayes_disc.physics.constants import LITERATURE
    tests = summary["literature_tests"]
    assert set(tests) == set(LITERATURE)
    for key, t in tests.items():
        assert t["values"] == LITERATURE[key].values and t["dof"] == len(LITERATURE[key].values)
        assert t["inside_90"] == (t["deviance"] <= chi2.ppf(0.9, t["dof"]))
        where = "inside" if t["inside_90"] else "outside"
        assert f"its {t['dof']} values together: W = {t['deviance']:.4g}" in first
        assert f"{t['deviance']:.4g}, {where} the data's joint 90 % region" in first
    # run and software tables are no longer on the first screen
    assert "sampler setting" not in first and "Software" not in first


def test_reader_text_has_no_spec_references_placeholders_or_round_off(tiny):
    text = tiny["text"]
    words = _reader_text(text)
    assert "SPEC" not in words
    assert "placeholder" not in text and "Not computed" not in words and "not computed" not in words
    assert '<section id="missing-physics">' not in text      # not run: left out
    # round-off never reaches the reader (e.g. a true angular velocity of -1.07e-14 rad/s is 0)
    import re
    assert not re.search(r"\de-(1[3-9]|[2-9]\d)\b", words), re.findall(r"\S*\de-(?:1[3-9]|[2-9]\d)\S*", words)[:5]
    # contraction is shown as posterior sd / prior sd in per cent, never as a bare "1"
    ident = _section(text, "identifiability")
    assert "posterior sd / prior sd" in ident and "contraction" not in ident
    assert re.findall(r"<td>\d[\d.]* %</td>", ident), "no percentages in the identifiability table"


def test_verdict_lines_from_their_files():
    from bayes_disc.report.answer import adequacy_verdict, convergence_verdict, identifiability_verdict
    conv = {"converged": False, "reason": "cap", "r_hat_max": 1.05, "ess_bulk_min_coefficient": 120.4,
            "total_steps": 3000, "kept_steps": 1000, "walkers_per_ensemble": 118, "ensembles": 4}
    v = convergence_verdict(conv, {"rhat": 1.01, "ess": 400, "max_steps": 3000})
    assert v.status == "attention" and "step cap of 3000 reached" in v.text and "R-hat max 1.05" in v.text
    assert "ESS 120 (needed 400)" in v.text and "472000 samples" in v.text
    v = convergence_verdict(conv | {"converged": True, "total_steps": 750}, {})
    assert v.status == "ok" and v.text.startswith("converged after 750 steps")
    # moves whose proposals do not fit the posterior are named when the run did not converge
    moves = {"independence jump": {"share": 0.28, "proposals": 100000, "acceptance": 0.0004},
             "ridge carry": {"share": 0.28, "proposals": 100000, "acceptance": 0.2},
             "DE snooker": {"share": 0.02, "proposals": 8000, "acceptance": 0.001}}
    v = convergence_verdict(conv | {"moves": moves}, {"max_steps": 3000})
    assert "(independence jump accepted less than 1% of the time" in v.text and "snooker" not in v.text
    v = convergence_verdict(conv | {"moves": moves, "converged": True}, {})
    assert "accepted less than" not in v.text
    from bayes_disc.report.content import _moves_table
    html = _moves_table({"moves": moves})
    assert "<td>independence jump</td><td>0.28</td><td>100000</td><td>0.0 %</td>" in html
    assert "<b>independence jump</b> accepted less than 1%" in html and "draws' mean" not in html
    html = _moves_table({"moves": moves, "log_prob_gap_at_mean": 30.38, "dimension": 78})
    assert ("lies 30.4 nats below that of the median draw (for a Gaussian posterior of 78 parameters it lies "
            "about 39 above): the posterior is curved.") in html
    assert _moves_table({}) == ""
    assert "accepted less than" not in _moves_table({"moves": {"DE snooker": moves["DE snooker"]}})
    coefs = ["CL0", "CLa", "CD0"]
    data = {"coefficients": {"CL0": {"verdict": "identified"}, "CLa": {"verdict": "weak"},
                             "CD0": {"verdict": "unidentified"}}}
    v = identifiability_verdict(data, coefs, "c.yaml")
    assert v.status == "attention" and v.text.startswith("1 of 3 coefficients identified; weak: CLa; unidentified: CD0")
    v = identifiability_verdict({"CL0": {"verdict": "identified", "reason": "r"}}, ["CL0"], "c.yaml")
    assert v.status == "ok" and v.text.startswith("1 of 1 coefficients identified")
    assert "throw that would pin them down" not in v.text        # no design ranked: no throw promised
    v = identifiability_verdict(data | {"design": {"ranking": [{"speed": 12.0}]}}, coefs, "c.yaml")
    assert "reasons and the throw that would pin them down below" in v.text
    from bayes_disc.report.answer import qualified_by_adequacy
    ok = identifiability_verdict({"CL0": {"verdict": "identified", "reason": "r"}}, ["CL0"], "c.yaml")
    q = qualified_by_adequacy(ok, {"verdict": "missing_physics", "unexplained": [{"flight": "a"}]})
    assert q.status == "attention" and "not a finding" in q.text and q.text.startswith(ok.text)
    assert qualified_by_adequacy(ok, {"verdict": "adequate", "unexplained": []}) == ok
    assert qualified_by_adequacy(ok, None) == ok
    v = identifiability_verdict(None, coefs, "runs/x/config.yaml")
    assert v.status == "not run" and v.command == "bayes-disc identifiability runs/x/config.yaml"
    v = adequacy_verdict({"verdict": "adequate"}, "c.yaml")
    assert v.status == "ok" and v.text.startswith("adequate")
    v = adequacy_verdict({"verdict": "missing_physics", "effects": [{"id": "side_force", "evidence": 4539.8}],
                          "settings": {"refit_run": "out/diagnosis_refit"}}, "c.yaml")
    assert v.status == "attention" and "side_force (ΔBIC 4540)" in v.text and "out/diagnosis_refit" in v.text
    v = adequacy_verdict(None, "c.yaml", coverage=0.894)
    assert v.status == "not run" and "89 %" in v.text and v.command == "bayes-disc diagnose c.yaml"
    nut = {"verdict": "missing_physics", "effects": [], "unexplained": [{"flight": "t1"}]}
    v = adequacy_verdict({**nut, "random_nutation": {"found": True, "evidence": 851.4}}, "c.yaml")
    assert v.status == "attention" and "randomly forced nutation (ΔBIC 851)" in v.text and "gyro_noise: nutation" in v.text
    assert "nutation" not in adequacy_verdict({**nut, "random_nutation": {"found": False, "evidence": 3.0}}, "c.yaml").text


def test_number_formats():
    from bayes_disc.report.answer import compare
    from bayes_disc.report.sections import fmt_count, fmt_percent, fmt_scaled, ordinal
    assert fmt_estimate(0.1892, 0.1864, 0.192) == ("0.1892", "0.1864 … 0.1920")
    assert fmt_estimate(-0.003396, -0.01796, 0.006192) == ("-0.003", "-0.018 … 0.006")
    assert fmt_estimate(-2.798e-05, -2.858e-05, -2.743e-05) == ("-2.798e-05", "-2.858e-05 … -2.743e-05")
    assert fmt_scaled(-1.0658e-14, 50.0) == "0" and fmt_scaled(1e-3, 50.0) == "0.001"
    assert fmt_scaled(1.776e-15, 0.0) == "1.776e-15"          # no scale: nothing to call round-off
    assert fmt_percent(0.997) == "99.7 %" and fmt_percent(0.9996) == "99.96 %" and fmt_percent(0.0086) == "0.86 %"
    assert fmt_percent(1.0) == "100 %" and fmt_percent(None) == "–"
    assert fmt_count(116751.3) == "116751" and fmt_count(float("nan")) == "–"
    assert [ordinal(i) for i in (1, 2, 3, 4, 11, 12, 22)] == ["1st", "2nd", "3rd", "4th", "11th", "12th", "22nd"]
    assert compare(0.08, 0.149, 0.151).html.endswith(">out</span>") and "✗" not in compare(0.08, 0.149, 0.151).html
    assert compare(0.15, 0.149, 0.151).html.endswith(">in</span>")
    assert compare(None, 0, 1).html == "–"


def test_bad_run_folder_is_a_one_line_input_error(tmp_path, tiny, capsys):
    with pytest.raises(ReportInputError, match="run folder not found"):
        build_report(tmp_path / "nope")
    (tmp_path / "config.yaml").write_text("name: x\n")
    with pytest.raises(ReportInputError, match="this is a run configuration; give its run folder"):
        build_report(tmp_path / "config.yaml")
    (tmp_path / "a").mkdir()
    with pytest.raises(ReportInputError, match="summary.json"):
        build_report(tmp_path / "a")
    (tmp_path / "a" / "summary.json").write_text("{not json")
    with pytest.raises(ReportInputError, match="summary.json: not valid JSON"):
        build_report(tmp_path / "a")
    shutil.copy(tiny["run"] / "summary.json", tmp_path / "a" / "summary.json")
    with pytest.raises(ReportInputError, match="posterior.nc"):
        build_report(tmp_path / "a")
    # the subcommand: exit status 2 and one line on stderr
    import argparse
    from bayes_disc.report.cli import register
    parser = argparse.ArgumentParser()
    register(parser.add_subparsers(dest="command"))
    args = parser.parse_args(["report", str(tmp_path / "a"), "--reports-dir", str(tmp_path / "r")])
    assert args.func(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "posterior.nc" in err[0]


def test_changed_data_is_refused(tiny, tmp_path):
    """The report rebuilds the model from the run's config: data edited since the run must not pass silently."""
    d = tmp_path / "copy"
    shutil.copytree(tiny["dir"], d, ignore=shutil.ignore_patterns("figures", "reports", "chains"))
    s = json.loads((d / "out/summary.json").read_text())
    s["config"] = str(d / "config.yaml")
    (d / "out/summary.json").write_text(json.dumps(s))
    lines = (d / "flights.csv").read_text().splitlines()
    (d / "flights.csv").write_text("\n".join(lines[:-30]) + "\n")
    with pytest.raises(ReportInputError, match="differ from the run's summary.json"):
        build_report(d / "out", reports_dir=tmp_path / "r")


def test_later_capabilities_slot_in_as_sections(tiny, tmp_path):
    run = load_run(tiny["run"])
    run.extras["identifiability"] = {"CLa": {"verdict": "identified", "reason": "sd 3 % of the prior's"}}
    ctx = ReportContext(run, tmp_path / "figs")
    from bayes_disc.report import findings

    def extra(c):
        return Section("extra-capability", "Extra", "A later capability's section.", "<p>hello</p>")
    secs = build_sections(ctx, [findings.identifiability_section, extra])
    assert [s.id for s in secs] == ["identifiability", "extra-capability"]
    assert "identified" in secs[0].html and "sd 3 %" in secs[0].html
    doc = _parse(render_document("t", "s", secs))
    assert doc.section_ids == ["identifiability", "extra-capability"] and not doc.errors
    assert len(default_builders()) == len(DEFAULT_SECTION_IDS)
    with pytest.raises(ValueError, match="duplicate"):
        build_sections(ctx, [extra, extra])


def test_sections_drawn_in_worker_processes_equal_those_drawn_in_one(tiny):
    """The same HTML (but for the build's duration and clock time) and byte-identical PNGs from two worker
    processes as from one."""
    def strip(text):
        return re.sub(r"\d{4}-\d\d-\d\d \d\d:\d\d UTC", "", re.sub(r"Report built in [0-9.]+ s", "", text))
    assert "Report built in" in tiny["pooled"]
    assert strip(tiny["pooled"]) == strip(tiny["text"])
    serial_png = {p.name: p.read_bytes() for p in sorted((tiny["run"] / "figures").glob("*.png"))}
    assert sorted(serial_png) == sorted(f"{n}.png" for n in FIGURES)
    assert serial_png == tiny["pooled_png"]


def test_worker_sections_keep_order_figures_and_errors(tiny, tmp_path):
    run = load_run(tiny["run"])
    ctx = ReportContext(run, tmp_path / "figs")
    from bayes_disc.report import content

    def fails(c):
        raise ReportInputError(c.run.run_dir / "summary.json", "a section's input is broken")
    secs = build_sections(ctx, [content.coefficient_table, content.residual_section, content.force_curve_section],
                          processes=2)
    assert [s.id for s in secs] == ["coefficients", "residuals", "force-curves"]
    assert [f.name for f in ctx.figures_written] == [f.name for s in secs for f in s.figures]
    assert all(Path(f.png_path).is_file() and Path(f.pdf_path).is_file() for f in ctx.figures_written)
    with pytest.raises(ReportInputError, match="summary.json: a section's input is broken"):
        build_sections(ctx, [content.coefficient_table, fails], processes=2)
    with pytest.raises(ValueError, match="processes must be ≥ 1"):
        build_sections(ctx, [content.coefficient_table], processes=0)


def test_identifiability_section_says_why_no_next_throw_was_ranked(tiny, tmp_path):
    """Inertial-only runs skip the next-throw design (identifiability.json ``design.skipped``): the section
    gives the reason instead of failing on a missing ranking."""
    run = load_run(tiny["run"])
    why = "not computed: the candidate throws are simulated as marker flights"
    run.extras["identifiability"] = {"coefficients": {"CLa": {"verdict": "weak", "reason": "r"}},
                                     "design": {"skipped": why}}
    from bayes_disc.report import findings
    sec = build_sections(ReportContext(run, tmp_path / "figs"), [findings.identifiability_section])[0]
    assert "<h3>Next throw</h3>" in sec.html and why in sec.html and "ln volume gain" not in sec.html

def test_flagged_points_and_swapped_frames_are_listed(tiny, tmp_path):
    """Robust runs (flagged.json): counts and estimated π, w, π_s per flight (– for runs from before they were
    estimated), every outlier and swap with its time and probability; runs without it have no such section."""
    from bayes_disc.report import findings
    run = load_run(tiny["run"])
    assert findings.flagged_section(ReportContext(run, tmp_path / "f0")) is None
    run.extras["flagged"] = {          # flagged.json: per flight
        "a": {"mixture": {"outlier_fraction": 0.0123, "outlier_width_m": 0.0385, "swap_fraction": 0.0045},
              "outliers": [{"flight": "a", "t": 0.125, "marker": "1", "probability": 0.999}],
              "swaps": [{"flight": "a", "t": 0.25, "markers": ["0", "2"], "probability": 0.99}]},
        "b": {"outliers": [{"flight": "b", "t": 0.5, "marker": "0", "probability": 0.97}], "swaps": []}}
    sec = build_sections(ReportContext(run, tmp_path / "f1"), [findings.flagged_section])[0]
    assert sec.id == "flagged" and "0 ↔ 2" in sec.html and "0.1250" in sec.html and "0.970" in sec.html
    assert re.search(r"<td>a</td><td[^>]*>1</td><td[^>]*>1</td><td[^>]*>1.23 %</td><td[^>]*>38.5</td>"
                     r"<td[^>]*>0.45 %</td>", sec.html), sec.html
    assert re.search(r"<td>b</td><td[^>]*>1</td><td[^>]*>0</td><td[^>]*>–</td>", sec.html), sec.html
    assert "Averaged over the judgement" not in sec.html
    moments = lambda m, sd: {"mean": m, "sd": sd, "q05": m - 1.645 * sd, "q50": m, "q95": m + 1.645 * sd}
    run.extras["judgement_average"] = {"draws": 4000, "failed": 0, "pareto_k": 0.21, "ess": 3500.0, "reliable": True,
                                       "pareto_k_max": 0.7, "conditional": {"CLa": moments(2.9, 0.1)},
                                       "averaged": {"CLa": moments(2.95, 0.11)}}
    sec = build_sections(ReportContext(run, tmp_path / "f2"), [findings.flagged_section])[0]
    assert "k̂ of the weights 0.21" in sec.html and "<td>CLa</td><td>2.9</td><td>2.95</td>" in sec.html
    assert "<td>1.100</td>" in sec.html
    run.extras["judgement_average"] |= {"pareto_k": 0.9, "reliable": False, "averaged": {}}
    sec = build_sections(ReportContext(run, tmp_path / "f3"), [findings.flagged_section])[0]
    assert "cannot be trusted" in sec.html and "<td>CLa</td>" not in sec.html


def test_missing_physics_section_tables_the_oscillations_left(tiny, tmp_path):
    """diagnosis.json's ``lines``: a table row per series (amplitude with unit, frequency, × spin, cycles, share)."""
    from bayes_disc.report import findings
    run = load_run(tiny["run"])
    line = {"frequency_hz": 0.7993, "amplitude": 0.441, "share": 0.419, "cycles": 2.88, "unit": "m/s²",
            "per_spin": 0.0813}
    run.extras["diagnosis"] = {"verdict": "missing_physics", "words": "w", "lines": {"003-rf": {"acc_z": line}}}
    sec = build_sections(ReportContext(run, tmp_path / "f0"), [findings.missing_physics_section])[0]
    assert "Oscillations left in the residuals" in sec.html
    assert re.search(r"<td>003-rf</td><td[^>]*>acc_z</td><td[^>]*>0.441 m/s²</td><td[^>]*>0.799</td>"
                     r"<td[^>]*>0.081</td><td[^>]*>2.9</td><td[^>]*>42 %</td>", sec.html), sec.html
    run.extras["diagnosis"]["lines"] = None
    sec = build_sections(ReportContext(run, tmp_path / "f1"), [findings.missing_physics_section])[0]
    assert "Oscillations left" not in sec.html


def test_diagnosis_adds_its_section_with_before_after_figure(tiny, tmp_path):
    """`diagnose` on a sampled run folder rebuilds the report with the missing-physics section filled in."""
    out = tmp_path / "out"
    shutil.copytree(tiny["run"], out)
    with pytest.MonkeyPatch.context() as mp:
        mp.chdir(tmp_path)
        assert main(["diagnose", str(tiny["dir"] / "config.yaml"), "--no-sample", "--processes", "1",
                     "--output", str(out)]) == 0
    diagnosis = json.loads((out / "diagnosis.json").read_text())
    html = (out / "reports" / "tiny.html").read_text(encoding="utf-8")    # --output DIR: DIR/reports/
    doc = _parse(html)
    assert "missing-physics" in doc.section_ids and not doc.errors
    section = html[html.index('<section id="missing-physics">'):]
    assert f"Verdict: <b>{diagnosis['verdict']}</b>" in section
    assert "Not computed" not in section and "Every candidate" in section
    assert (out / "figures" / "diagnosis_residuals.png").is_file()
    assert "diagnosis_residuals" in section


def test_wind_tunnel_table_is_packaged():
    t = load_wind_tunnel()
    assert t.alpha_deg[0] == -100 and t.alpha_deg[-1] == 100 and t.alpha_deg.size == 41
    assert "Potts" in t.citation and "Manchester" in t.citation
    i = int(np.flatnonzero(t.alpha_deg == 0)[0])
    assert (t.CL[i], t.CD[i], t.CM[i]) == (0.11852, 0.09367, -0.00699)


# ---------------------------------------------------------------------------------------------- browser
def _chromium(tmp_path: Path, *args: str) -> subprocess.CompletedProcess:
    require_outside_input(Path(CHROMIUM).is_file(),
                          f"{CHROMIUM} not installed (Debian's chromium): CI installs it, see .ci/run")
    profile = tmp_path / f"profile{len(list(tmp_path.glob('profile*')))}"
    profile.mkdir()
    cmd = [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
           "--disable-background-networking", "--disable-component-update", "--disable-sync",
           "--disable-dev-shm-usage", f"--user-data-dir={profile}", "--virtual-time-budget=10000", *args]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=120)


def _body_attrs(dom: str) -> dict:
    start = dom.index("<body")
    tag = dom[start: dom.index(">", start) + 1]
    doc = _Doc()
    out = {}

    def grab(t, attrs):
        out.update(dict(attrs))
    doc.handle_starttag = grab
    doc.feed(tag)
    return out


def test_renders_in_headless_chromium_without_broken_images(tiny, tmp_path):
    url = tiny["html"].resolve().as_uri()
    r = _chromium(tmp_path, "--dump-dom", url)
    assert r.returncode == 0, r.stderr[-2000:]
    body = _body_attrs(r.stdout)
    assert body.get("data-render-check") == "done", body
    assert body.get("data-images") == str(len(FIGURES)), body
    assert body.get("data-broken-images") == "0", body
    shot = tmp_path / "shot.png"
    r = _chromium(tmp_path, f"--screenshot={shot}", "--window-size=1200,3000", "--hide-scrollbars", url)
    assert r.returncode == 0 and shot.is_file(), r.stderr[-2000:]
    im = Image.open(shot)
    assert im.size == (1200, 3000)
    px = np.asarray(im.convert("L"), float)
    assert px.std() > 10 and (px < 128).mean() > 0.01, "page looks blank"


def test_browser_check_detects_a_broken_image(tiny, tmp_path):
    """Negative control: the same check reports a corrupted image."""
    text = tiny["text"]
    i = text.index("data:image/png;base64,") + len("data:image/png;base64,")
    bad = tmp_path / "broken.html"
    bad.write_text(text[:i] + "AAAA" + text[i + 4:], encoding="utf-8")
    r = _chromium(tmp_path, "--dump-dom", bad.resolve().as_uri())
    assert r.returncode == 0, r.stderr[-2000:]
    assert _body_attrs(r.stdout).get("data-broken-images") == "1"


MEASURE_SCRIPT = """<script>
window.addEventListener('load', function () {
  function bottom(sel) { var e = document.querySelector(sel); return e ? e.getBoundingClientRect().bottom : -1; }
  var b = document.body;
  b.setAttribute('data-viewport', String(window.innerHeight));
  b.setAttribute('data-table-bottom', String(bottom('section#answer table.answer')));
  var lines = document.querySelectorAll('section#answer li.verdict-line');
  b.setAttribute('data-verdicts', String(lines.length));
  b.setAttribute('data-verdicts-bottom', String(lines.length ? lines[lines.length - 1].getBoundingClientRect().bottom : -1));
});
</script>"""


def test_first_screen_in_a_browser_shows_table_and_verdicts(tiny, tmp_path):
    """At 1280 × 900 px the coefficient table and the three verdict lines are on screen without scrolling
    (positions measured by the browser's layout), and the screenshot is not blank."""
    text = tiny["text"]
    probe = tmp_path / "probe.html"
    probe.write_text(text.replace("</head>", MEASURE_SCRIPT + "</head>", 1), encoding="utf-8")
    r = _chromium(tmp_path, "--window-size=1280,900", "--dump-dom", probe.resolve().as_uri())
    assert r.returncode == 0, r.stderr[-2000:]
    body = _body_attrs(r.stdout)
    assert body.get("data-verdicts") == "3", body
    view = float(body["data-viewport"])
    assert 0 < float(body["data-verdicts-bottom"]) <= view, body
    assert 0 < float(body["data-table-bottom"]) <= view, body
    shot = tmp_path / "first.png"
    r = _chromium(tmp_path, f"--screenshot={shot}", "--window-size=1280,900", "--hide-scrollbars",
                  tiny["html"].resolve().as_uri())
    assert r.returncode == 0 and shot.is_file(), r.stderr[-2000:]
    px = np.asarray(Image.open(shot).convert("L"), float)
    assert px.std() > 10 and (px < 128).mean() > 0.01, "first screen looks blank"


def test_diagnosis_figure_of_an_inertial_run_draws_the_logger_series():
    """An inertial run's diagnosis has gyro and accelerometer series, no marker translations or attitude
    angles: the figure draws the most structured logger series in its own unit (before, it fell back to the
    marker series "roll", absent from the file, and the report stopped with a KeyError)."""
    from bayes_disc.report import figures as F
    from bayes_disc.report.findings import SERIES_LABELS, diagnosis_series
    rng = np.random.default_rng(0)
    names = [f"{s}_{a}" for s in ("gyro", "acc") for a in "xyz"]
    series = {"flights": np.array(["a", "b"])}
    for c in range(2):
        series[f"{c}_times"] = np.linspace(0.0, 1.0, 50)
        for n in names:
            series[f"{c}_times_{n}"] = series[f"{c}_times"]
            series[f"{c}_se_{n}"] = np.full(50, 0.01)
            series[f"{c}_before_{n}"] = rng.normal(0.0, 0.3, 50)
            series[f"{c}_after_{n}"] = series[f"{c}_before_{n}"]
    ratio = {"gyro_x": 5.0, "gyro_y": 40.0, "gyro_z": 2.0, "acc_x": 3.0, "acc_y": 1.0, "acc_z": 9.0}
    data = {"localisation_before": {f: {n: {"noise_ratio": r} for n, r in ratio.items()} for f in ("a", "b")},
            "effects": []}
    chosen = diagnosis_series(series, data)
    assert chosen == ["gyro_y"]
    fig = F.diagnosis_figure(series, ["a", "b"], chosen, SERIES_LABELS)
    assert fig.axes[0].get_ylabel() == "gyro y [rad/s]"
    # a marker run keeps its choice: the most structured translation, then the most structured attitude angle
    marker = {"flights": np.array(["a"]), "0_times": np.linspace(0.0, 1.0, 10),
              **{f"0_{k}_{n}": np.zeros(10) for k in ("se", "before", "after")
                 for n in ("along", "lateral", "normal", "roll", "pitch", "spin_phase")}}
    loc = {"a": {"along": {"noise_ratio": 2.0}, "lateral": {"noise_ratio": 7.0}, "normal": {"noise_ratio": 1.0},
                 "roll": {"noise_ratio": 1.5}, "pitch": {"noise_ratio": 3.0}, "spin_phase": {"noise_ratio": 1.0}}}
    assert diagnosis_series(marker, {"localisation_before": loc, "effects": []}) == ["lateral", "pitch"]


def test_noise_rms_formats_old_and_new_runs_alike():
    """The appendix's residual RMS: a run's ``noise`` groups in their units, and a run written before that key
    (only ``rms_mm``, marker flights) through the same formatter (``leastsq.noise_text``)."""
    from bayes_disc.report.content import _noise_rms
    new = {"noise": {"sigma_bsfl5": {"value": 0.00152, "unit": "m"},
                     "sigma_gyro_axial": {"value": 0.0127, "unit": "rad/s"}}}
    assert _noise_rms(new) == "bsfl5 1.52 mm, gyro_axial 0.0127 rad/s"
    assert _noise_rms({"rms_mm": {"bsfl5": 1.52, "fffl10": 0.98}}) == "bsfl5 1.52 mm, fffl10 0.98 mm"
    assert _noise_rms({}) == ""


def test_refits_from_a_lower_point_are_listed_in_the_appendix():
    """Each ``lower_optima`` record of the least squares (profile.profiles_through_lowest) is one appendix row;
    runs written before the key have none."""
    from bayes_disc.report.content import _lower_optimum_rows
    ls = {"cost": 5918.806,
          "lower_optima": [{"profile": "CM0", "t": -1.797, "deviance": -0.6227, "earlier_cost": 5919.83}]}
    rows = _lower_optimum_rows(ls)
    assert len(rows) == 1 and rows[0][0] == "refit 1 from a lower point"
    text = rows[0][1]
    assert "CM0" in text and "-0.62 at t = -1.80" in text and "scales: 5919.8, the new one's 5918.8" in text
    assert _lower_optimum_rows({}) == [] and _lower_optimum_rows({"lower_optima": []}) == []
