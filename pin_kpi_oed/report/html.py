"""The certificate as one self-contained HTML page: tables, statements and the figures inlined as base64 PNG.

Every number comes from the certificate's data (SI) and is printed in mm, mrad or degrees with its unit; the
page has one ``<section id=...>`` per entry of :data:`~pin_kpi_oed.report.content.SECTIONS`, each with a
statement where the data give no figure.
"""

from __future__ import annotations

import base64
import html
from typing import Any

import numpy as np

from pin_kpi_oed.report.content import SECTIONS, Certificate

__all__ = ["render_html", "mm"]

_CSS = """body{font-family:sans-serif;max-width:1100px;margin:2em auto;color:#222}
h1{border-bottom:3px solid #4c72b0}h2{border-bottom:1px solid #ccc;margin-top:1.6em}
table{border-collapse:collapse;margin:.6em 0}
td,th{border:1px solid #ccc;padding:3px 8px;font-size:13px;text-align:right}
th{background:#eef}td.l,th.l{text-align:left}
code{background:#f4f4f4;padding:2px 4px;font-size:12px;word-break:break-all}
pre{white-space:pre-wrap;overflow-wrap:anywhere;font-size:12px}td{overflow-wrap:anywhere}
.verdict{font-weight:bold}img{max-width:100%}.note{color:#555;font-size:13px}
.status{font-size:18px;font-weight:bold;padding:6px 10px;border:2px solid}.status.draft{color:#a33;border-color:#a33}
.status.certificate{color:#264;border-color:#264}.v-conforms{color:#264}.v-does-not-conform{color:#a33}
.v-undetermined{color:#a60}.sign{margin-top:2em}
@media print{section{break-inside:auto}#summary{break-after:page}body{max-width:none;margin:0}}"""


def mm(v: Any, digits: int = 4) -> str:
    """A length in m printed in mm (``—`` for None)."""
    return "—" if v is None else f"{float(v) * 1e3:.{digits}f} mm"


def _e(x: Any) -> str:
    return html.escape(str(x))


def _table(header: list[str], rows: list[list[Any]], left: int = 1) -> str:
    th = "".join(f'<th class="l">{_e(h)}</th>' if i < left else f"<th>{_e(h)}</th>" for i, h in enumerate(header))
    body = "".join("<tr>" + "".join(f'<td class="l">{_e(c)}</td>' if i < left else f"<td>{_e(c)}</td>"
                                    for i, c in enumerate(r)) + "</tr>" for r in rows)
    return f"<table><tr>{th}</tr>{body}</table>"


def _img(figs: dict, name: str, alt: str) -> str:
    if name not in figs:
        return ""
    return f'<p><img alt="{_e(alt)}" src="data:image/png;base64,{base64.b64encode(figs[name]).decode()}"></p>'


def _calibrated(d: dict) -> str:
    c = d["calibrated"]
    rows = [["robot", c["robot"]], ["URDF", c["urdf_path"]], ["URDF SHA-256", c["urdf_sha256"]],
            ["kinematics hash", c["kinematics_hash"] or "— (the URDF's own kinematics)"],
            ["tool frame", c["tool_frame"]],
            ["TCP in the tool frame", ", ".join(mm(v, 2) for v in c["tcp_m"])],
            ["tracker noise model (weights of the fit)",
             ", ".join(f"{v * 1e6:.1f} µm" for v in c["noise"]["sigma_xyz_m"])
             + f" per axis ({c.get('sigma_source') or 'as given'})"],
            ["model file", f"{c['model_file']['path']} (SHA-256 {c['model_file']['sha256']})"]]
    out = _table(["item", "value"], rows, left=2)
    st = [[s["label"], ", ".join(f"{v:.4f}" for v in s["tracker_T_base_xyz_m"]) + " m",
           ", ".join(f"{np.degrees(v):.3f}" for v in s["tracker_T_base_rpy_rad"]) + " deg",
           ", ".join(mm(v, 2) for v in s["reflector_m"]), s["n_rows"], s["fitted_by"]] for s in c["stations"]]
    out += "<h3>Stations (tracker set-ups)</h3>" + _table(
        ["station", "base in tracker: xyz", "rpy", "reflector (tool frame)", "rows", "fitted by"], st)
    files = [[role, f["path"], f["rows"], f["sha256"]] for role, key in (("training", "train_files"),
                                                                        ("held-out", "validate_files"))
             for f in c[key]]
    out += "<h3>Data files</h3>" + _table(["role", "file", "rows", "SHA-256"], files, left=2)
    out += f'<p class="note">{_e(c["train_files_check"]["note"])}</p>'
    sw = c["software_at_calibration"] or c["software_now"]
    out += "<h3>Software</h3>" + _table(["package", "version"], [[k, v] for k, v in sw.items()], left=2)
    return out


