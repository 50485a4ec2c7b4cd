r"""The certificate of a camera calibration: the same page machinery as the tracker's, the figures a camera has.

A camera measures board corners in pixels, never the TCP's position: a camera's certificate states

* **identity** and **provenance** as the tracker's (:mod:`pin_kpi_oed.report.lab`: a draft without a lab file; the
  robot, URDF SHA-256, the camera and board, the data files with their SHA-256 checked against those the model file
  recorded, versions, commands);
* **the fit**: the reprojection RMS (px) on the training images and on held-out images, the reduced χ²;
* **the hand-eye transform and the board pose** with the σ of their six parameters (translation m, rotation rad);
* **the TCP's expanded uncertainty** U = 2 σ (k = 2) at the working configurations, σ the one σ at the TCP
  (:func:`~pin_kpi_oed.calibrated.tcp_sigma.tcp_sigma`, what ``predict --at tcp`` prints), with its budget: the
  fitted parameters' share (E C_p Eᵀ) and the share of the joint placements held at nominal (G Σ_N Gᵀ: no image of
  the board determines them, the fitted pose of the part on the tool absorbs them; only a measurement of the TCP
  removes them); with ``mc_draws`` its Monte-Carlo check (:func:`camera_monte_carlo`);
* **conformity** (ISO 14253-1, :func:`~pin_kpi_oed.report.uncertainty.conformity`): the TCP's position error,
  estimated 0 by the calibrated model (no TCP measured), with the largest U at the working configurations, against
  the required accuracy;
* the tracker's sections that do not apply (accuracy on held-out positions, ISO 9283 AP / vAP / RP, the honest σ
  and trust map of measured positions), each stated in one line.

Every number is SI in the returned dict (pixels in px); the HTML (:mod:`pin_kpi_oed.report.camera_html`) prints mm.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from pin_kpi_oed.errors import InputError
from pin_kpi_oed.report.content import CERTIFICATE_FORMAT, Certificate, CertificateOptions

__all__ = ["build_camera_certificate", "camera_monte_carlo", "CAMERA_SECTIONS", "NOT_APPLICABLE"]

#: The camera certificate's sections, in order: (id, title).
CAMERA_SECTIONS = (("summary", "Summary"), ("identity", "Identity and traceability"),
                   ("calibrated", "What was calibrated"), ("fit", "Fit on the board images"),
                   ("camera_setup", "Hand-eye transform and board"), ("parameters", "Parameters"),
                   ("uncertainty", "Uncertainty at the TCP (GUM)"), ("not_applicable", "Sections that do not apply"),
                   ("reproduce", "Reproduce"))
#: The tracker certificate's sections a camera's does not have, each with its one line.
NOT_APPLICABLE = {
    "accuracy": "Accuracy on held-out positions: not applicable — a camera measures board corners in pixels, not "
                "the TCP's position; the held-out figure is the reprojection RMS (section 'Fit on the board images')",
    "iso9283": "ISO 9283 AP / vAP / RP: not applicable — they need measured positions of commanded poses, and a "
               "camera measures none",
    "honest_sigma": "Honest sigma and trust map of measured positions: not applicable — no position was measured; "
                    "the held-out images' reprojection RMS against the training's says whether the fit holds",
    "diagnosis": "Diagnosis: not applicable — diagnose scores a tracker's positions"}


def _reprojection(model: Any, p: np.ndarray, path: str) -> tuple[Any, dict]:
    """The corners of ``path`` and their reprojection figures with the calibrated camera: images, detected corners,
    RMS (px) over the detected coordinates."""
    from pin_kpi_oed.data.corner_measurements import read_corners

    cs = read_corners(path)
    labels, Q, uv = cs.arrays(model.board.n, path)
    if sorted(cs.joint_names) != sorted(model.robot.joint_names):
        raise InputError(f"{path}: joint columns {', '.join(cs.joint_names)} are not the model's robot's "
                         f"({', '.join(model.robot.joint_names)})")
    Q = model.robot.check_q(Q[:, [cs.joint_names.index(n) for n in model.robot.joint_names]], path)
    r = model.predict(p, Q) - uv
    ok = np.isfinite(r)
    return cs, {"images": len(labels), "corners": int(ok.sum() // 2), "rms_px": float(np.sqrt(np.mean(r[ok] ** 2)))}


def _pose(T: Any, std: dict, group: str) -> dict:
    """A fitted pose (4 × 4) as xyz (m) and rpy (rad) with the σ of its six parameters ``group.tx .. group.rz``."""
    import pinocchio as pin

    T = np.asarray(T, float)
    sig = [std.get(f"{group}.{c}") for c in ("tx", "ty", "tz", "rx", "ry", "rz")]
    return {"xyz_m": T[:3, 3].tolist(), "rpy_rad": pin.rpy.matrixToRpy(T[:3, :3]).tolist(),
            "sigma_t_m": sig[:3], "sigma_r_rad": sig[3:], "estimated": all(s is not None for s in sig)}


def _camera_setup(cm: Any, dev: dict) -> dict:
    """The hand-eye transform and the board pose as fitted, with their σ (the fit's covariance)."""
    P = cm.parameters or {}
    std = dict(zip(P.get("names") or [], (float(s) for s in P.get("std", []))))
    eih = dev.get("mode", "eye_in_hand") == "eye_in_hand"
    # the fixed device frame is stored as the station's set-up (tracker.*), the part on the tool under its own name
    cam_group, board_group = ("camera", "tracker") if eih else ("tracker", "board")
    return {"mode": dev.get("mode"),
            "hand_eye": {"means": "tool_T_camera: the camera in the tool frame" if eih else
                         "camera_T_base: the robot base in the camera frame",
                         **_pose(dev["fitted_camera_pose"], std, cam_group)},
            "board": {"means": "board_T_base: the robot base in the board frame" if eih else
                      "tool_T_board: the board in the tool frame",
                      **_pose(dev["fitted_board_pose"], std, board_group)},
            "note": "σ of the pose's six parameters (a right perturbation exp6(δ): translation m, rotation rad) from "
                    "the fit's covariance of the pixel noise"}


def _axial(robot: Any, name: str) -> bool:
    """Whether a held parameter is the last joint's translation along its own axis (the flange's axial offset)."""
    from pin_kpi_oed.model.kinematics import joint_motion_axes

    joint, _, comp = name.partition(".")
    if joint != robot.joint_names[-1] or not comp.startswith("t"):
        return False
    _, ang = joint_motion_axes(robot.model, [robot.model.getJointId(joint)])
    return int(np.argmax(np.abs(ang[0]))) == "xyz".index(comp[1])


def _tcp_uncertainty(cm: Any, Q: np.ndarray, where: str, mounted: str) -> dict:
    """U (k = 2) of the TCP at configurations Q from the one σ at the TCP, its budget and the held parameters."""
    from pin_kpi_oed.calibrated.tcp_sigma import tcp_sigma
    from pin_kpi_oed.report.uncertainty import COVERAGE_FACTOR

    ts = tcp_sigma(cm, Q)
    k = COVERAGE_FACTOR
    Cp = ts.covariance_m2 - ts.held_m2
    u_p = np.sqrt(np.maximum(np.einsum("maa->m", Cp), 0.0))
    top = [int(i) for i in np.argsort(-ts.held_contrib_m)[:3] if ts.held_contrib_m[i] > 0.05 * ts.held_contrib_m.max()]
    held = [{"name": ts.held_names[i], "u_rms_m": float(ts.held_contrib_m[i]),
             "axial": _axial(cm.robot, ts.held_names[i])} for i in top]
    axial = next((h["name"] for h in held if h["axial"]), None)
    what = ("held at nominal, mostly " + (f"the flange's axial offset ({axial})" if axial else
                                           "the joint placements " + ", ".join(str(h["name"]) for h in held)))
    return {"k": k, "where": where, "n": int(len(Q)), "frame": f"the {cm.station(None)} station's device frame",
            "tcp_m": ts.tcp_m.tolist(), "U_m": (k * ts.sigma_m).tolist(), "sigma_m": ts.sigma_m.tolist(),
            "U_median_m": float(k * np.median(ts.sigma_m)), "U_max_m": float(k * ts.sigma_m.max()),
            "contributions": [
                {"key": "parameters", "label": "fitted parameters (E C_p Eᵀ)", "share": float(1.0 - ts.held_share),
                 "u_rms_m": float(np.sqrt(np.mean(u_p ** 2))),
                 "note": "the robot's joint placements, the hand-eye transform and the board fitted on the images: "
                         "the pixel noise through the fit"},
                {"key": "held", "label": "joint placements held at nominal (G Σ_N Gᵀ)", "share": float(ts.held_share),
                 "u_rms_m": float(np.sqrt(np.mean(ts.held_sigma_m ** 2))),
                 "note": "their tolerances, absorbed by the fitted " + mounted + " pose on the tool"}],
            "held": held, "held_share": float(ts.held_share),
            "held_statement": (f"{ts.held_share * 100:.0f} % of the TCP's variance is {what}: no image of the board "
                               f"determines it, the fitted {mounted} pose on the tool absorbs it; only a measurement "
                               "of the TCP (a tool calibration) removes it") if held else
            "no joint placement held at nominal moves the TCP"}


def camera_monte_carlo(cm: Any, Q: np.ndarray, n: int = 2000, seed: int = 0) -> dict:
    """Monte-Carlo check of the TCP's σ: truths drawn around the calibration and the TCP's error computed through the
    camera's own kinematics (the TCP of :meth:`~pin_kpi_oed.model.camera.CameraModel.kpi` at each drawn truth,
    batched over the draws by :meth:`~pin_kpi_oed.model.device.MeasurementModel.sensor_points`; not the Jacobians the
    budget uses).

    A draw: the held joint placements δN ~ N(0, Σ_N) (their tolerances), the fit's error ε ~ N(0, C_p); the truth is
    the fitted parameters with N += δN and the estimated ones −= A δN + ε (the fit moved its estimate by A δN, stored
    absorption A). The sampled σ = sqrt(tr cov(true − predicted TCP)) per configuration.

    Args:
        cm: a camera's calibrated model; Q: configurations (t, n) rad; n: draws; seed: their seed.

    Returns:
        ``n``, ``sigma_m`` (t,) m the sampled σ, ``ratio`` (t,) sampled / the budget's σ
        (:func:`~pin_kpi_oed.calibrated.tcp_sigma.tcp_sigma`), ``median_ratio``.
    """
    from pin_kpi_oed.calibrated.tcp_sigma import tcp_sigma
    from pin_kpi_oed.identification.camera_identify import camera_model_of

    model, p0 = camera_model_of(cm)
    P = cm.parameters or {}
    L = model.layout.names
    frame = model.frame_group
    col = [L.index(f"{frame}.{s.split('.', 1)[1]}" if s.startswith("tracker.") else s) for s in P["names"]]
    rng = np.random.default_rng(seed)
    eps = rng.multivariate_normal(np.zeros(len(col)), np.asarray(P["covariance"], float), size=n,
                                  method="eigh")
    held = P.get("held") or {}
    hcol = [L.index(h) for h in held.get("names", [])]
    A = np.asarray(held.get("absorption", np.zeros((len(col), 0))), float).reshape(len(col), len(hcol))
    dN = rng.standard_normal((n, len(hcol))) * np.asarray(held.get("sigma", []), float)
    Q = np.atleast_2d(np.asarray(Q, float))
    y0 = model.kpi(p0, Q)
    Pd = np.repeat(p0[None], n, axis=0)  # the drawn truths, one row a draw
    Pd[:, hcol] += dN
    Pd[:, col] -= dN @ A.T + eps
    E = np.empty((n, len(Q), 3))
    step = max(1, 20000 // len(Q))  # draws per batched pass (bounded memory)
    for i in range(0, n, step):
        E[i:i + step] = model.sensor_points(Pd[i:i + step], Q, model.tcp_m) - y0
    s = np.sqrt(np.sum(np.var(E, axis=0, ddof=1), axis=1))
    ratio = s / tcp_sigma(cm, Q).sigma_m
    return {"n": int(n), "sigma_m": s.tolist(), "ratio": ratio.tolist(), "median_ratio": float(np.median(ratio))}


def _records(paths: Sequence[str], counts: Sequence[int]) -> list[dict]:
    from pin_kpi_oed.data.provenance import file_record

    return [file_record(p, c) for p, c in zip(paths, counts)]


def _calibrated(cm: Any, dev: dict, model_path: str, files: dict, checked: dict) -> dict:
    from pin_kpi_oed.data.provenance import sha256_of, software_versions
    from pin_kpi_oed.report.content import robot_identity

    step = (cm.history or [{}])[-1]
    return {**robot_identity(cm), "tcp_stated_by": cm.tool_source or None, "camera": dev.get("camera"),
            "board": dev.get("board"),
            "mode": dev.get("mode"), "sigma_px": dev.get("sigma_px"),
            "model_file": {"path": str(model_path), "sha256": sha256_of(model_path)},
            "train_files": files["train"], "validate_files": files["validate"], "train_files_check": checked,
            "software_at_calibration": step.get("software"), "software_now": software_versions(),
            "history": [{k: v for k, v in h.items() if k != "software"} for h in cm.history]}


def _sha256_text(text: str) -> str:
    import hashlib

    return hashlib.sha256(text.encode()).hexdigest()


def _parameters(cm: Any) -> dict:
    from pin_kpi_oed.report.content import correlations

    P = cm.parameters or {}
    names = list(P.get("names") or [])
    rows = [{"name": n, "value": float(v), "std": float(s), "unit": u}
            for n, v, s, u in zip(names, P.get("values", []), P.get("std", []), P.get("units", [""] * len(names)))]
    held = (P.get("held") or {}).get("names") or []
    dev = _mode(cm)
    fixed = "board" if dev == "eye_in_hand" else "camera"
    return {"rows": rows, "correlations": correlations(names, P.get("covariance")), "held_at_nominal": list(held),
            "in_words": f"{len(names)} parameters estimated on the images (joint placements, the hand-eye transform "
                        f"and the board); {len(held)} joint-placement parameters held at nominal under their "
                        "tolerances: the images cannot tell them from the hand-eye transform, whose fitted value "
                        "absorbs them; at the TCP they enter its sigma (section 'Uncertainty at the TCP'); "
                        f"tracker.* are the {fixed} pose (the fixed device frame, stored as the station's set-up as "
                        "a tracker's pose is)"}


def _mode(cm: Any) -> str:
    """``eye_in_hand`` or ``eye_to_hand``: the mount of the camera a model was identified with."""
    return str(((cm.fit or {}).get("device") or {}).get("mode", "eye_in_hand"))


def _work(cm: Any, o: CertificateOptions, Q_held_out: np.ndarray) -> tuple[np.ndarray, str]:
    if o.work_q is not None:
        return np.asarray(o.work_q, float), "the working configurations given (joint-space program)"
    if cm.q_work is not None and len(cm.q_work):
        return np.asarray(cm.q_work, float), "the model's working configurations (its cell's)"
    return Q_held_out, "the held-out images' configurations (the model names no working configurations)"


def build_camera_certificate(model_path: str, train_paths: Sequence[str], validate_path: str | None, *,
                             command: str = "", options: CertificateOptions | None = None,
                             seed: int = 0) -> Certificate:
    """Collect a camera calibration's certificate (module docstring).

    Args:
        model_path: the model file ``identify --cell CAMERA_CELL`` wrote.
        train_paths: the one corner file it was calibrated on (checked against the recorded SHA-256).
        validate_path: held-out corner file (required: the certificate states the held-out reprojection RMS).
        command: the ``report`` command line (printed in the certificate).
        options: the lab file, the required accuracy (m, of the TCP's position), the working configurations,
            ``mc_draws`` (:class:`~pin_kpi_oed.report.content.CertificateOptions`; the ISO 9283 and tracker options
            do not apply).
        seed: the seed of the Monte-Carlo draws.

    Returns:
        The :class:`~pin_kpi_oed.report.content.Certificate` (``data["device"] == "camera"``), no figures.

    Raises:
        InputError: no held-out file, several training files, a model not identified with a camera, training files
            other than the recorded ones, the held-out file one of them, bad corner files, a bad lab file.
    """
    from pin_kpi_oed.calibrated.model_file import load_model_file
    from pin_kpi_oed.identification.camera_identify import camera_device, camera_model_of
    from pin_kpi_oed.report.content import check_recorded
    from pin_kpi_oed.report.lab import read_lab, status

    if not validate_path:
        raise InputError("a certificate states the fit on images it was not fitted on: give validate_path='FILE' "
                         "(held-out corner file)")
    if len(train_paths) != 1:
        raise InputError(f"train_paths: a camera calibration is fitted on one corner file, got {len(train_paths)}")
    cm = load_model_file(model_path)
    dev = camera_device(cm)
    if dev is None:
        raise InputError(f"{model_path}: not a camera's model (its fit names no camera), but {train_paths[0]} holds "
                         "camera measurements")
    o = options or CertificateOptions()
    lab = read_lab(o.lab_path) if o.lab_path else None
    model, p = camera_model_of(cm)
    cs_t, fit_t = _reprojection(model, p, train_paths[0])
    cs_v, fit_v = _reprojection(model, p, validate_path)
    files = {"train": _records(train_paths, [len(cs_t)]), "validate": _records([validate_path], [len(cs_v)])}
    if files["train"][0]["sha256"] == files["validate"][0]["sha256"]:
        raise InputError(f"{validate_path}: the held-out file is the training file: give images the model was not "
                         "fitted on")
    checked = check_recorded(cm, files["train"], str(model_path))
    f = cm.fit or {}
    fit = {"training": {**fit_t, "rms_px_recorded": f.get("rms_px")}, "held_out": fit_v,
           "chi2_reduced": f.get("chi2_reduced"), "sigma_px": dev.get("sigma_px"), "loss": f.get("loss"),
           "held_out_over_training": fit_v["rms_px"] / fit_t["rms_px"] if fit_t["rms_px"] > 0 else None}
    Qv = _configurations(cs_v, model)
    Q, where = _work(cm, o, Qv)
    unc = _tcp_uncertainty(cm, Q, where, model.target_groups[0])
    if o.mc_draws:
        unc["monte_carlo"] = camera_monte_carlo(cm, Q, o.mc_draws, seed)
    unc["conformity"] = _conformity(unc, o.required_accuracy_m)
    st = status(lab)
    data = {"format": CERTIFICATE_FORMAT, "device": "camera",
            "title": (f"Calibration certificate: {cm.robot.name} (camera)" if st["kind"] == "certificate" else
                      f"DRAFT — not a certificate: {cm.robot.name} (camera)"),
            "identity": {"status": st, "lab": lab, "data": _data_record(fit_t, fit_v), "report_time_utc": _now()},
            "calibrated": _calibrated(cm, dev, model_path, files, checked), "fit": fit,
            "camera_setup": _camera_setup(cm, dev), "parameters": _parameters(cm), "uncertainty": unc,
            "not_applicable": dict(NOT_APPLICABLE),
            "reproduce": {"calibration": [h.get("command") for h in cm.history if h.get("command")],
                          "report": command}}
    data["summary"] = _summary(data)
    return Certificate(data)


def _configurations(cs: Any, model: Any) -> np.ndarray:
    _, Q, _ = cs.arrays(model.board.n)
    return Q[:, [cs.joint_names.index(n) for n in model.robot.joint_names]]


def _conformity(unc: dict, required_m: float | None) -> dict | None:
    """ISO 14253-1 on the TCP's position error: estimated 0 (no TCP measured), U the largest at the configurations."""
    from pin_kpi_oed.report.uncertainty import conformity

    if required_m is None:
        return None
    out = conformity(0.0, unc["U_max_m"], required_m)
    out["figure"] = "tcp_error_m"
    out["figure_label"] = ("TCP position error at the working configurations (the calibrated model's estimate 0: no "
                           "TCP measured; U the largest there)")
    return out


def _data_record(fit_t: dict, fit_v: dict) -> dict:
    """What the corner files carry: images and corners per role; they carry no time nor temperature."""
    return {"roles": {"training": {"rows": fit_t["corners"], "images": fit_t["images"], "time_span_s": None,
                                   "temperature_c": None},
                      "held-out": {"rows": fit_v["corners"], "images": fit_v["images"], "time_span_s": None,
                                   "temperature_c": None}},
            "statements": ["the corner files carry no time nor temperature"], "temperature_c": None}


def _summary(data: dict) -> dict:
    fit, unc = data["fit"], data["uncertainty"]
    con = unc.get("conformity")
    head = [("training images, held-out images", f"{fit['training']['images']}, {fit['held_out']['images']}"),
            ("reprojection RMS on the training images", f"{fit['training']['rms_px']:.3f} px"),
            ("reprojection RMS on the held-out images", f"{fit['held_out']['rms_px']:.3f} px"),
            ("reduced χ² of the fit", "—" if fit["chi2_reduced"] is None else f"{fit['chi2_reduced']:.3f}"),
            (f"U (k = 2) of the TCP position, median at {unc['n']} configurations", unc["U_median_m"]),
            ("U (k = 2) of the TCP position, largest", unc["U_max_m"]),
            ("share of the TCP's variance held at nominal (only a TCP measurement removes it)",
             f"{unc['held_share'] * 100:.1f} %")]
    if con is not None:
        verdict = {"text": f"{con['verdict']}: the TCP position's U {con['U_m'] * 1e3:.3f} mm (k = 2, largest at the "
                           f"working configurations) against the required {con['required_m'] * 1e3:.3f} mm",
                   "kind": con["verdict"]}
    else:
        verdict = {"text": "no required accuracy stated: no conformity statement", "kind": "none"}
    return {"status": data["identity"]["status"], "verdict": verdict,
            "headline": [{"label": lab, "value": v, "U_m": None} for lab, v in head], "repeats_removed": 0}


def _now() -> str:
    import datetime as dt

    return dt.datetime.now(dt.timezone.utc).replace(microsecond=0).isoformat()
