"""The diagnosis in words: RMS per flight and channel, the effects adopted and how much of the misfit they
explain, what stays unexplained, the candidates turned down, the noise verdict, the learned correction, the
wobble of inertial throws and the oscillations left in the residuals — read from a ``diagnosis.json`` record
(:func:`.diagnosis.diagnosis_record`)."""
from __future__ import annotations

import numpy as np

from .mismatch import SERIES_WORDS
from .missing_physics import EVIDENCE_THRESHOLD, SHARE_PARTIAL


def _fmt(x: float) -> str:
    return f"{x:.3g}"


#: display scale and unit of each RMS channel
_RMS_DISPLAY = {"m": (1e3, "mm"), "rad/s": (1.0, "rad/s"), "m/s²": (1.0, "m/s²")}


def rms_text(rms: dict, after: dict | None = None) -> str:
    """'flight markers 1.52 mm' or 'flight gyro 0.031 rad/s, acc 0.41 m/s²' (→ after) for every flight.

    Parameters
    ----------
    rms, after : dict
        {flight: {channel: {"rms", "unit"}}} before and (optionally) after.

    Returns
    -------
    str
    """
    parts = []
    for f, per in rms.items():
        items = []
        for chan, d in per.items():
            k, u = _RMS_DISPLAY.get(d["unit"], (1.0, d["unit"]))
            x = f"{d['rms'] * k:.3g}"
            if after is not None:
                x += f" → {after[f][chan]['rms'] * k:.3g}"
            items.append(f"{chan} {x} {u}")
        parts.append(f"{f} " + ", ".join(items))
    return "; ".join(parts)


def effect_name(term_id: str) -> str:
    """A term's id in words ('ground_effect' → 'ground effect')."""
    return term_id.replace("_", " ")


def _share_text(share) -> str:
    return f"{100 * share:.0f} %" if share is not None and np.isfinite(share) else "part"


def _rest_text(unexplained: list) -> str:
    """Where the structure a partial explanation leaves sits: its flights, then the strongest window."""
    if not unexplained:
        return "no flight's residuals stay structured"
    flights = [u["flight"] for u in unexplained]
    top = max(unexplained, key=lambda u: len(u["series"]))
    a, b = top["peak_window_s"]
    text = (f"the rest sits in flight{'s' if len(flights) > 1 else ''} {', '.join(flights)}, strongest at "
            f"{a:.2f}–{b:.2f} s")
    h = top.get("peak_height_m")
    if h is not None:
        text += f" (height {h[0]:.2f}–{h[1]:.2f} m)" if abs(h[1] - h[0]) >= 0.005 else f" (height {h[0]:.2f} m)"
    if len(flights) > 1:
        text += f" in flight {top['flight']}"
    return text + f", in the {', '.join(SERIES_WORDS[s] for s in top['series'][:3])} residuals"


def partial_words(result: dict) -> str:
    """The partial explanation in words: what the adopted terms explain and where the rest sits.

    Parameters
    ----------
    result : dict
        ``diagnosis.json`` content with ``partial_explanation`` ({ids, share_explained, evidence}) and
        ``unexplained``.

    Returns
    -------
    str
    """
    pe = result["partial_explanation"]
    names = " and ".join(effect_name(i) for i in pe["ids"])
    verb = "explain" if len(pe["ids"]) > 1 else "explains"
    return (f"{names[0].upper()}{names[1:]} {verb} {_share_text(pe['share_explained'])} of the excess misfit "
            f"(ΔBIC {pe['evidence']:,.0f}); {_rest_text(result['unexplained'])}: the effect's form differs from "
            "the library's (a different law, or a further effect of the same kind), so its estimate is that of "
            "the nearest formula the library has.")


def _rejected_text(c: dict) -> str:
    """Why an insufficient candidate was not adopted: too small a share, or a gain not replicated."""
    rep = c.get("replication")
    if rep and not rep["replicated"]:
        where = ", ".join(rep["removing"]) or "no flight"
        others = [f for f in (rep["acts_in"] or []) if f not in rep["removing"]]
        also = (f"; as fitted it acts in {', '.join(others)} too, where it removes none" if others else "")
        return (f"{c['id']} (ΔBIC {c['evidence']:.1f}, removes {_share_text(c.get('share_explained'))} of the "
                f"excess misfit, but only in {where}{also}: not replicated)")
    return (f"{c['id']} (ΔBIC {c['evidence']:.1f} but leaves structure and removes only "
            f"{_share_text(c.get('share_explained'))} of the excess misfit, less than {100 * SHARE_PARTIAL:.0f} %)")


