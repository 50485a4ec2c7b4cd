"""One result vocabulary: every result type of the package derives from :class:`pin_kpi_oed.results.Result` (found
by name, ``*Result``, and the step results named otherwise), and their dicts carry the common words."""

from __future__ import annotations

import ast
import importlib
from pathlib import Path

from pin_kpi_oed.results import Result
from tests._cache_misc import kept_out_of_collections

PKG = Path(__file__).resolve().parents[1] / "pin_kpi_oed"
#: results of a step whose class name does not end in "Result" (module under pin_kpi_oed, class)
OTHER_RESULTS = {("oed.selection_result", "PoolSelection"), ("oed.relaxation", "ApproximateDesign"),
                 ("oed.certificate", "Certificate"), ("oed.evaluate", "DesignScore"),
                 ("oed.identifiability", "Identifiability"), ("oed.discrepancy_kpi", "PosesNeeded"),
                 ("diagnosis.report", "DiagnosisReport"), ("program.ordering", "Program"),
                 ("studies.learning_curves", "LearningCurves"), ("design.ipopt", "IpoptRun"),
                 ("upkeep.monitoring", "MonitorLog")}


def _result_classes() -> list[tuple[str, str]]:
    """(module, class) of every result type the package declares at the top level of a module: each file parsed
    without garbage collections and its tree dropped after it (kept trees slow down every later collection)."""
    out = []
    with kept_out_of_collections():
        for f in sorted(PKG.rglob("*.py")):
            rel = ".".join(f.relative_to(PKG).with_suffix("").parts)
            for node in ast.parse(f.read_text()).body:
                if isinstance(node, ast.ClassDef) and (node.name.endswith("Result") or (rel, node.name) in
                                                       OTHER_RESULTS):
                    out.append(("pin_kpi_oed." + rel, node.name))
    return out


def test_every_result_type_derives_from_result() -> None:
    found = _result_classes()
    assert {n for _, n in found} >= {n for _, n in OTHER_RESULTS} | {"IkResult", "EffectResult", "IdentificationResult"}
    bad = [f"{m}.{n}" for m, n in found if n != "Result" and not issubclass(getattr(importlib.import_module(m), n),
                                                                               Result)]
    assert not bad, "result types outside the one vocabulary: " + ", ".join(bad)


def test_a_skipped_effect_speaks_the_vocabulary() -> None:
    from pin_kpi_oed.diagnosis.report import EffectResult

    skipped = EffectResult("thermal", status="skipped", message="no temperature column")
    ok = EffectResult("gravity", heldout_rms_before_m=2e-4, heldout_rms_after_m=1e-4)
    assert (skipped.success, skipped.status) == (False, "skipped") and (ok.success, ok.status) == (True, "ok")
    d = skipped.to_dict()
    assert d["status"] == "skipped" and d["message"] == "no temperature column" and d["success"] is False
    assert abs(ok.reduction_m - 1e-4) < 1e-18
