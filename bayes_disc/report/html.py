"""One self-contained HTML file: inline CSS, PNGs as base64 data URIs, no external resources.

A small inline script marks ``<body>`` after load with ``data-images`` (number of ``<img>``),
``data-broken-images`` (images that failed to decode: ``naturalWidth == 0``) and ``data-render-check``
(``"done"``), so a headless browser's ``--dump-dom`` shows whether every image rendered.
"""
from __future__ import annotations

import base64
from datetime import datetime, timezone

from .sections import Section, esc

CSS = """
body{font-family:-apple-system,"Segoe UI",Helvetica,Arial,sans-serif;margin:0 auto;max-width:1250px;
padding:0 1.2em 3em;color:#222;line-height:1.4;font-size:15px}
header{border-bottom:2px solid #335;margin-bottom:.4em;padding-bottom:.3em}
h1{margin:.5em 0 .1em;font-size:1.6em}h2{border-bottom:1px solid #ccd;padding-bottom:.2em;margin-top:2em}
header p.sub{margin:0;color:#555;font-size:.88em}
nav ol{list-style:none;padding:0;margin:.3em 0 0;font-size:.85em;display:flex;flex-wrap:wrap;gap:.1em 1.1em}
section#answer h2{margin-top:.6em}
p.lead{margin:.3em 0 .5em}
ul.verdicts{list-style:none;padding:0;margin:.4em 0 .6em}
li.verdict-line{padding:.25em .5em;margin:.15em 0;border-left:4px solid #aab;background:#f6f7fa}
li.status-ok{border-left-color:#3a8a4f}li.status-attention{border-left-color:#c77800}
li.status-not-run{border-left-color:#99a}
.badge{display:inline-block;width:5.4em;margin-right:.5em;font-size:.8em;font-weight:600;text-transform:uppercase;
letter-spacing:.03em;color:#445}
li.status-ok .badge{color:#2d6e3e}li.status-attention .badge{color:#9a5c00}li.status-not-run .badge{color:#667}
.cmp{font-size:.8em;color:#667;margin-left:.25em}.cmp-out{font-style:italic}
table.answer{font-size:.92em}
p.guide{background:#eef3fb;border-left:4px solid #4a78c2;padding:.4em .7em;margin:.4em 0 1em}
p.note{color:#555;font-size:.9em}
table{border-collapse:collapse;margin:.5em 0 1em;font-size:.88em}
th,td{border:1px solid #ccd;padding:.2em .5em;vertical-align:top}th{background:#f0f2f7;text-align:left}
table.num td{text-align:right;font-variant-numeric:tabular-nums}table.num td:first-child{text-align:left}
table.kv td:first-child{font-weight:600;white-space:nowrap}
.disagree{color:#b00020;font-weight:600}.truth{color:#555;font-size:.9em}
.verdict{padding:.5em .8em;border-radius:4px}.verdict.ok{background:#e6f4ea}.verdict.warn{background:#fdecea}
figure{margin:1em 0 1.5em}figure img{max-width:100%;height:auto;border:1px solid #e3e3e3}
figcaption{font-size:.88em;color:#444;margin-top:.3em}figcaption .files{color:#888;font-family:monospace;
font-size:.85em}
.cols{display:flex;gap:2em;flex-wrap:wrap}code{background:#f4f4f4;padding:0 .2em}
footer{margin-top:3em;color:#888;font-size:.85em}
"""

CHECK_SCRIPT = """
window.addEventListener('load', function () {
  var imgs = document.images, bad = 0;
  for (var i = 0; i < imgs.length; i++) {
    if (!imgs[i].complete || imgs[i].naturalWidth === 0 || imgs[i].naturalHeight === 0) { bad++; }
  }
  document.body.setAttribute('data-images', String(imgs.length));
  document.body.setAttribute('data-broken-images', String(bad));
  document.body.setAttribute('data-render-check', 'done');
});
"""


def data_uri(png: bytes) -> str:
    return "data:image/png;base64," + base64.b64encode(png).decode("ascii")


def render_section(sec: Section) -> str:
    parts = [f'<section id="{esc(sec.id)}">', f"<h2>{esc(sec.title)}</h2>"]
    if sec.guide:
        parts.append(f'<p class="guide"><b>How to read:</b> {esc(sec.guide)}</p>')
    parts.append(sec.html)
    for fig in sec.figures:
        parts.append(f'<figure id="fig-{esc(fig.name)}"><img src="{data_uri(fig.png)}" alt="{esc(fig.caption)}">'
                     f"<figcaption>{esc(fig.caption)} <span class=files>[{esc(fig.png_path)}, "
                     f"{esc(fig.pdf_path)}]</span></figcaption></figure>")
    parts.append("</section>")
    return "\n".join(parts)


def render_document(title: str, subtitle: str, sections: list[Section], footer: str = "") -> str:
    """The complete HTML page."""
    nav = "".join(f'<li><a href="#{esc(s.id)}">{esc(s.title)}</a></li>' for s in sections)
    stamp = datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    body = "\n".join(render_section(s) for s in sections)
    return (f"<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n"
            f"<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n"
            f"<title>{esc(title)}</title>\n<style>{CSS}</style>\n<script>{CHECK_SCRIPT}</script>\n</head>\n"
            f"<body>\n<header><h1>{esc(title)}</h1><p class=sub>{esc(subtitle)}</p>"
            f"<nav><ol>{nav}</ol></nav></header>\n{body}\n"
            f"<footer>Generated {esc(stamp)} by bayes-disc. {esc(footer)}</footer>\n</body>\n</html>\n")