def _parameters(d: dict) -> str:
    from pin_kpi_oed.report.html_parts import correlations_html, parameter_value as val

    p = d["parameters"]

    out = _table(["parameter", "value", "std"], [[r["name"], val(r["value"], r["unit"]),
                                                  val(r["std"], r["unit"]).lstrip("+")] for r in p["rows"]])
    cor = p["correlations"]
    out += correlations_html(cor)
    ident = p["identifiable"]
    out += f"<h3>Identifiable set</h3><p>{_e(ident['in_words'])}</p>"
    if ident["held_at_nominal"]:
        out += f"<p class=\"note\">Held at nominal: {_e(', '.join(ident['held_at_nominal']))}</p>"
    out += "<pre>" + _e("\n".join(ident["summary"])) + "</pre>"
    eff = p["effects"]
    out += "<h3>Effects</h3>" + (_table(["effect", "parameters", "values"], [[e["name"], ", ".join(e["param_names"]),
                                                                            ", ".join(f"{v:.4g}" for v in e["theta"])]
                                                                           for e in eff], left=2)
                                 if eff else "<p>None: geometry only.</p>")
    disc = p["discrepancy"]
    out += "<h3>Discrepancy</h3>" + (
        f"<p>{_e(disc.get('decision') or disc.get('kind'))}</p>" + _table(
            ["hyper-parameter", "value"], [["kind", disc.get("kind")], ["kernel", disc.get("kernel", "—")],
                                           ["scale per axis", ", ".join(mm(v, 4) for v in disc.get("scale_m") or [])],
                                           ["white level (normalised)", f"{disc.get('noise', float('nan')):.4g}"],
                                           ["training rows", disc.get("n_rows")]], left=2)
        if disc else "<p>None: the model's σ is the noise model's.</p>")
    return out


_STATS = (("n", "rows", None), ("mean_m", "mean", 1), ("rms_m", "RMS", 1), ("p95_m", "95th percentile", 1),
          ("max_m", "max", 1), ("mean_3sigma_m", "mean + 3σ", 1))


def _accuracy(d: dict) -> str:
    a = d["accuracy"]
    rows = [[label] + [a[k][key] if unit is None else mm(a[k][key]) for k in ("before", "after")]
            for key, label, unit in _STATS]
    rows += [[f"{ax}: mean / RMS / max |e|"] + [" / ".join(mm(a[k]["per_axis"][ax][f], 4) for f in
                                                         ("mean_m", "rms_m", "max_abs_m")) for k in ("before", "after")]
             for ax in "xyz"]
    if "rot_rms_rad" in a["after"] and "rot_rms_rad" in a["before"]:
        rows.append(["orientation RMS (6-D probe)"]
                    + [f"{a[k]['rot_rms_rad'] * 1e3:.4f} mrad" for k in ("before", "after")])
    out = f"<p>Before: {_e(a['before_means'])}. After: {_e(a['after_means'])}.</p>"
    if a["registration"]:
        r = a["registration"]
        out += (f"<p>Set-up re-registered on {r['n']} rows of {_e(r['source'])} (RMS {mm(r['rms_m'])}); the other rows "
                "are scored.</p>")
        out += "".join(f"<p class=\"note\">{_e(n)}</p>" for n in r.get("notes") or [])
    cov = a.get("coverage") or {}
    if cov.get("rows_covered") is not None:
        out += (f"<p class=\"note\">{cov['rows_covered'] * 100:.1f} % of the held-out rows lie within the training's "
                f"joint angles (±{cov.get('tol_rad', 0.05):g} rad on every joint).</p>")
    return out + _table(["3-D error", "before", "after"], rows)


def _iso(d: dict) -> str:
    iso = d["iso9283"]
    out = ""
    if "AP_vAP" in iso:
        rows = []
        for k in ("before", "after"):
            x = iso["AP_vAP"][k]
            rows.append([k, x["n_positions"], x["n_samples"], mm(x["AP"]["mean_m"]), mm(x["AP"]["max_m"]),
                         mm(x["vAP"]["mean_m"]), mm(x["vAP"]["max_m"]), x["vAP"]["n_positions"],
                         f"{x['vAP']['directions_mean']:.1f}" if x["vAP"]["directions_mean"] else "—"])
        out += _table(["model", "positions", "samples", "AP mean", "AP max", "vAP mean", "vAP max",
                       "positions with ≥ 2 directions", "directions per position"], rows)
        out += "".join(f"<p>AP per axis, mean over the positions ({k}): "
                       + ", ".join(f"{a} {mm(v)}" for a, v in zip("xyz", iso["AP_vAP"][k]["AP"]["per_axis_mean_m"]))
                       + "</p>" for k in ("before", "after"))
        out += f"<p class=\"note\">AP: {_e(iso['clauses']['AP'])}; vAP: {_e(iso['clauses']['vAP'])}.</p>"
    if "RP" in iso:
        r = iso["RP"]
        out += (f"<p>RP ({_e(iso['clauses']['RP'])}): {r['n_groups']} repeated configurations, "
                f"{r['n_samples']} samples;"
                f" median {mm(r['median_m'])}, max {mm(r['max_m'])}. {_e(r['note'])}.</p>")
    out += "".join(f"<p>{_e(s)}.</p>" for s in iso["statements"])
    return out


