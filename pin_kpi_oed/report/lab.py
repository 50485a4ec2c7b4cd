r"""Who measured, with what and for whom: the lab file of a certificate, and what the measurement data carry.

A certificate names the organisation that signs it, its operator, the customer, the robot's serial number and the
instrument (make, model, serial, the date and number of its own calibration certificate): ``report --lab LAB.yaml``
reads them from a YAML file::

    organisation: Example Metrology Lab
    operator: A. Operator
    customer: Example Robotics Ltd
    robot_serial: UR10-2017-0042
    measured_on: 2021-03-02          # optional: the date the rows were measured (ISO 8601)
    instrument:
      make: Leica
      model: AT960
      serial: "750123"
      calibration_date: 2020-11-15   # ISO 8601; not after the report's date
      calibration_certificate: DAkkS-K-12345
      uncertainty_m: 1.5e-5          # optional: standard uncertainty of one measured point (m)
      resolution_m: 1.0e-5           # optional: two configurations closer than this at the TCP are one (m)

Every field but the optional ones is required; a missing or empty one, an unknown one, a date that does not parse
or a length that is not a positive number in metres is refused in one line naming the file and the field. Without a
lab file the page is a **draft**, never a certificate (:func:`status`).

From the measurement files (:func:`data_record`): the rows' time span (``time`` column, s) and temperature range
(``temperature`` column, °C) — or the statement that they carry none.
"""

from __future__ import annotations

import datetime as _dt
from pathlib import Path
from typing import Any

import numpy as np

from pin_kpi_oed.errors import InputError

__all__ = ["read_lab", "data_record", "status", "LAB_FIELDS", "INSTRUMENT_FIELDS", "DEFAULT_RESOLUTION_M"]

#: Required top-level fields of a lab file.
LAB_FIELDS = ("organisation", "operator", "customer", "robot_serial", "instrument")
#: Required fields of its ``instrument`` block.
INSTRUMENT_FIELDS = ("make", "model", "serial", "calibration_date", "calibration_certificate")
_OPTIONAL = {"measured_on"}
_INSTRUMENT_OPTIONAL = {"uncertainty_m", "resolution_m"}
#: The distance at the TCP below which two configurations are one when the lab file states no resolution (m).
DEFAULT_RESOLUTION_M = 1e-5


def _date(value: Any, where: str) -> str:
    if isinstance(value, _dt.datetime):
        value = value.date()
    if isinstance(value, _dt.date):
        return value.isoformat()
    try:
        return _dt.date.fromisoformat(str(value).strip()).isoformat()
    except ValueError:
        raise InputError(f"{where}: {value!r} is not a date (YYYY-MM-DD)") from None


def _length(value: Any, where: str) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{where}: {value!r} is not a number (m)") from None
    if not (np.isfinite(v) and 0 < v < 0.01):
        raise InputError(f"{where}: {value!r} must be a positive length below 0.01 m (the file is in metres)")
    return v


def _text(d: dict, key: str, where: str) -> str:
    v = d.get(key)
    if v is None or not str(v).strip():
        raise InputError(f"{where}: field '{key}' is missing or empty")
    if isinstance(v, (dict, list)):
        raise InputError(f"{where}: field '{key}' must be text, not {type(v).__name__}")
    return str(v).strip()


def read_lab(path: str | Path, today: _dt.date | None = None) -> dict:
    """Read and check a lab file (module docstring).

    Args:
        path: the YAML file.
        today: the report's date (default: today); the instrument's calibration may not be after it.

    Returns:
        The fields as text (dates ISO 8601, lengths in m as floats), plus ``file`` (the path as given).

    Raises:
        InputError: unreadable file, missing / empty / unknown field, bad date or length (one line).
    """
    import yaml

    p = Path(path)
    try:
        doc = yaml.safe_load(p.read_text())
    except OSError as exc:
        raise InputError(f"{path}: cannot read the lab file ({exc.strerror or exc})") from None
    except yaml.YAMLError as exc:
        raise InputError(f"{path}: not YAML ({str(exc).splitlines()[0]})") from None
    if not isinstance(doc, dict):
        raise InputError(f"{path}: a lab file is a mapping of fields ({', '.join(LAB_FIELDS)})")
    unknown = sorted(set(doc) - set(LAB_FIELDS) - _OPTIONAL)
    if unknown:
        raise InputError(f"{path}: unknown field '{unknown[0]}' (fields: {', '.join(LAB_FIELDS + tuple(_OPTIONAL))})")
    out: dict[str, Any] = {k: _text(doc, k, str(path)) for k in LAB_FIELDS if k != "instrument"}
    ins = doc.get("instrument")
    if not isinstance(ins, dict):
        raise InputError(f"{path}: field 'instrument' must hold {', '.join(INSTRUMENT_FIELDS)}")
    where = f"{path}: instrument"
    bad = sorted(set(ins) - set(INSTRUMENT_FIELDS) - _INSTRUMENT_OPTIONAL)
    if bad:
        raise InputError(f"{where}: unknown field '{bad[0]}'")
    inst: dict[str, Any] = {k: _text(ins, k, f"{path}: instrument") for k in INSTRUMENT_FIELDS}
    inst["calibration_date"] = _date(ins["calibration_date"], f"{path}: instrument.calibration_date")
    today = today or _dt.date.today()
    if _dt.date.fromisoformat(inst["calibration_date"]) > today:
        raise InputError(f"{path}: instrument.calibration_date {inst['calibration_date']} is after the report's "
                         f"date {today.isoformat()}")
    for k in _INSTRUMENT_OPTIONAL & set(ins):
        inst[k] = _length(ins[k], f"{path}: instrument.{k}")
    out["instrument"] = inst
    if doc.get("measured_on") is not None:
        out["measured_on"] = _date(doc["measured_on"], f"{path}: measured_on")
    out["file"] = str(path)
    return out


def data_record(sets: dict[str, Any]) -> dict:
    """What the measurement files carry about when and in what conditions they were measured.

    Args:
        sets: role (``training``, ``held-out``, ...) -> :class:`~pin_kpi_oed.data.measurements.MeasurementSet`.

    Returns:
        Per role: ``rows``, ``time_span_s`` (max − min of the ``time`` column, s, or None), ``temperature_c``
        ([min, max] °C, or None); ``temperature_c`` over every role; ``statements`` where the rows carry nothing.
    """
    out: dict[str, Any] = {"roles": {}, "statements": []}
    temps = []
    for role, ms in sets.items():
        t, T = ms.time_s, ms.temperature_c
        rec = {"rows": int(len(ms)), "time_span_s": None if t is None else float(np.ptp(t)),
               "temperature_c": None if T is None else [float(np.min(T)), float(np.max(T))]}
        if T is not None:
            temps.append(T)
        else:
            out["statements"].append(f"the {role} rows carry no temperature")
        if t is None:
            out["statements"].append(f"the {role} rows carry no time")
        out["roles"][role] = rec
    allT = np.concatenate(temps) if temps else None
    out["temperature_c"] = None if allT is None else [float(allT.min()), float(allT.max())]
    out["temperature_mean_c"] = None if allT is None else float(allT.mean())
    return out


def status(lab: dict | None) -> dict:
    """``certificate`` with a lab file, else ``draft`` with the reason (the page says which in its title)."""
    if lab is None:
        return {"kind": "draft", "reason": "no lab file (organisation, operator, instrument and its calibration, "
                                           "robot serial, customer): give one, report --lab LAB.yaml "
                                           "(CertificateOptions(lab_path=...) in Python)"}
    return {"kind": "certificate", "reason": f"identity and traceability from {lab['file']}"}
