"""A camera calibration's certificate as HTML fragments, one per entry of
:data:`~pin_kpi_oed.report.camera.CAMERA_SECTIONS` (every number from the certificate's data, SI, printed in mm,
mrad, degrees or px with its unit); the page around them is :func:`~pin_kpi_oed.report.html.render_html`'s."""

from __future__ import annotations

import html
from typing import Any

import numpy as np

__all__ = ["camera_section_html"]


def _e(x: Any) -> str:
    return html.escape(str(x))


def _mm(v: Any, digits: int = 4) -> str:
    return "—" if v is None else f"{float(v) * 1e3:.{digits}f} mm"


def _rows(rows: list[list[Any]], header: list[str] | None = None, left: int = 1) -> str:
    th = ("<tr>" + "".join(f'<th class="l">{_e(h)}</th>' if i < left else f"<th>{_e(h)}</th>"
                           for i, h in enumerate(header)) + "</tr>") if header else ""
    return "<table>" + th + "".join("<tr>" + "".join(f'<td class="l">{_e(c)}</td>' if i < left else f"<td>{_e(c)}</td>"
                                                     for i, c in enumerate(r)) + "</tr>" for r in rows) + "</table>"


def _summary(d: dict) -> str:
    s = d["summary"]
    st = s["status"]
    kind = s["verdict"]["kind"].replace(" ", "-")
    rows = [[h["label"], h["value"] if isinstance(h["value"], str) else _mm(h["value"], 3)] for h in s["headline"]]
    return (f'<div class="status {st["kind"]}">{_e(st["kind"].upper())}: {_e(st["reason"])}</div>'
            f'<p class="verdict v-{kind}">{_e(s["verdict"]["text"])}</p>' + _rows(rows))


def _calibrated(d: dict) -> str:
    c = d["calibrated"]
    cam = c.get("camera") or {}
    board = c.get("board") or {}
    rows = [["robot", c["robot"]], ["URDF", c["urdf_path"]], ["URDF SHA-256", c["urdf_sha256"]],
            ["kinematics hash", c["kinematics_hash"] or "— (the URDF's own kinematics)"],
            ["tool frame", c["tool_frame"]],
            ["TCP in the tool frame", ", ".join(_mm(v, 2) for v in c["tcp_m"])
             + (f" (stated by {c['tcp_stated_by']})" if c.get("tcp_stated_by") else "")],
            ["camera", f"{c['mode']}; pixel noise {c['sigma_px']:g} px (weights of the fit)"],
            ["camera description", ", ".join(f"{k}: {v}" for k, v in cam.items() if k != "view")],
            ["board", ", ".join(f"{k}: {v}" for k, v in board.items())],
            ["model file", f"{c['model_file']['path']} (SHA-256 {c['model_file']['sha256']})"]]
    out = _rows(rows, left=2)
    files = [[role, f["path"], f["rows"], f["sha256"]] for role, key in (("training", "train_files"),
                                                                        ("held-out", "validate_files"))
             for f in c[key]]
    out += "<h3>Data files (one row per detected corner)</h3>" + _rows(files, ["role", "file", "rows", "SHA-256"], 2)
    out += f'<p class="note">{_e(c["train_files_check"]["note"])}</p>'
    sw = c["software_at_calibration"] or c["software_now"]
    return out + "<h3>Software</h3>" + _rows([[k, v] for k, v in sw.items()], ["package", "version"], 2)


def _identity(d: dict) -> str:
    from pin_kpi_oed.report.html_parts import identity_html

    return identity_html(d).replace("the positions were measured with the instrument above",
                                    "the board images were taken with the camera above")


def _fit(d: dict) -> str:
    f = d["fit"]
    t, v = f["training"], f["held_out"]
    rows = [["training", t["images"], t["corners"], f"{t['rms_px']:.4f} px"],
            ["held-out", v["images"], v["corners"], f"{v['rms_px']:.4f} px"]]
    chi = "—" if f["chi2_reduced"] is None else f"{f['chi2_reduced']:.3f}"
    ratio = f["held_out_over_training"]
    return (_rows(rows, ["images", "count", "corners detected", "reprojection RMS"], 1)
            + f"<p>Reduced χ² of the fit {chi} (1 when the stated pixel noise {f['sigma_px']:g} px is the residual's); "
              f"held-out RMS / training RMS {'—' if ratio is None else format(ratio, '.3f')} (near 1: the fit holds on "
              f"images it was not fitted on). Loss: {_e(f['loss'])}.</p>"
              '<p class="note">Reprojection RMS: over the detected corners\' u and v coordinates, the calibrated '
              "model's pixels against the detected ones.</p>")


