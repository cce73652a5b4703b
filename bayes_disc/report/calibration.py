"""The page of a calibration campaign (``<output>/calibration.html``): rank histograms and coverage.

It is given the ``calibration.json`` content as a dict (the campaign itself lives above the report in
the layers): per coefficient the counts of the SBC ranks in B bins and the coverage of the 50 % and 90 %
central intervals, and the binomial bands of the campaign (``rank_count_band_95``: the central 95 % range
of a bin's count when the ranks are uniform, Binomial(N, 1/B); ``coverage_band_95``: that of the coverage
when the intervals are calibrated, Binomial(N, c)/N; ``coverage_band_familywise_95``: the wider range that
all K coverages of a calibrated campaign fall inside with probability ≥ 95 %, and
``coverage_outside_expected``: how many of the K fall outside their own band by chance, on average).
Same self-contained HTML as the run reports.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .figures import _grid, new_figure, save_figure
from .html import render_document
from .sections import Section, esc, fmt, table


def rank_histogram_figure(result: dict):
    """One panel per coefficient: rank counts per bin, the uniform count N/B and its 95 % band (grey)."""
    names = list(result["coefficients"])
    nr, nc = _grid(len(names), 5)
    fig = new_figure(12, 2.0 * nr + 0.4)
    axes = fig.subplots(nr, nc, squeeze=False).ravel()
    b, n = result["rank_bins"], result["replicates"]
    lo, hi = result["rank_count_band_95"]
    for ax, name in zip(axes, names):
        counts = np.asarray(result["coefficients"][name]["rank_counts"])
        ax.axhspan(lo, hi, color="0.85", lw=0)
        ax.axhline(n / b, color="0.4", lw=0.8, ls=":")
        ax.bar(np.arange(b), counts, width=0.9, color="tab:blue")
        ax.set_title(f"{name}  (p = {fmt(result['coefficients'][name]['rank_uniformity_p'], 2)})", fontsize=9)
        ax.set_xticks([])
        ax.tick_params(labelsize=7)
    for ax in axes[len(names):]:
        ax.set_visible(False)
    for ax in axes[::nc]:
        ax.set_ylabel("replicates", fontsize=8)
    fig.subplots_adjust(left=0.06, right=0.98, top=0.92, bottom=0.06, hspace=0.45)
    return fig


def coverage_figure(result: dict):
    """Coverage of the 50 % and 90 % intervals per coefficient against nominal, with binomial 95 % bands."""
    names = list(result["coefficients"])
    fig = new_figure(12, 3.2)
    ax = fig.subplots()
    x = np.arange(len(names))
    family = result.get("coverage_band_familywise_95")
    for level, color, dx in ((50, "tab:blue", -0.12), (90, "tab:orange", 0.12)):
        lo, hi = result["coverage_band_95"][str(level)]
        ax.axhspan(lo, hi, color=color, alpha=0.15, lw=0)
        if family is not None:
            for edge in family[str(level)]:
                ax.axhline(edge, color=color, lw=0.8, ls="--")
        ax.axhline(level / 100, color=color, lw=0.8, ls=":")
        cov = [result["coefficients"][n][f"coverage_{level}"] for n in names]
        ax.plot(x + dx, cov, "o", color=color, label=f"{level} % interval")
    ax.set_xticks(x, names, fontsize=8)
    ax.set_ylim(0, 1.02)
    ax.set_ylabel("coverage", fontsize=9)
    ax.legend(fontsize=8, frameon=False, loc="lower right")
    fig.subplots_adjust(left=0.06, right=0.98, top=0.95, bottom=0.12)
    return fig


def _inside(x: float, band) -> str:
    return "yes" if band[0] <= x <= band[1] else "NO"


def calibration_sections(result: dict, figures_dir: Path) -> list[Section]:
    """The page's sections: summary table, rank histograms, coverage."""
    n, b = result["replicates"], result["rank_bins"]
    bands = result["coverage_band_95"]
    family = result.get("coverage_band_familywise_95")     # absent from campaign summaries of older versions
    rows = []
    for name, c in result["coefficients"].items():
        row = [name]
        for level in ("50", "90"):
            row += [fmt(c[f"coverage_{level}"], 3), _inside(c[f"coverage_{level}"], bands[level])]
            if family is not None:
                row.append(_inside(c[f"coverage_{level}"], family[level]))
        rows.append(row + [fmt(c["rank_uniformity_p"], 3), fmt(c.get("z_sd"), 3)])
    header = ["coefficient"]
    for level in ("50", "90"):
        header += [f"coverage {level} %", "in band"] + (["in family-wise band"] if family is not None else [])
    header += ["rank uniformity p (χ²)", "sd of z"]
    failed = result.get("failed", [])
    unconv = result.get("not_converged", [])
    lead = (f"<p class=lead>{n} replicates ranked (of {result.get('requested', n)} requested; {len(failed)} failed, "
            f"{len(unconv)} reached the sampler's cap before converging). Truths drawn from "
            f"{esc(result.get('truth_draw', '?'))}; L = {result['draws_per_replicate']} thinned posterior draws "
            f"per replicate, ranks in {b} bins. Binomial 95 % bands: 50 % interval "
            f"{fmt(bands['50'][0], 3)}–{fmt(bands['50'][1], 3)}, 90 % interval {fmt(bands['90'][0], 3)}–"
            f"{fmt(bands['90'][1], 3)}. sd of the standardised error z = (truth − posterior mean)/sd: 1 for intervals "
            f"of the right width, &gt; 1 too narrow (± {fmt(result.get('z_sd_se'), 2)} for N = {n}).</p>")
    chosen = result.get("noise_chosen") or {}
    if chosen:
        lead += ("<p>Marker noise model the runs used, over all flights of the ranked replicates: "
                 + ", ".join(f"{esc(label)} {count}" for label, count in sorted(chosen.items(), key=lambda x: -x[1]))
                 + ".</p>")
    if family is not None:
        k = 2 * len(result["coefficients"])
        outside = sum(not (bands[lv][0] <= c[f"coverage_{lv}"] <= bands[lv][1])
                      for c in result["coefficients"].values() for lv in ("50", "90"))
        lead += (f"<p>{outside} of the {k} coverages fall outside their own 95 % band; calibrated intervals put "
                 f"{fmt(result['coverage_outside_expected'], 2)} of {k} outside on average, by chance. Family-wise "
                 f"bands (all {k} inside with probability ≥ 95 % when calibrated; dashed in the coverage figure): "
                 f"50 % interval {fmt(family['50'][0], 3)}–{fmt(family['50'][1], 3)}, 90 % interval "
                 f"{fmt(family['90'][0], 3)}–{fmt(family['90'][1], 3)}. A coverage outside the family-wise band "
                 "is evidence against calibration; one outside its own band only is what chance gives about "
                 "once per campaign.</p>")
    summary = Section("summary", "Calibration summary",
                      "coverage inside its band and rank uniformity p not small (say > 0.01) mean honest intervals",
                      lead + table(header, rows))
    if failed:
        summary.html += "<p>Failed replicates: " + "; ".join(esc(f"{f['index']}: {f['error']}") for f in failed) + "</p>"
    ranks = Section("ranks", "Rank histograms",
                    "uniform ranks (bars inside the grey band) mean the posterior is calibrated; ∪: too narrow, "
                    "∩: too wide, slope: biased")
    ranks.figures.append(save_figure(rank_histogram_figure(result), figures_dir, "calibration_ranks",
                                     f"SBC rank counts per coefficient in {b} bins over {n} replicates; dotted: "
                                     "uniform count, grey: its binomial 95 % band"))
    cover = Section("coverage", "Coverage against nominal",
                    "points inside their shaded band are consistent with the nominal 50 % and 90 %")
    cover.figures.append(save_figure(coverage_figure(result), figures_dir, "calibration_coverage",
                                     "fraction of replicates whose central interval contains the truth; shaded: "
                                     "binomial 95 % band around nominal; dashed: family-wise 95 % band (all "
                                     "coverages at once)"))
    return [summary, ranks, cover]


def build_calibration_page(result: dict, path, figures_dir=None) -> Path:
    """Write the self-contained HTML page of a calibration campaign.

    Parameters
    ----------
    result : dict
        The calibration.json content (keys: :func:`bayes_disc.calibration.stats.summarize`).
    path : str or Path
        The ``.html`` file to write.
    figures_dir : str or Path, optional
        Where the PNG/PDF figures also go (default: ``figures`` beside the page).

    Returns
    -------
    Path
        The page written.
    """
    path = Path(path)
    figures_dir = path.parent / "figures" if figures_dir is None else Path(figures_dir)
    sections = calibration_sections(result, figures_dir)
    html = render_document(f"Calibration: {result.get('name', '')}",
                           "simulation-based calibration (Talts et al. 2018) over synthetic data sets",
                           sections)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(html, encoding="utf-8")
    return path
