"""Per-robot honesty of the σ at the TCP: ``python -m benchmarks.every_arm --truths K``.

One simulated robot's standardised TCP error over its held-out rows follows the few draws of the joint-placement
parameters no reflector measurement determines (e.g. the last joint's translation along its axis, 0.5 mm under the
tolerances): with one truth per robot, a robot's figure is ≈ |its draw| / its σ, whatever the σ's honesty. Here each
arm (and seed) is designed once (``design --cell cell.yaml --criteria kpi_gp --seed S``), and K true robots are drawn
on the same designed poses (``simulate --design d.json --seed S + 1000 k``, k = 0..K-1; k = 0 draws the plain walk's
truth), each identified (``identify`` without ``--validate``, ``--accept-poor-fit`` after a refusal), predicted at the TCP
(``predict --at tcp``, true noise-free TCP against the predicted one) and compensated (``compensate`` in the tracker
and the base frame, the true robot driven to the compensated joints). Per robot:

* the standardised RMS at the TCP over its K truths, sqrt(Σ_k m_k / K) with m_k truth k's mean z² per axis, and a
  95 % χ² interval on it with K degrees of freedom (m_k ~ χ²₁ scaled: one effective draw per truth, the
  conservative end, since the held term's few parameters dominate each truth); pass when it lies in 0.67-1.5, ``!``
  when the interval excludes the band;
* the share of rows (over the K truths) within the 95 % ellipsoid with its Clopper-Pearson interval over the rows
  (rows of one truth are correlated: a lower bound on the interval's width);
* the compensated targets: how many are marked plainly ``ok`` while the true TCP error exceeds their stated 95 %
  bound, how many of those the status ``tcp_unmeasured`` (the TCP's σ dominated by held parameters) now names, and
  the same for "farther than uncompensated".
"""

from __future__ import annotations

import json
import shutil
import time
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.every_arm import (HARMONIC, N_TEST, arm_urdf, compensate_both_frames, limits, run_cli, tcp_heldout,
                                  true_tcp, work_files, write_cell)

BAND = (0.67, 1.5)


def truth_rows(pt_csv: Path, truth: tuple, tcp_m: np.ndarray, Q: np.ndarray) -> np.ndarray:
    """Per held-out row, z² per axis (3,) of the TRUE TCP against ``predict --at tcp``'s table, (m, 3)."""
    import csv

    rows = list(csv.DictReader(open(pt_csv)))
    P = np.array([[float(r[f"{a}_pred"]) for a in "xyz"] for r in rows])
    S = np.array([[float(r[f"sigma_{a}"]) for a in "xyz"] for r in rows])
    return ((true_tcp(truth, tcp_m, Q, "cell") - P) / S) ** 2


def one_truth(f: dict[str, Path], urdf: Path, seed: int) -> dict:
    """Simulate one truth at the designed poses, identify, predict at the TCP, compensate (both frames)."""
    from pin_kpi_oed.calibrated.model_file import load_model_file
    from pin_kpi_oed.data.measurements import read_measurements
    from pin_kpi_oed.simulation.simulator import load_truth

    out: dict = {"truth_seed": seed}
    f["truth"].unlink(missing_ok=True)  # simulate --truth reads an existing file: draw afresh
    run_cli("simulate", "--design", f["d"], "--n-test", N_TEST, "--effects", HARMONIC, "--seed", seed,
            "--truth", f["truth"], "--out", f["tr"], "--test-out", f["te"])
    ident = ["identify", "--robot", urdf, "--data", f["tr"], "--model-out", f["m"], "--seed", seed, "--quiet"]
    try:
        run_cli(*ident)
    except RuntimeError as exc:
        out["identify_refused"] = str(exc)
        run_cli(*ident, "--accept-poor-fit")
    run_cli("predict", "--model", f["m"], "--data", f["te"], "--out", f["pt"], "--at", "tcp", "--quiet")
    truth, cm = load_truth(str(f["truth"])), load_model_file(f["m"])
    te = read_measurements(f["te"], joint_names=cm.robot.joint_names, joint_guard=limits(cm.robot))
    out["z2"] = truth_rows(f["pt"], truth, cm.tcp_m, te.q).tolist()
    out["tcp"] = tcp_heldout(f["pt"], truth, cm.tcp_m, te.q)
    for frame, (res, c) in compensate_both_frames(f, truth, cm).items():
        c["held_m"] = res.get("tcp_unobservable_m", [])
        out[f"compensate_{frame}"] = c
    return out