def _section(sid: str, title: str, d: dict, figs: dict) -> str:
    from pin_kpi_oed.report.html_parts import commanded_html, identity_html, summary_html, uncertainty_html

    if sid == "summary":
        body = summary_html(d)
    elif sid == "identity":
        body = identity_html(d)
    elif sid == "uncertainty":
        body = uncertainty_html(d)
    elif sid == "calibrated":
        body = _calibrated(d)
    elif sid == "parameters":
        body = _parameters(d) + _img(figs, "correlation", "correlations")
    elif sid == "accuracy":
        body = _accuracy(d) + _img(figs, "histogram", "error histogram") + _img(figs, "reach_joints", "error vs reach")
    elif sid == "fit_quality":
        q = d["fit_quality"]
        files = [f["name"] for h in d["calibrated"]["history"][-1:] for f in h.get("validate_files") or []]
        body = (f'<p class="verdict">{_e(q.get("message"))}</p>'
                '<p class="note">The verdict the calibrating command gave '
                f"on its training rows{' and ' + _e(', '.join(files)) if files else ''}.</p>")
    elif sid == "honest_sigma":
        h = d["honest_sigma"]
        body = ("<p>Predicted σ (3-D) mean {}; standardised error RMS {} (1 = honest); {} of the held-out rows inside "
                "their 95 % ellipsoid (95 % expected); {} outside the training coverage.</p>").format(
            mm(h["sigma_mean_m"]), f"{h['z_rms']:.2f}" if h["z_rms"] is not None else "—",
            f"{h['inside_95'] * 100:.1f} %" if h["inside_95"] is not None else "—",
            f"{(h['extrapolation_share'] or 0) * 100:.1f} %")
    elif sid == "tcp_sigma":
        t = d["tcp_sigma"]
        body = (f"<p>The TCP ({', '.join(mm(v, 2) for v in t['tcp_m'])}, tool frame"
                + ("" if t["stated"] else "; no cell or tool header stated it") + f"): predicted 3-D σ RMS "
                f"{mm(t['rms_m'])}, max {mm(t['max_m'])} at the {t['n']} {_e(t['where'])}, with the discrepancy, the "
                f"parameters and the joint-placement parameters held at nominal ({t['held_share'] * 100:.0f} % of "
                f"the variance, RMS {mm(t['held_rms_m'])}).</p>" + (f"<p class=\"note\">{_e(t['advice'])}.</p>"
                                                                   if t["advice"] else ""))
    elif sid == "trust_map":
        t = d["trust_map"]
        body = (f"<p>Predicted 3-D σ on the {t['n']} held-out rows: {mm(t['sigma_min_m'])} to {mm(t['sigma_max_m'])} "
                f"(median {mm(t['sigma_median_m'])}); {t['extrapolated']} rows outside the training coverage."
                + ("" if t["discrepancy"] else " The model has no discrepancy: σ is the noise model's.") + "</p>"
                + _img(figs, "trust_map", "trust map"))
    elif sid == "iso9283":
        body = _iso(d) + commanded_html(d["iso9283"]) + _img(figs, "iso_ap", "AP per position")
    elif sid == "diagnosis":
        g = d["diagnosis"]
        body = (f"<p>{_e(g.get('message'))}</p><pre>{_e(g.get('summary'))}</pre>" if g else
                "<p>The model did not come from <code>diagnose</code>: no diagnosis recorded.</p>")
    else:
        r = d["reproduce"]
        body = "".join(f"<p>Calibration: <code>{_e(c)}</code></p>" for c in r["calibration"]) or \
            "<p>The calibration command was not recorded.</p>"
        body += f"<p>This certificate: <code>{_e(r['report'])}</code></p>"
    return f'<section id="{sid}"><h2>{_e(title)}</h2>{body}</section>'


def render_html(cert: Certificate) -> str:
    """The certificate as one self-contained HTML page (a camera's: the sections of
    :data:`~pin_kpi_oed.report.camera.CAMERA_SECTIONS`)."""
    d = cert.data
    parts = [f"<!DOCTYPE html><html><head><meta charset=\"utf-8\"><title>{_e(d['title'])}</title><style>{_CSS}</style>"
             f"</head><body><h1>{_e(d['title'])}</h1>"]
    if d.get("device") == "camera":
        from pin_kpi_oed.report.camera import CAMERA_SECTIONS
        from pin_kpi_oed.report.camera_html import camera_section_html

        parts += [camera_section_html(sid, title, d) for sid, title in CAMERA_SECTIONS]
    else:
        parts += [_section(sid, title, d, cert.figures) for sid, title in SECTIONS]
    parts.append("</body></html>")
    return "".join(parts)