def _pose_row(name: str, p: dict) -> list[Any]:
    st = "—" if not p["estimated"] else ", ".join(_mm(s, 4) for s in p["sigma_t_m"])
    sr = "—" if not p["estimated"] else ", ".join(f"{s * 1e3:.4f} mrad" for s in p["sigma_r_rad"])
    return [name, p["means"], ", ".join(f"{x:.5f}" for x in p["xyz_m"]) + " m",
            ", ".join(f"{np.degrees(a):.4f}" for a in p["rpy_rad"]) + " deg", st, sr]


def _camera_setup(d: dict) -> str:
    c = d["camera_setup"]
    return (_rows([_pose_row("hand-eye transform", c["hand_eye"]), _pose_row("board pose", c["board"])],
                  ["pose", "meaning", "xyz", "rpy", "σ translation (x, y, z)", "σ rotation (x, y, z)"], 2)
            + f'<p class="note">{_e(c["note"])}.</p>')


def _parameters(d: dict) -> str:
    from pin_kpi_oed.report.html_parts import correlations_html, parameter_value as val

    p = d["parameters"]

    out = f"<p>{_e(p['in_words'])}.</p>" + _rows([[r["name"], val(r["value"], r["unit"]),
                                                    val(r["std"], r["unit"]).lstrip("+")] for r in p["rows"]],
                                                  ["parameter", "value", "std"])
    cor = p["correlations"]
    out += correlations_html(cor)
    if p["held_at_nominal"]:
        out += f"<p class=\"note\">Held at nominal: {_e(', '.join(p['held_at_nominal']))}</p>"
    return out


def _uncertainty(d: dict) -> str:
    u = d["uncertainty"]
    out = (f"<p>Expanded uncertainty U (k = {u['k']:g}) of the TCP position ({', '.join(_mm(v, 2) for v in u['tcp_m'])}"
           f", tool frame) in {_e(u['frame'])} at {_e(u['where'])}: median {_mm(u['U_median_m'])}, largest "
           f"{_mm(u['U_max_m'])} ({u['n']} configurations; U = 2 σ, σ the one σ at the TCP that "
           "<code>predict --at tcp</code> states).</p>")
    out += _rows([[c["label"], _mm(c["u_rms_m"]), f"{c['share'] * 100:.1f} %", c["note"]] for c in u["contributions"]],
                 ["contribution", "u (RMS over the configurations)", "share of u²", "from"])
    out += _rows([[f"configuration {i + 1}", _mm(x)] for i, x in enumerate(u["U_m"])], ["where", "U (k = 2)"])
    if u["held"]:
        out += _rows([[h["name"], _mm(h["u_rms_m"]), "yes" if h["axial"] else "no"] for h in u["held"]],
                     ["held parameter", "its σ at the TCP (RMS)", "the flange's axial offset"])
    out += f'<p class="verdict">{_e(u["held_statement"])}.</p>'
    if "monte_carlo" in u:
        m = u["monte_carlo"]
        out += (f"<p>Monte-Carlo check ({m['n']} draws of the fitted parameters from their covariance and of the held "
                f"joint placements from their tolerances, the TCP through the camera model's kinematics): sampled / "
                f"budget σ, median {m['median_ratio']:.3f} (per configuration: "
                + ", ".join(f"{r:.3f}" for r in m["ratio"]) + ").</p>")
    c = u.get("conformity")
    if c:
        out += (f'<p class="verdict">Conformity: {_e(c["verdict"])} — {_e(c["figure_label"])}: '
                f'{_mm(c["figure_m"])} ± {_mm(c["U_m"])} against {_mm(c["required_m"])}.</p>'
                f'<p class="note">{_e(c["rule"])}; without a measured TCP non-conformity cannot be shown.</p>')
    else:
        out += "<p>No required accuracy was stated: no conformity statement.</p>"
    return out


def _not_applicable(d: dict) -> str:
    return "".join(f"<p>{_e(line)}.</p>" for line in d["not_applicable"].values())


def _reproduce(d: dict) -> str:
    r = d["reproduce"]
    body = "".join(f"<p>Calibration: <code>{_e(c)}</code></p>" for c in r["calibration"]) or \
        "<p>The calibration command was not recorded.</p>"
    return body + f"<p>This certificate: <code>{_e(r['report'])}</code></p>"


_PARTS = {"summary": _summary, "identity": _identity, "calibrated": _calibrated, "fit": _fit,
          "camera_setup": _camera_setup, "parameters": _parameters, "uncertainty": _uncertainty,
          "not_applicable": _not_applicable, "reproduce": _reproduce}


def camera_section_html(sid: str, title: str, d: dict) -> str:
    """One ``<section id=...>`` of a camera certificate (``sid`` of
    :data:`~pin_kpi_oed.report.camera.CAMERA_SECTIONS`)."""
    return f'<section id="{sid}"><h2>{_e(title)}</h2>{_PARTS[sid](d)}</section>'