def run_truths(label: str, seed: int, k_truths: int, work: Path, args: Any) -> dict:
    """One arm at one design seed with K truths; the per-truth results and the per-robot summary."""
    from pin_kpi_oed.errors import PinKpiOedError
    from pin_kpi_oed.model.robot import erd_root

    w = work / f"{label}_s{seed}_truths"
    shutil.rmtree(w, ignore_errors=True)
    w.mkdir(parents=True)
    f = work_files(w)
    t0 = time.process_time()
    step = "URDF"
    rows = []
    try:
        urdf, tool = arm_urdf(label, work, args)
        step = "cell"
        write_cell(label, urdf, tool, w)
        step = "design"
        run_cli("design", "--cell", f["cell"], "--criteria", "kpi_gp", "--seed", seed, "--json", f["d"], "--quiet")
        for k in range(k_truths):
            step = f"truth {k}"
            rows.append(one_truth(f, urdf, seed + 1000 * k))
    except (PinKpiOedError, RuntimeError) as exc:
        if not rows:
            return {"arm": label, "seed": seed, "refused_at": step,
                    "refused": str(exc).replace(str(erd_root()) + "/", "").replace(str(work) + "/", "")}
    return {"arm": label, "seed": seed, "truths": rows, "cpu_s": time.process_time() - t0,
            **summarise(rows)}


def chi2_interval(m: np.ndarray) -> tuple[float, float, float]:
    """(standardised RMS, its 95 % interval) from per-truth mean z² values m_k (K dof, module docstring)."""
    from scipy.stats import chi2

    k, s = len(m), float(np.sum(m))
    return (float(np.sqrt(s / k)), float(np.sqrt(s / chi2.ppf(0.975, k))), float(np.sqrt(s / chi2.ppf(0.025, k))))


def binomial_interval(x: int, n: int) -> tuple[float, float]:
    """Clopper-Pearson 95 % interval of a share x / n."""
    from scipy.stats import beta

    lo = 0.0 if x == 0 else float(beta.ppf(0.025, x, n - x + 1))
    hi = 1.0 if x == n else float(beta.ppf(0.975, x + 1, n - x))
    return lo, hi


def summarise(rows: list[dict]) -> dict:
    """The per-robot figures over its truths (module docstring)."""
    from benchmarks.every_arm import CHI2_3_95

    m = np.array([np.mean(r["z2"]) for r in rows])
    z, lo, hi = chi2_interval(m)
    inside = np.concatenate([np.sum(r["z2"], axis=1) <= CHI2_3_95 for r in rows])
    x, n = int(inside.sum()), int(inside.size)
    comp = {"ok_over_bound": 0, "named_over_bound": 0, "ok_worse": 0, "named_worse": 0, "ok": 0, "named": 0,
            "over_bound": 0, "targets": 0}
    for r in rows:
        for fr in ("cell", "base"):
            c = r[f"compensate_{fr}"]
            for s, e, b, u in zip(c["status"], c["error_m"], c["bound95_m"], c["uncompensated_m"]):
                comp["targets"] += 1
                comp["over_bound"] += int(e > b)
                if s == "ok":
                    comp["ok"] += 1
                    comp["ok_over_bound"] += int(e > b)
                    comp["ok_worse"] += int(e > u)
                elif s == "tcp_unmeasured":
                    comp["named"] += 1
                    comp["named_over_bound"] += int(e > b)
                    comp["named_worse"] += int(e > u)
    ilo, ihi = binomial_interval(x, n)
    return {"k": len(rows), "z_rms": z, "z_lo": lo, "z_hi": hi, "inside": x / n, "inside_lo": ilo,
            "inside_hi": ihi, "n_rows": n, "per_truth_z": np.sqrt(m).tolist(),
            "passes": BAND[0] <= z <= BAND[1], "excludes_band": hi < BAND[0] or lo > BAND[1], "compensation": comp}


