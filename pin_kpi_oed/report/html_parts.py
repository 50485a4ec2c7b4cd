"""The certificate page's first screen (verdict and headline figures), identity, uncertainty budget and the ISO 9283
figures against the commanded poses, as HTML fragments (every number from the certificate's data, SI, printed in mm
with its unit)."""

from __future__ import annotations

import html
from typing import Any

__all__ = ["summary_html", "identity_html", "uncertainty_html", "commanded_html"]


def _e(x: Any) -> str:
    return html.escape(str(x))


def parameter_value(v: float, unit: str) -> str:
    """A parameter's value for display: m as mm, rad as mrad (signed, 4 decimals); other units as given."""
    if unit in ("m", "rad"):
        return f"{v * 1e3:+.4f} {'mm' if unit == 'm' else 'mrad'}"
    return f"{v:+.6g} {unit}"


def correlations_html(cor: list[dict]) -> str:
    """The strongest parameter correlations (|r| ≥ 0.9, at most 12) as one paragraph."""
    if not cor:
        return "<p>No two parameters correlate with |r| ≥ 0.9.</p>"
    return "<p>Strongest correlations (|r| ≥ 0.9): " + ", ".join(
        f"{_e(c['a'])} / {_e(c['b'])} ({c['r']:+.3f})" for c in cor[:12]) + "</p>"


def _mm(v: Any, digits: int = 3) -> str:
    return "—" if v is None else f"{float(v) * 1e3:.{digits}f} mm"


def _rows(rows: list[list[Any]]) -> str:
    return "<table>" + "".join("<tr>" + "".join(f'<td class="l">{_e(c)}</td>' if i == 0 else f"<td>{_e(c)}</td>"
                                               for i, c in enumerate(r)) + "</tr>" for r in rows) + "</table>"


def summary_html(d: dict) -> str:
    """The verdict box and the headline table."""
    s = d["summary"]
    st = s["status"]
    kind = s["verdict"]["kind"].replace(" ", "-")
    out = (f'<div class="status {st["kind"]}">{_e(st["kind"].upper())}: {_e(st["reason"])}</div>'
           f'<p class="verdict v-{kind}">{_e(s["verdict"]["text"])}</p>')
    rows = []
    for h in s["headline"]:
        v = h["value"]
        if isinstance(v, int):
            txt = f"{v:,}"
        elif "within" in h["label"]:
            txt = f"{v * 100:.1f} %"
        else:
            txt = _mm(v) + (f" ± {_mm(h['U_m'])}" if h["U_m"] is not None else "")
        rows.append([h["label"], txt])
    if s["repeats_removed"]:
        rows.append(["held-out rows removed: they repeat training configurations", f"{s['repeats_removed']:,}"])
    return out + _rows(rows)


def identity_html(d: dict) -> str:
    """Who, with what, when: the lab file's fields and what the data carry."""
    idn = d["identity"]
    lab = idn["lab"]
    rows = [["report made (UTC)", idn["report_time_utc"]]]
    if lab:
        ins = lab["instrument"]
        rows += [["organisation", lab["organisation"]], ["operator", lab["operator"]],
                 ["customer", lab["customer"]], ["robot serial", lab["robot_serial"]],
                 ["instrument", f"{ins['make']} {ins['model']}, serial {ins['serial']}"],
                 ["instrument calibration", f"{ins['calibration_date']}, certificate {ins['calibration_certificate']}"],
                 ["measured on", lab.get("measured_on", "— (not stated)")]]
        if "uncertainty_m" in ins:
            rows.append(["instrument uncertainty of a point (1 σ)", _mm(ins["uncertainty_m"], 4)])
    else:
        rows.append(["lab file", "none: organisation, operator, instrument, its calibration, robot serial and "
                                 "customer are not stated — this page is a draft"])
    rec = idn["data"]
    for role, r in rec["roles"].items():
        t = "—" if r["time_span_s"] is None else f"{r['time_span_s'] / 3600:.2f} h"
        T = "—" if r["temperature_c"] is None else f"{r['temperature_c'][0]:.2f} to {r['temperature_c'][1]:.2f} °C"
        rows.append([f"{role} rows: time span, temperature", f"{t}; {T}"])
    out = _rows(rows)
    if lab:
        out += ('<p class="note">Traceability: the positions were measured with the instrument above, whose '
                "calibration certificate is named; the uncertainty below states the chain from it to the TCP.</p>")
    out += "".join(f'<p class="note">{_e(x[0].upper() + x[1:])}.</p>' for x in rec["statements"])
    out += '<p class="sign">Signature: ________________________ &nbsp; Date: ____________</p>'
    return out


def _paths_html(paths: list) -> str:
    """U (k = 2) of the TCP along each working path: largest (where), median, the budget's shares, Monte-Carlo."""
    keys = [c["key"] for c in paths[0]["budget"]["contributions"]]
    labels = {c["key"]: c["label"] for c in paths[0]["budget"]["contributions"]}
    head = ("<tr><th class=\"l\">working path</th><th>samples</th><th>U largest (at arc length)</th><th>U median</th>"
            + "".join(f"<th>{_e(labels[k])}</th>" for k in keys) + "<th>Monte-Carlo / budget</th></tr>")
    body = ""
    for p in paths:
        sh = {c["key"]: c["share"] for c in p["budget"]["contributions"]}
        mc = p.get("monte_carlo")
        body += (f'<tr><td class="l">{_e(p["name"])}</td><td>{p["n"]}</td><td>{_mm(p["U_max_m"])} '
                 f'({p["s_at_max_m"] * 1e3:.0f} mm)</td><td>{_mm(p["U_median_m"])}</td>'
                 + "".join(f"<td>{sh[k] * 100:.1f} %</td>" for k in keys)
                 + f"<td>{'—' if mc is None else format(mc['median_ratio'], '.3f')}</td></tr>")
    return ("<p>Expanded uncertainty U (k = 2) of the TCP position along each working path of the cell (every "
            "sample; shares of u² averaged over the samples):</p><table>" + head + body + "</table>")


