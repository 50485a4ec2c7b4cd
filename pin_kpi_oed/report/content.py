r"""The content of a calibration certificate: what was calibrated, the parameters, the accuracy, its honesty.

:func:`build_certificate` reads a model file, its training and held-out measurement files, and collects — from
the library's own functions, never recomputed another way — every figure the certificate shows:

* **calibrated**: robot, URDF (SHA-256 of its text) and kinematics hash, tool frame, stations with their
  set-ups (tracker pose, reflector), TCP, the data files (rows, SHA-256; checked against the ones the model
  file recorded), the model file's SHA-256, software versions, the commands that reproduce it;
* **parameters**: values, standard deviations, the strongest correlations, the identifiable set in words
  (:func:`~pin_kpi_oed.oed.identifiability.analyse`), effects, the discrepancy's hyper-parameters;
* **accuracy**: before / after on the held-out rows (:mod:`pin_kpi_oed.report.accuracy`), the fit-quality verdict
  ``identify`` recorded, the honest σ (standardised RMS, share inside the 95 % ellipsoid), the trust map
  numbers, ISO 9283 AP / vAP / RP (:mod:`pin_kpi_oed.report.iso9283`), and the diagnosis ``diagnose`` recorded.

Every number is SI in the returned dict; the HTML prints mm / mrad with the unit.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field
from typing import Any
from collections.abc import Sequence

import numpy as np

from pin_kpi_oed.errors import InputError

__all__ = ["Certificate", "CertificateOptions", "build_certificate", "check_recorded", "robot_identity", "correlations",
           "sections_present", "portable_path", "CERTIFICATE_FORMAT", "SECTIONS"]

#: Format tag of the certificate's JSON.
CERTIFICATE_FORMAT = "pin_kpi_oed.certificate/1"
#: The certificate's sections, in order: (id, title).
SECTIONS = (("summary", "Summary"), ("identity", "Identity and traceability"),
            ("calibrated", "What was calibrated"), ("parameters", "Parameters"),
            ("accuracy", "Accuracy on held-out rows"), ("uncertainty", "Uncertainty (GUM)"),
            ("fit_quality", "Fit quality"),
            ("honest_sigma", "Honest sigma"), ("tcp_sigma", "Sigma at the TCP"), ("trust_map", "Trust map"),
            ("iso9283", "ISO 9283 pose figures"),
            ("diagnosis", "Diagnosis"), ("reproduce", "Reproduce"))


@dataclass(frozen=True)
class CertificateOptions:
    """What makes a page a certificate besides the model and its data.

    Attributes:
        lab_path: the lab file (:mod:`pin_kpi_oed.report.lab`); None: the page is a draft.
        required_accuracy_m: the accuracy the user requires of ``accuracy_figure`` (m); None: no conformity statement.
        accuracy_figure: the held-out figure the requirement is about (``p95_m``, ``rms_m``, ``mean_m``, ``max_m``).
        work_q: working configurations (k, n) rad / m the budget is stated at (default: the model's).
        goal_radius_m: the stated distance of a commanded position's rows to its goal (m).
        commanded_tcp_m: the point the goal columns command in the tool frame (m); None: the measured point.
        mc_draws: draws of the budget's Monte-Carlo check (0: none).
        cell: a work cell (:func:`~pin_kpi_oed.cell.cell.load_cell`) whose working paths the TCP's U is stated
            along (its TCP); None: none.
    """

    lab_path: str | None = None
    required_accuracy_m: float | None = None
    accuracy_figure: str = "p95_m"
    work_q: Any = None
    goal_radius_m: float = 1e-3
    commanded_tcp_m: Any = None
    mc_draws: int = 0
    cell: Any = None


@dataclass
class Certificate:
    """A certificate's content: ``data`` (JSON-ready, SI) and ``figures`` (name -> PNG bytes)."""

    data: dict
    figures: dict = field(default_factory=dict)


def correlations(names: Sequence[str], cov: Any, threshold: float = 0.9) -> list[dict]:
    """Pairs of parameters whose correlation |r| ≥ ``threshold``, strongest first (r = C_ij / √(C_ii C_jj))."""
    if cov is None:
        return []
    C = np.asarray(cov, float)
    d = np.sqrt(np.clip(np.diag(C), 1e-300, None))
    R = C / np.outer(d, d)
    i, j = np.triu_indices(len(d), 1)
    keep = np.abs(R[i, j]) >= threshold
    pairs = sorted(zip(i[keep], j[keep]), key=lambda t: -abs(R[t]))
    return [{"a": names[a], "b": names[b], "r": float(R[a, b])} for a, b in pairs]


def _sha256_text(text: str) -> str:
    return hashlib.sha256(text.encode()).hexdigest()


def check_recorded(cm: Any, records: list[dict], model_path: str) -> dict:
    """Compare the given training files with those the model file recorded; refuse another data set."""
    step = (cm.history or [{}])[-1]
    recorded = step.get("train_files")
    if not recorded:
        return {"checked": False, "note": "the model file records no training files (made before provenance was "
                                          "recorded, or through the Python API): not checked"}
    want = {r["sha256"] for r in recorded}
    names = ", ".join(f"{r['name']} ({r['sha256'][:12]}…)" for r in recorded)
    for rec in records:
        if rec["sha256"] not in want:
            raise InputError(f"{rec['path']}: SHA-256 {rec['sha256'][:12]}… is not a file {model_path} was calibrated "
                             f"on (recorded: {names})")
    missing = want - {r["sha256"] for r in records}
    if missing:
        raise InputError(f"train_paths: {model_path} was calibrated on {len(want)} files ({names}); give every one "
                         "of them (the nominal comparison is fitted on all its training rows)")
    return {"checked": True, "note": "the training files are the ones the model file recorded (SHA-256)"}


def _stations(cm: Any) -> list[dict]:
    import pinocchio as pin

    out = []
    for lab, st in cm.setups.items():
        T = np.asarray(st.tracker_T_base)
        out.append({"label": lab, "tracker_T_base_xyz_m": T[:3, 3].tolist(),
                    "tracker_T_base_rpy_rad": pin.rpy.matrixToRpy(T[:3, :3]).tolist(),
                    "reflector_m": np.asarray(st.reflector_m).tolist(), "n_rows": int(st.n_rows),
                    "fitted_by": st.fitted_by, "source": st.source, "rms_m": st.rms_m,
                    "sigma_scale": float(st.sigma_scale)})
    return out


def portable_path(path: str) -> str:
    """A robot file's path without the machine's folders: ``example-robot-data:<relative>`` or
    ``pin_kpi_oed:<relative>`` for the shipped robots, else the path as given."""
    from pathlib import Path

    from pin_kpi_oed.errors import RobotLoadError
    from pin_kpi_oed.model.robot import URDF_DIR, erd_root

    p = Path(path).resolve()
    roots = [("pin_kpi_oed:urdf/", URDF_DIR)]
    try:
        roots.append(("example-robot-data:", erd_root()))
    except RobotLoadError:
        pass
    for prefix, root in roots:
        if p.is_relative_to(root.resolve()):
            return f"{prefix}{p.relative_to(root.resolve())}"
    return str(path)


def robot_identity(cm: Any) -> dict:
    """The calibrated robot as a certificate names it: robot, URDF (portable path, SHA-256 of its text), the
    kinematics file's hash, tool frame, joints and the TCP (m, tool frame)."""
    rb = cm.robot
    return {"robot": rb.name, "urdf_path": portable_path(str(rb.urdf_path)),
            "urdf_sha256": _sha256_text(rb.read_urdf_text()),
            "kinematics_hash": rb.kinematics.hash if rb.kinematics is not None else None,
            "tool_frame": rb.tool_frame, "joints": list(rb.joint_names), "tcp_m": np.asarray(cm.tcp_m).tolist()}


def _calibrated(cm: Any, model_path: str, train_recs: list[dict], val_recs: list[dict], checked: dict) -> dict:
    from pin_kpi_oed.data.provenance import sha256_of, software_versions

    step = (cm.history or [{}])[-1]
    return {**robot_identity(cm),
            "pose6d": bool(cm.pose6d), "stations": _stations(cm), "noise": cm.noise.to_dict(),
            "sigma_source": (cm.fit or {}).get("sigma_source"),
            "model_file": {"path": str(model_path), "sha256": sha256_of(model_path)},
            "train_files": train_recs, "validate_files": val_recs, "train_files_check": checked,
            "software_at_calibration": step.get("software"), "software_now": software_versions(),
            "history": [{k: v for k, v in h.items() if k not in ("software", "diagnosis")} for h in cm.history]}


def _identifiable(cm: Any) -> dict:
    from pin_kpi_oed.oed.identifiability import analyse

    model, _ = cm.station_model(next(iter(cm.setups)))
    ident = analyse(model)
    est = list((cm.parameters or {}).get("names") or [])
    robot_names = [n for n in model.layout.names[:6 * cm.robot.nq]]
    held = [n for n in robot_names if n not in est]
    return {"summary": ident.summary().splitlines(), "n_raw": ident.n_raw, "rank": ident.rank,
            "estimated": est, "held_at_nominal": held,
            "in_words": (f"{len(est)} parameters estimated; {len(held)} of the {len(robot_names)} joint-placement "
                         "parameters are held at their nominal values: tracker positions cannot tell them apart "
                         "from the others or from the set-up (tracker pose, reflector), so any value of them "
                         "gives the same predictions at the reflector; not at a TCP away from it, where their "
                         "tolerance enters the TCP's sigma (section 'Sigma at the TCP')")}


def _tcp_sigma(cm: Any, station: str | None, Q_held_out: np.ndarray) -> dict:
    """The TCP's σ (:func:`~pin_kpi_oed.calibrated.tcp_sigma.tcp_sigma`, the one every command states) at the model's
    working configurations, else at the held-out rows' configurations: RMS and max 3-D σ (m), the held parameters'
    part and share, and the line saying which part no reflector measurement removes and what does."""
    from pin_kpi_oed.calibrated.tcp_sigma import tcp_sigma

    where = "working configurations" if cm.q_work is not None else "held-out configurations"
    Q = cm.q_work if cm.q_work is not None else Q_held_out
    at = tcp_sigma(cm, Q, station=station)
    held = float(np.sqrt(np.mean(at.held_sigma_m ** 2)))
    return {"tcp_m": at.tcp_m.tolist(), "stated": bool(cm.tool_source), "where": where, "n": int(len(Q)),
            "rms_m": at.rms_m, "max_m": float(at.sigma_m.max()), "sigma_m": at.sigma_m.tolist(),
            "held_rms_m": held, "held_share": at.held_share, "held_names": list(at.held_names),
            "advice": at.advice()}


def _parameters(cm: Any) -> dict:
    P = cm.parameters or {}
    names = list(P.get("names") or [])
    rows = [{"name": n, "value": float(v), "std": float(s), "unit": u}
            for n, v, s, u in zip(names, P.get("values", []), P.get("std", []), P.get("units", [""] * len(names)))]
    effects = [{"name": e.name, "unit": getattr(e, "unit", ""), "param_names": list(e.param_names()),
                "theta": np.asarray(t).tolist()} for e, t in zip(cm.effects, cm.thetas)]
    d = cm.discrepancy
    disc = None if d is None else {k: v for k, v in d.to_dict().items()
                                   if k in ("kind", "decision", "scale_m", "noise", "n_rows", "cv")}
    if d is not None and getattr(d, "kernel", None) is not None:
        disc["kernel"] = str(d.kernel)
    return {"rows": rows, "correlations": correlations(names, P.get("covariance")),
            "identifiable": _identifiable(cm), "effects": effects, "discrepancy": disc}


def _read(paths: Sequence[str], robot: Any, opts: dict) -> tuple[Any, list[dict]]:
    from pin_kpi_oed.data.measurements import concat_measurements, read_measurements
    from pin_kpi_oed.data.provenance import file_record

    sets, recs = [], []
    for p in paths:
        ms = read_measurements(p, joint_names=robot.joint_names, reach_m=robot.reach(), **opts)
        sets.append(ms)
        recs.append(file_record(p, len(ms)))
    return (sets[0] if len(sets) == 1 else concat_measurements(sets)), recs


def build_certificate(model_path: str, train_paths: Sequence[str], validate_path: str | None, *,
                      register_rows: int | None = None, register_data_path: str | None = None, seed: int = 0,
                      table_opts: dict | None = None, kinematics: str | None = None, command: str = "",
                      figures: bool = True, options: CertificateOptions | None = None) -> Certificate:
    """Collect a calibration certificate.

    Args:
        model_path: the model file (``identify`` / ``diagnose --model-out``).
        train_paths: the measurement files it was calibrated on (checked against the recorded SHA-256).
        validate_path: held-out measurements (required: a certificate states held-out accuracy).
        register_rows, register_data_path, seed: score on another session after re-registering its set-up.
        table_opts: reader options (``units``, ``columns``).
        kinematics: a UR kinematics file the model's nominal robot must have (its hash and values checked).
        command: the ``report`` command line (printed in the certificate).
        figures: draw the figures (PNG).
        options: the lab file, the required accuracy, the working configurations, the ISO 9283 grouping
            (:class:`CertificateOptions`).

    Raises:
        InputError: no held-out data, training files other than the recorded ones, a kinematics file of
            another robot or another hash, bad measurement files, a bad lab file, too few held-out rows once those
            repeating training configurations are removed.
    """
    from pin_kpi_oed.calibrated.model_file import load_model_file
    from pin_kpi_oed.report.accuracy import accuracy_figures, before_after
    from pin_kpi_oed.report.certify import commanded_section
    from pin_kpi_oed.report.iso9283 import iso_figures
    from pin_kpi_oed.report.lab import read_lab

    if not validate_path:
        raise InputError("a certificate states accuracy on rows the model was not fitted on: give "
                         "validate_path='FILE' (held-out measurements)")
    cm = load_model_file(model_path)
    _check_kinematics(cm, kinematics)
    o = options or CertificateOptions()
    lab = read_lab(o.lab_path) if o.lab_path else None
    opts = dict(table_opts or {})
    train, train_recs = _read(train_paths, cm.robot, opts)
    test, val_recs = _read([validate_path], cm.robot, opts)
    if {r["sha256"] for r in val_recs} & {r["sha256"] for r in train_recs}:
        raise InputError(f"{validate_path}: the held-out file is one of the training files: give rows the model was "
                         "not fitted on")
    test, repeats = _held_out(cm, train, test, lab, str(validate_path))
    checked = check_recorded(cm, train_recs, str(model_path))
    reg = _read([register_data_path], cm.robot, opts)[0] if register_data_path else None
    ho = before_after(cm, train, test, register_rows=register_rows, register_data=reg, seed=seed)
    scored = test if ho.mode == "split" or reg is not None else test.subset(np.asarray(ho.after["scored_rows"]) - 1)
    names = list(cm.robot.joint_names)
    acc = {"mode": ho.mode, "registration": _registration(ho.registration), "coverage": ho.coverage,
           "before_means": "nominal robot + tracker pose and reflector fitted on the training rows",
           "after_means": "the calibrated model" + (" (set-up re-registered)" if ho.mode == "transfer" else ""),
           "before": accuracy_figures(ho.before, ho.Q, ho.reach_m, names),
           "after": accuracy_figures(ho.after, ho.Q, ho.reach_m, names), "repeats_removed": repeats}
    quality = (cm.fit or {}).get("quality")
    after = ho.after
    data = {"format": CERTIFICATE_FORMAT, "title": f"Calibration certificate: {cm.robot.name}",
            "calibrated": _calibrated(cm, model_path, train_recs, val_recs, checked),
            "parameters": _parameters(cm), "accuracy": acc,
            "fit_quality": quality or {"verdict": "not recorded",
                                       "message": "the model file holds no fit-quality verdict"},
            "honest_sigma": {k: after.get(k) for k in ("z_rms", "inside_95", "sigma_mean_m", "extrapolation_share",
                                                        "sigma_scale")},
            "tcp_sigma": _tcp_sigma(ho.model, ho.station, ho.Q),
            "trust_map": None, "iso9283": iso_figures(scored, ho.Q, np.asarray(ho.before["residuals_m"]),
                                                      np.asarray(after["residuals_m"]), goal_radius_m=o.goal_radius_m,
                                                      commanded=commanded_section(scored, ho, o.goal_radius_m,
                                                                                  o.commanded_tcp_m)),
            "diagnosis": next((h.get("diagnosis") for h in reversed(cm.history or []) if h.get("diagnosis")), None),
            "reproduce": {"calibration": [h.get("command") for h in cm.history if h.get("command")],
                          "report": command}}
    _certify(data, cm, ho, lab, {"training": train, "held-out": scored}, o, seed)
    cert = Certificate(data)
    from pin_kpi_oed.report.figures import draw_figures, trust_numbers
    from pin_kpi_oed.viz.trust_map import trust_map

    tm = trust_map(ho.model, ho.Q, scored, ho.station)  # once: its numbers and its figure
    data["trust_map"] = trust_numbers(ho.model, ho.Q, scored, ho.station, tm)
    if figures:
        cert.figures = draw_figures(cm, ho, scored, data, tm)
    return cert


def _held_out(cm: Any, train: Any, test: Any, lab: dict | None, where: str) -> tuple[Any, dict]:
    """The held-out rows that repeat no training configuration (:mod:`pin_kpi_oed.report.heldout_rows`) and the
    record of those removed; the tracker's resolution from the lab file, else the default."""
    from pin_kpi_oed.model.measured_joints import align_data
    from pin_kpi_oed.report.heldout_rows import held_out_only
    from pin_kpi_oed.report.lab import DEFAULT_RESOLUTION_M

    res = (lab or {}).get("instrument", {}).get("resolution_m", DEFAULT_RESOLUTION_M)
    keep, rec = held_out_only(align_data(cm.robot, train), align_data(cm.robot, test), cm.robot.reach(), res, where)
    return (test.subset(keep) if rec["removed"] else test), rec


def _certify(data: dict, cm: Any, ho: Any, lab: dict | None, sets: dict, o: CertificateOptions, seed: int) -> None:
    """Identity, the uncertainty section and the conformity statement into ``data``, then the summary."""
    from pin_kpi_oed.report.certify import conformity_section, figure_uncertainty, uncertainty_section
    from pin_kpi_oed.report.lab import data_record, status
    from pin_kpi_oed.report.summary import summary

    rec = data_record(sets)
    st = status(lab)
    data["title"] = (f"Calibration certificate: {cm.robot.name}" if st["kind"] == "certificate" else
                     f"DRAFT — not a certificate: {cm.robot.name}")
    data["identity"] = {"status": st, "lab": lab, "data": rec, "report_time_utc": _now()}
    u_instr = (lab or {}).get("instrument", {}).get("uncertainty_m")
    temps = None
    T = sets["training"].temperature_c
    if T is not None and rec["temperature_c"] is not None:
        tmean = float(np.mean(T))
        temps = {"mean_c": tmean, "half_range_k": max(abs(rec["temperature_c"][0] - tmean),
                                                      abs(rec["temperature_c"][1] - tmean), 1e-3)}
    unc = uncertainty_section(cm, ho, work=o.work_q, instrument_u_m=u_instr, temps=temps, seed=seed,
                              mc_draws=o.mc_draws, cell=o.cell)
    unc["figures"] = figure_uncertainty(ho.after["errors_m"], u_instr or 0.0)
    unc["conformity"] = conformity_section(data["accuracy"]["after"], unc["figures"], o.required_accuracy_m,
                                           o.accuracy_figure, unc["budget"])
    data["uncertainty"] = unc
    data["summary"] = summary(data)


def _now() -> str:
    import datetime as dt

    return dt.datetime.now(dt.timezone.utc).replace(microsecond=0).isoformat()


def _registration(reg: dict | None) -> dict | None:
    if reg is None:
        return None
    return {k: reg.get(k) for k in ("source", "n", "rms_m", "seed", "hold_reflector", "notes")}


def _check_kinematics(cm: Any, kinematics: str | None) -> None:
    """The model's nominal robot must have the given UR kinematics file (values and hash)."""
    if not kinematics:
        return
    from pin_kpi_oed.model.robot import load_robot

    given = load_robot(cm.robot.name, cm.robot.tool_frame, kinematics=kinematics).kinematics
    have = cm.robot.kinematics
    if have is None:
        raise InputError(f"{kinematics}: the model's nominal robot is the {cm.robot.name} URDF ({cm.robot.urdf_path}), "
                         "not a kinematics file")
    if given.hash != have.hash or not np.allclose(given.values, have.values, rtol=0, atol=1e-12):
        raise InputError(f"{kinematics}: kinematics hash {given.hash} differs from the model's nominal {have.hash}")


def sections_present(data: dict) -> list[str]:
    """The section ids of :data:`SECTIONS` the certificate holds (every one, with a statement where empty)."""
    return [s for s, _ in SECTIONS if s in data]