HEADER = ("arm                 seed  K   TCP z [95 % χ²]        verdict  in95 % [Clopper-Pearson]  "
          "per-truth z (min-max)  comp: plain ok & > bound (before -> after), "
          "plain ok & > unc (before -> after)  cpu s")


def line(r: dict) -> str:
    """One row per robot (arm, design seed)."""
    if "refused" in r:
        return f"{r['arm']:<19} s{r['seed']}  refused ({r['refused_at']}): {r['refused']}"
    c = r["compensation"]
    verdict = ("pass" if r["passes"] else "FAIL") + ("!" if r["excludes_band"] else " ")
    pz = r["per_truth_z"]
    return (f"{r['arm']:<19} s{r['seed']}  {r['k']:>2}  {r['z_rms']:5.2f} [{r['z_lo']:4.2f}, {r['z_hi']:4.2f}]"
            f"   {verdict:<7}  {r['inside'] * 100:5.1f} [{r['inside_lo'] * 100:4.1f}, {r['inside_hi'] * 100:5.1f}]"
            f"       {min(pz):4.2f}-{max(pz):4.2f}          "
            f"{c['ok_over_bound'] + c['named_over_bound']:>3} -> {c['ok_over_bound']:<3} of {c['targets']:<3}"
            f"   {c['ok_worse'] + c['named_worse']:>3} -> {c['ok_worse']:<3}   "
            f"(tcp_unmeasured {c['named']}, ok {c['ok']}, any status > bound {c['over_bound']})  {r['cpu_s']:5.0f}")


def pooled(rows: list[dict]) -> str:
    """Pass count and the compensation counts over every robot that ran."""
    ran = [r for r in rows if "refused" not in r]
    if not ran:
        return "no arm ran"
    keys = ("ok_over_bound", "named_over_bound", "ok_worse", "named_worse", "ok", "named", "targets")
    tot = {k: sum(r["compensation"][k] for r in ran) for k in keys}
    return (f"{sum(r['passes'] for r in ran)} of {len(ran)} robots within {BAND[0]}-{BAND[1]} "
            f"({sum(r['excludes_band'] for r in ran)} with the interval outside the band); compensated targets "
            f"whose true TCP error exceeds the 95 % bound: {tot['ok_over_bound'] + tot['named_over_bound']} marked "
            f"ok before, {tot['ok_over_bound']} marked plainly ok now ({tot['named_over_bound']} tcp_unmeasured); "
            f"farther than uncompensated: {tot['ok_worse'] + tot['named_worse']} before, {tot['ok_worse']} now; "
            f"{tot['ok']} plainly ok and {tot['named']} tcp_unmeasured of {tot['targets']} targets")


def main_truths(labels: list[str], seeds: list[int], k_truths: int, work: Path, args: Any) -> list[dict]:
    """Walk the arms with K truths each; print one row per robot; returns the rows."""
    print(f"K = {k_truths} truths per robot (same designed poses); TCP z = standardised RMS over the truths "
          f"(target {BAND[0]}-{BAND[1]}; '!' = the χ² interval excludes it); in95 = share of rows inside the 95 % "
          "ellipsoid; comp: compensated targets (tracker and base frame, every truth) marked ok whose true error "
          "exceeds the 95 % bound / is farther than uncompensated, before (ok or tcp_unmeasured) -> after (plainly "
          "ok)", flush=True)
    print(HEADER, flush=True)
    rows = []
    for label in labels:
        for seed in seeds:
            rows.append(run_truths(label, seed, k_truths, work, args))
            print(line(rows[-1]), flush=True)
            if args.json:
                Path(args.json).write_text(json.dumps(rows, default=float))
            if "refused" in rows[-1] and rows[-1]["refused_at"] in ("URDF", "cell"):
                break
    print(pooled(rows), flush=True)
    return rows