def choice_words(noise: dict) -> list[str]:
    """One line listing the marker noise ``sample`` uses per flight (``noise.choice``), when it is not white
    noise for every flight; none otherwise."""
    choice = noise.get("choice") or {}
    if all(r.get("label") == "white" for r in choice.values()):
        return []
    return ["Marker noise as `sample` chooses it at the base model's least squares: "
            + "; ".join(r["text"] for r in choice.values()) + "."]


def lines_words(result: dict) -> list[str]:
    """One sentence per flight naming the oscillations left in its residuals (``lines`` of diagnosis.json:
    :mod:`.lines`): series, amplitude, frequency, its multiple of the spin and its share of the series."""
    out = []
    for flight, per in (result.get("lines") or {}).items():
        items = []
        for name, line in per.items():
            k, u = _RMS_DISPLAY.get(line["unit"], (1.0, line["unit"]))
            spin = f"{line['per_spin']:.3f} × spin, " if line.get("per_spin") else ""
            items.append(f"{SERIES_WORDS.get(name, name)} {line['amplitude'] * k:.2g} {u} at "
                         f"{line['frequency_hz']:.2f} Hz ({spin}{_share_text(line['share'])} of its residual)")
        out.append(f"Oscillations left in flight {flight}: " + "; ".join(items) + ".")
    return out


def words(result: dict) -> str:
    """The diagnosis in words (printed by the command, shown in the report)."""
    lines = []
    before, after = result["rms_before"], result["rms_after"]
    skipped = result.get("skipped_candidates") or {}
    noise = result.get("noise") or {}
    if noise.get("model") == "ar1":
        lines.append("Noise correlated in time: AR(1) marker noise, " + ", ".join(
            f"ρ = {r:.2f} ({f})" for f, r in noise["rho"].items()) + f" per frame (ΔBIC {noise['evidence']:.0f} over "
            "white noise)" + ("; no missing physics." if result["verdict"] == "adequate" else "."))
    if result["verdict"] == "adequate":
        best = result["candidates"][0] if result["candidates"] else None
        white = "AR(1) innovations" if noise.get("model") == "ar1" else "residuals"
        lines.append(f"The model is adequate: the {white} of every flight are white"
                     + (f" and no candidate earns its place (ΔBIC > {EVIDENCE_THRESHOLD:.0f} with white residuals; "
                        f"best: {best['id']}, ΔBIC {best['evidence']:.1f})." if best else "."))
        lines.append("RMS " + rms_text(before) + ".")
        lines += [] if noise.get("adopted") else choice_words(noise)
        lines += [w["words"] for w in (result.get("wobble") or {}).values()]
        lines += [result["random_nutation"]["words"]] if result.get("random_nutation") else []
        lines += lines_words(result)
        if skipped:
            lines.append("Not tried: " + ", ".join(f"{c} ({why})" for c, why in skipped.items()) + ".")
        return "\n".join(lines)
    partial = result.get("partial_explanation")
    if partial:
        lines.append(partial_words(result))
    for e in result["effects"]:
        est = "; ".join(f"{n} = {_fmt(v['value'])} (95% {_fmt(v['q025'])} … {_fmt(v['q975'])})"
                        for n, v in e["estimate"].items())
        lines.append(f"{e['where'][0].upper()}{e['where'][1:]} → {e['title']} [{e['id']}]. "
                     f"ΔBIC {e['evidence']:.1f}. Estimated {est}.")
    if result["effects"]:
        lines.append("RMS " + rms_text(before, after) + ".")
        moved = result.get("shifted_coefficients") or []
        if moved:
            lines.append("Base coefficients the missing term had biased: " + ", ".join(
                f"{s['name']} moved from {_fmt(s['before'])} to {_fmt(s['after'])} ({s['shift_sd']:+.1f} sd)"
                for s in moved) + ".")
        else:
            lines.append("No base coefficient moved by more than 2 sd.")
    if noise.get("ar1_explains") is False:
        tried = (f"Correlated (AR(1)) marker noise was tried (ΔBIC {noise['ar1_evidence']:.0f} over white noise)"
                 if noise.get("ar1_rho") else "The per-point noise chosen was tried")
        lines.append(f"{tried} and leaves the structure below unexplained too, so it is not taken as the explanation.")
    lines += [] if noise.get("adopted") else choice_words(noise)
    for u in ([] if partial else result["unexplained"]):
        a, b = u["peak_window_s"]
        onset = u["model_follows_until_s"]
        if onset is not None:
            when = f"; the model follows the flight until {onset:.2f} s after its start, then departs"
        elif u.get("onset_note"):
            when = f"; onset {u['onset_note']}"
        else:
            when = "; structured from the start"
        lines.append(f"Unexplained: flight {u['flight']} (RMS {rms_text({u['flight']: u['rms']})[len(u['flight']) + 1:]})"
                     f" — structured {', '.join(SERIES_WORDS[s] for s in u['series'][:4])} residuals, largest at "
                     f"{a:.2f}–{b:.2f} s{when}. No term of the library removes it "
                     "(a gust, a collision, a sensor or tracking fault, or physics the library lacks?).")
    rejected = [c for c in result["candidates"] if c["status"] == "insufficient" and c["round"] == 1]
    if result["unexplained"] and rejected and not partial:
        lines.append("Not forced onto a term: " + ", ".join(_rejected_text(c) for c in rejected[:4]) + ".")
    learned = learned_words(result)
    if learned:
        lines.append(learned)
    lines += [w["words"] for w in (result.get("wobble") or {}).values()]
    lines += [result["random_nutation"]["words"]] if result.get("random_nutation") else []
    lines += lines_words(result)
    if skipped:
        lines.append("Not tried: " + ", ".join(f"{c} ({why})" for c, why in skipped.items()) + ".")
    return "\n".join(lines)


