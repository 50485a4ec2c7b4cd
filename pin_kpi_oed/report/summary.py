"""The certificate's first screen: the verdict and the headline figures, from the certificate's own data (SI)."""

from __future__ import annotations

__all__ = ["summary"]


def summary(data: dict) -> dict:
    """Verdict and headline figures of a certificate's data.

    Returns:
        ``status`` (certificate / draft and why), ``verdict`` (the conformity verdict, or the fit quality's when no
        accuracy is required), ``headline`` (label, value in m or a count, its U (k = 2) in m or None) rows.
    """
    acc, unc = data["accuracy"], data["uncertainty"]
    a, b = acc["after"], acc["before"]
    fu = unc["figures"]
    con = unc.get("conformity")
    ho = unc["held_out"]
    head = [("held-out rows", a["n"], None),
            ("RMS error before calibration", b["rms_m"], None),
            ("RMS error after calibration", a["rms_m"], fu["rms_m"]),
            ("95th percentile after calibration", a["p95_m"], fu["p95_m"]),
            ("largest error after calibration", a["max_m"], None),
            ("U (k = 2) of the TCP position, median at the working configurations", unc["budget"]["U_median_m"],
             None),
            ("held-out rows within their U", ho["within_U"], None)]
    if con is not None:
        verdict = {"text": f"{con['verdict']}: {con['figure_label']} {con['figure_m'] * 1e3:.3f} mm ± "
                           f"{con['U_m'] * 1e3:.3f} mm (k = 2) against the required {con['required_m'] * 1e3:.3f} mm"
                           + (f"; {con['at_tcp']}" if con.get("at_tcp") else ""),
                   "kind": con["verdict"]}
    else:
        verdict = {"text": "no required accuracy stated: no conformity statement "
                           f"(fit quality: {data['fit_quality'].get('verdict', 'not recorded')})", "kind": "none"}
    return {"status": data["identity"]["status"], "verdict": verdict,
            "headline": [{"label": lab, "value": v, "U_m": u} for lab, v, u in head],
            "repeats_removed": acc.get("repeats_removed", {}).get("removed", 0),
            "mode": acc["mode"]}