def uncertainty_html(d: dict) -> str:
    """The budget table, U at the working configurations, the held-out rows against U, conformity."""
    u = d["uncertainty"]
    b = u["budget"]
    out = (f"<p>Expanded uncertainty U (k = {b['k']:g}) of the TCP position at {_e(u['where'])}: median "
           f"{_mm(b['U_median_m'])}, 95th percentile {_mm(b['U_p95_m'])}, largest {_mm(b['U_max_m'])} "
           f"({b['n']} configurations; a 3-D error within U with probability {b['coverage_mean'] * 100:.1f} % under "
           "the budget's normal law).</p>")
    rows = [[c["label"], _mm(c["u_rms_m"], 4), f"{c['share'] * 100:.1f} %", c["note"]] for c in b["contributions"]]
    out += ("<table><tr><th class=\"l\">contribution</th><th>u (RMS over the configurations)</th><th>share of u²</th>"
            "<th class=\"l\">from</th></tr>" + "".join(
                "<tr>" + f'<td class="l">{_e(r[0])}</td><td>{_e(r[1])}</td><td>{_e(r[2])}</td>'
                f'<td class="l">{_e(r[3])}</td></tr>' for r in rows) + "</table>")
    h = u["held_out"]
    out += (f"<p>Held-out rows within their U: {h['within_U'] * 100:.1f} % of {h['n']} (the budget states "
            f"{h['coverage_stated'] * 100:.1f} %); per axis within U_a: {h['within_U_axis'] * 100:.1f} % "
            f"({h['coverage_axis'] * 100:.1f} % stated).</p>")
    if "monte_carlo" in u:
        m = u["monte_carlo"]
        out += (f"<p>Monte-Carlo check ({m['n']} draws of the parameters and the discrepancy): sampled / budget u, "
                f"median {m['median_ratio']:.3f} (5–95 %: {m['ratio_p5']:.3f}–{m['ratio_p95']:.3f}).</p>")
    f = u["figures"]
    out += (f"<p>Uncertainty of the held-out figures (k = 2, {f['n']} rows): RMS ± {_mm(f['rms_m'], 4)}, mean ± "
            f"{_mm(f['mean_m'], 4)}, 95th percentile ± {_mm(f['p95_m'], 4)}.</p><p class=\"note\">{_e(f['note'])}"
            + (f"; {_e(u['paths'])}.</p>" if isinstance(u["paths"], str) else ".</p>" + _paths_html(u["paths"])))
    c = u.get("conformity")
    if c:
        out += (f'<p class="verdict">Conformity: {_e(c["verdict"])} — {_e(c["figure_label"])} {_mm(c["figure_m"])} ± '
                f'{_mm(c["U_m"])} against {_mm(c["required_m"])}'
                + (f'; {_e(c["at_tcp"])}' if c.get("at_tcp") else "") + f'.</p><p class="note">{_e(c["rule"])}.</p>')
    else:
        out += "<p>No required accuracy was stated: no conformity statement.</p>"
    return out


def commanded_html(iso: dict) -> str:
    """ISO 9283 against the commanded poses, and the label of the model-prediction variant."""
    out = f"<p class=\"note\">AP, vAP and RP in the table above: the {_e(iso['variant'])}.</p>"
    c = iso.get("commanded")
    if c is None:
        return out + "<p>The rows carry no commanded poses: no figures against them.</p>"
    out += f"<h3>Against the commanded poses</h3><p class=\"note\">{_e(c['frame'])}.</p>"
    if "AP_vAP" in c:
        x = c["AP_vAP"]
        out += _rows([[f"commanded positions (goals within {iso['goal_radius_m'] * 1e3:g} mm of the first), samples",
                       f"{x['n_positions']}, {x['n_samples']}"],
                      ["AP mean / max", f"{_mm(x['AP']['mean_m'])} / {_mm(x['AP']['max_m'])}"],
                      ["vAP mean / max (positions with ≥ 2 directions)",
                       f"{_mm(x['vAP']['mean_m'])} / {_mm(x['vAP']['max_m'])} ({x['vAP']['n_positions']})"]])
    if c.get("RP"):
        r = c["RP"]
        out += (f"<p>RP per commanded position and direction (≥ 3 rows): {r['n_groups']} groups, {r['n_samples']} "
                f"samples, median {_mm(r['median_m'])}, max {_mm(r['max_m'])}.</p>")
    if c.get("drift"):
        g = c["drift"]
        out += (f"<p>Drift dAP (first and last row of a position, up to {g['span_s'] / 3600:.2f} h apart): mean "
                f"{_mm(g['mean_m'])}, max {_mm(g['max_m'])} over {g['n_positions']} positions.</p>")
    return out + "".join(f"<p>{_e(s[0].upper() + s[1:])}.</p>" for s in c["statements"])