def learned_words(result: dict) -> str | None:
    """The learned correction in words, or None when none was learned."""
    ld = result.get("learned_discrepancy")
    if not ld:
        return None
    if not ld.get("selected"):
        return f"A correction learned in height, α and spin finds nothing significant ({ld['reason']})."
    conc = sorted(ld["concentration"].items(), key=lambda t: -t[1])
    where = ", ".join(f"{v} {100 * s:.0f} %" for v, s in conc)
    share = ld.get("share_explained")
    result_text = ("leaves white residuals" if ld["white"] else
                   f"removes {_share_text(share)} of the excess misfit but leaves some structure")
    text = (f"A correction learned in functions of height, α and spin ({ld['selected']} of them selected, ΔBIC "
            f"{ld['evidence']:,.0f}) {result_text}; its evidence lies in {where}, mostly in {ld['direction']}")
    fam = ld.get("family")
    large = share is not None and np.isfinite(share) and share >= SHARE_PARTIAL
    # files written before the replication rule have no "explains": there it was white or a large share
    explains = ld["explains"] if "explains" in ld else (ld["white"] or large)
    if fam:
        text += (f": the missing physics is {'' if ld['white'] else 'mainly '}a function of {ld['variable']}, the "
                 f"{effect_name(fam)} family")
        curve = ld.get("curve") or {}
        named = [e["id"] for e in result.get("effects") or []]
        if fam in named and curve.get("family") is not None:
            text += " named above" + (", whose fitted form it follows" if _follows(curve) else
                                      f"; its {ld['direction']} curve departs from the fitted {effect_name(fam)} "
                                      "form beyond two standard deviations (see the report's curve)")
        text += "."
    elif large and not explains:
        text += (": its gain is not replicated in a second flight, so it cannot tell physics from a disturbance "
                 "of one flight (a gust, say) and names no family.")
    elif not explains:
        text += (": the mismatch is not a smooth function of the flight state the library's terms use "
                 "(a disturbance, or physics outside these variables).")
    else:
        text += ": spread over several flight variables, it names no single family."
    return text


def _follows(curve: dict) -> bool:
    """Whether the learned curve and the fitted family's agree within 2 sd (+ 10 % of the curve's range)."""
    value, sd = (np.asarray(curve["value"], float), np.asarray(curve["sd"], float))
    fam = np.asarray(curve["family"]["value"], float)
    tol = 2 * sd + 0.1 * (np.ptp(value) + 1e-12)
    return bool(np.all(np.abs(value - fam) <= tol))
