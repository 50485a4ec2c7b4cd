"""The calibration check on simulated robots that are not the model and on the real UR10: false alarms at the stated
rate, changes that matter detected and named, re-fit or re-calibrate chosen on the expected TCP error.

Simulation (:mod:`pin_kpi_oed.studies.check_robots`): per robot a UR10 with errors on every joint parameter and an
unmodelled gear harmonic, calibrated by ``identify`` from 60 D-optimal poses (noise 0.025 mm per axis), its check
poses from ``check design`` sized for the verdict (the fewest poses whose verdict power against a change of 1.5 ×
the tolerance reaches 0.95; at least 10, at most 30); then ``--none`` unchanged checks and ``--changes`` of each kind
(a joint offset, the tool, the tracker) of k × the tolerance (k from :data:`FACTORS`), the tolerance 0.1 mm at 5
working TCPs, α = 0.05. Rates with Clopper–Pearson 95 % intervals; for every change shown above the tolerance the
true TCP error of the verdict's re-fit and of a re-calibration on the 60 poses; the choice between them per band of
the verdict's expected-error ratio (in expectation: the chosen action's mean true error against the other's), and
with ``--recal-draws k`` the spread of k re-calibrations on fresh noise draws and the calibration's own error the
re-fit carries (what one event's choice cannot foresee). ``--kinds placement_tracker`` simulates instead a joint's
placement changed with the tracker moved (:data:`~pin_kpi_oed.studies.check_robots.COMBINED_KINDS`): the re-fit
re-registers the set-up on the check rows and estimates a change of many columns, the kind where a re-calibration is
expected better; per choice the paired comparison of the true TCP errors (median ratio, sign test).

Real UR10 (IPA data, ``--real``): a model (``identify`` with ``discrepancy="auto"``) of a seeded half of Series C
checked on 10 seeded rows of the other half (``--splits`` seeded splits: *holds* expected; with ``--draws k`` also k
more seeded draws of 10 rows per split: the share of anything but *holds*) and on 10 seeded rows of Series D
(another session, another region of joint space).

Monitor (``--monitor N``): a model of 2,000 seeded rows of Series A, the next N other rows replayed in time order
(:func:`~pin_kpi_oed.upkeep.monitoring.monitor`: the set-up filter, a check every 10 rows): standardised RMS of
the rows predicted before use (overall and per 1,000 rows), mean error and predicted σ, checks flagged, requests for
poses, time per row (wall, and CPU against the target :data:`MONITOR_CPU_TARGET_S`).

Run:  python -m benchmarks.check_events [--robots 2] [--first 0] [--none 5] [--changes 2] [--events-json ev.json]
      [--kinds joint_offset tool tracker] [--recal-draws 1] [--real] [--splits 3] [--draws 0] [--monitor 1500]
      (the figures of docs/results.md: --robots 40 --events-json ev.json; --robots 40 --none 0 --changes 6 --kinds
      placement_tracker --recal-draws 4 (the choice of a re-calibration); --robots 0 --real --splits 20 --draws 30;
      --robots 0 --monitor 9911)
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from pin_kpi_oed.model.robot import load_robot
from pin_kpi_oed.studies.check_robots import CHANGE_KINDS as EVENT_KINDS
from pin_kpi_oed.studies.check_robots import COMBINED_KINDS

SIGMA = 2.5e-5
TOL = 1e-4
#: The monitor's CPU time per row it must stay within (s): prediction, set-up filter and checks.
MONITOR_CPU_TARGET_S = 0.020
ALPHA = 0.05
#: the sizes of the changes, in units of the tolerance
FACTORS = (0.25, 0.4, 0.75, 1.0, 1.5, 2.0, 3.0)


def simulated(n_robots: int, n_none: int = 5, n_changes: int = 2, out: str | None = None, first: int = 0,
              recal_draws: int = 1, kinds: tuple[str, ...] = EVENT_KINDS[1:]) -> None:
    """Robots that are not the model (:mod:`pin_kpi_oed.studies.check_robots`): per robot ``n_none`` unchanged
    checks and ``n_changes`` changes of each kind, sizes k × τ with k from :data:`FACTORS`; rates with their
    Clopper–Pearson 95 % intervals. ``first``: the first robot's seed (a run in chunks of robots: ``--first 20
    --robots 20``, the chunks' JSONs reported together by ``--report a.json b.json``). ``recal_draws``: re-calibrations
    on this many seeded noise draws per event that re-fits (the realisation's spread). ``kinds``: the changes
    (default the single-part kinds of the published figures; :data:`COMBINED_KINDS` change two parts at once)."""
    import json

    from pin_kpi_oed.studies.check_robots import robot_event, simulated_robot

    print(f"simulated UR10s that are not the model: errors on every joint parameter, a gear harmonic (50 urad), "
          f"calibrated on 60 D-optimal poses (noise {SIGMA * 1e3:.3g} mm per axis); tolerance {TOL * 1e3:.3g} mm at "
          f"5 working TCPs, alpha {ALPHA}; {n_robots} robots x ({n_none} unchanged + {n_changes} of each change: "
          f"{', '.join(kinds)})",
          flush=True)
    events = []
    t0 = time.perf_counter()
    for r in range(first, first + n_robots):
        robot = simulated_robot(r, noise_m=SIGMA, tolerance_m=TOL, alpha=ALPHA)
        rng = np.random.default_rng(5000 + r)
        plan = [("none", 0.0)] * n_none + [(k, float(rng.choice(FACTORS))) for k in kinds
                                           for _ in range(n_changes)]
        for i, (kind, k) in enumerate(plan):
            ev = robot_event(robot, kind, k, 100_000 * r + i, tolerance_m=TOL, alpha=ALPHA, recal_draws=recal_draws)
            events.append({**ev.__dict__, "robot": r, "check_poses": len(robot.Q_check), **robot.sizing})
        print(f"robot {r}: {len(robot.Q_check)} check poses (sized: {robot.sizing['poses_needed']}), "
              f"{sum(e['verdict'] != 'holds' for e in events if e['robot'] == r and e['kind'] == 'none')} of {n_none} "
              f"unchanged not 'holds' ({time.perf_counter() - t0:.0f} s)", flush=True)
        if out:
            with open(out, "w") as fh:
                json.dump(events, fh)
    report_simulated(events)


def report_simulated(events: list[dict]) -> None:
    """The rates of the issue's targets with their Clopper–Pearson intervals."""
    from pin_kpi_oed.studies.check_robots import clopper_pearson

    def rate(name: str, hits: list[bool]) -> None:
        k, n = int(sum(hits)), len(hits)
        lo, hi = clopper_pearson(k, n)
        print(f"  {name}: {k} of {n} = {k / max(n, 1) * 100:.1f} % (95 % CI {lo * 100:.1f}-{hi * 100:.1f} %)")

    none = [e for e in events if e["kind"] == "none"]
    print(f"{len({e['robot'] for e in events})} robots, {len(events)} events")
    rate("unchanged: anything but holds", [e["verdict"] != "holds" for e in none])
    rate("unchanged: the robot changed / re-calibrate", [e["verdict"] in ("robot_changed", "recalibrate",
                                                                          "discrepancy_level") for e in none])
    for kind in [k for k in (*EVENT_KINDS[1:], *COMBINED_KINDS) if any(e["kind"] == k for e in events)]:
        ch = [e for e in events if e["kind"] == kind]
        big = [e for e in ch if e["tcp_change_m"] >= 1.5 * TOL]
        small = [e for e in ch if e["tcp_change_m"] < 0.5 * TOL]
        rate(f"{kind} >= 1.5x tolerance: detected (not holds)", [e["verdict"] != "holds" for e in big])
        rate(f"{kind} >= 1.5x tolerance: named right", [e["right"] for e in big])
        rate(f"{kind} < 0.5x tolerance: holds", [e["verdict"] == "holds" for e in small])
    ch = [e for e in events if e["kind"] != "none"]
    big = [e for e in ch if e["tcp_change_m"] >= 1.5 * TOL]
    rate("every change >= 1.5x tolerance: detected", [e["verdict"] != "holds" for e in big])
    rate("every change >= 1.5x tolerance: named right", [e["right"] for e in big])
    rate("every change < 0.5x tolerance: holds", [e["verdict"] == "holds" for e in ch if e["tcp_change_m"] < 0.5 * TOL])
    print(f"  named 'X or Y' (parts the check rows do not tell apart): {sum(bool(e.get('alike')) for e in big)} of "
          f"{len(big)} changes >= 1.5x tolerance; 'cannot size': {sum(not e.get('sized', True) for e in ch)} of "
          f"{len(ch)} changes")
    for e in big:
        if not e["right"]:
            print(f"    misnamed: robot {e['robot']} {e['kind']} {e['joint']} {e['tcp_change_m'] * 1e3:.3f} mm -> "
                  f"{e['verdict']} {e['group']!r} {e.get('alike', [])}")
    both = [e for e in events if np.isfinite(e["refit_error_m"]) and np.isfinite(e["recal_error_m"])]
    for choice in ("robot_changed", "recalibrate"):
        sel = [e for e in both if e["verdict"] == choice]
        if not sel:
            continue
        a = np.array([e["refit_error_m"] for e in sel])
        b = np.array([e["recal_error_m"] for e in sel])
        chosen, other = (a, b) if choice == "robot_changed" else (b, a)
        print(f"  chose {'re-fit' if choice == 'robot_changed' else 're-calibrate'} in {len(sel)} events: true TCP "
              f"error mean {chosen.mean() * 1e3:.4f} mm (median {np.median(chosen) * 1e3:.4f}), the other "
              f"{other.mean() * 1e3:.4f} mm (median {np.median(other) * 1e3:.4f}); mean ratio chosen/other "
              f"{chosen.mean() / other.mean():.3f}; chosen worse by > 10 % in "
              f"{np.mean(chosen > 1.1 * other) * 100:.0f} % of the events")
        pa = np.array([e["predicted_refit_m"] for e in sel])
        pb = np.array([e["predicted_recal_m"] for e in sel])
        print(f"    expected (the verdict's): re-fit {pa.mean() * 1e3:.4f} mm, re-calibration {pb.mean() * 1e3:.4f} mm "
              f"(ratio {np.min(pa / pb):.3f}-{np.max(pa / pb):.3f})")
        _paired(chosen, other, len({e["robot"] for e in sel}))
        k = int(np.argmax(chosen / other))
        print(f"    worst case: chosen {chosen[k] * 1e3:.4f} mm against the other's {other[k] * 1e3:.4f} mm (ratio "
              f"{chosen[k] / other[k]:.3f}; robot {sel[k]['robot']}, {sel[k]['kind']} {sel[k]['joint']} "
              f"{sel[k]['tcp_change_m'] * 1e3:.3f} mm)")
    report_choice(both)


def _paired(chosen: np.ndarray, other: np.ndarray, n_robots: int) -> None:
    """The paired comparison of the chosen action's true TCP errors with the other's (the project's): the median of
    the ratios, the sign test of chosen > other (two-sided), the share worse by more than 10 %."""
    from scipy import stats

    worse = int(np.sum(chosen > other))
    print(f"    paired ({len(chosen)} events on {n_robots} robots): median ratio chosen / other "
          f"{np.median(chosen / other):.3f}, chosen worse in {worse} of {len(chosen)} (sign test p "
          f"{stats.binomtest(worse, len(chosen)).pvalue:.2g}), worse by > 10 % in {int(np.sum(chosen > 1.1 * other))}")


def _worse_pairs(d: np.ndarray) -> float:
    """The share of ordered pairs (j ≠ k) of realisations with d_j > 1.1 d_k."""
    m = d[:, None] > 1.1 * d[None, :]
    return float(m.sum() / max(len(d) * (len(d) - 1), 1))


#: bands of the verdict's expected-error ratio re-fit / re-calibration (the choice's margin is 1.1)
RATIO_BANDS = (0.0, 1.01, 1.03, 1.1, 1.3, np.inf)


def report_choice(both: list[dict]) -> None:
    """The choice between re-fit and re-calibration in expectation: per band of the verdict's expected-error ratio
    (re-fit / re-calibration, :data:`RATIO_BANDS`), the mean true TCP error of the chosen action over the band's
    events against the other's (target: within 10 %), the paired median ratio and a sign test of chosen > other;
    then what a single event cannot foresee: the spread of re-calibrations on fresh noise draws of the same rows
    and the calibration's own error the re-fit carries (events run with ``--recal-draws``)."""
    from scipy import stats

    if not both:
        return
    ratio = np.array([e["predicted_refit_m"] / e["predicted_recal_m"] for e in both])
    print("  the choice in expectation, per band of the expected ratio re-fit / re-calibration:")
    for lo, hi in zip(RATIO_BANDS[:-1], RATIO_BANDS[1:]):
        band = [e for e, x in zip(both, ratio) if lo <= x < hi]
        if not band:
            continue
        refit = [e["verdict"] == "robot_changed" for e in band]
        a = np.array([e["refit_error_m"] if f else e["recal_error_m"] for e, f in zip(band, refit)])
        b = np.array([e["recal_error_m"] if f else e["refit_error_m"] for e, f in zip(band, refit)])
        worse = int(np.sum(a > b))
        p = stats.binomtest(worse, len(a)).pvalue
        expected = np.sqrt(np.mean([e["predicted_refit_m"] ** 2 for e in band])
                           / np.mean([e["predicted_recal_m"] ** 2 for e in band]))
        print(f"    [{lo:.2f}, {hi:.2f}): {len(band)} events ({sum(refit)} re-fit, {len(band) - sum(refit)} "
              f"re-calibrate) on {len({e['robot'] for e in band})} robots; mean true TCP error chosen "
              f"{a.mean() * 1e3:.4f} mm, the other {b.mean() * 1e3:.4f} mm, ratio of the means "
              f"{a.mean() / b.mean():.3f} (expected {expected:.3f} for the re-fit); paired median ratio "
              f"{np.median(a / b):.3f}, chosen worse in {worse} of {len(a)} (sign test p {p:.2g})")
        if all(len(e.get("recal_draws_m", [])) > 1 for e in band):
            m = np.array([np.mean(e["recal_draws_m"]) for e in band])
            r = np.array([e["refit_error_m"] for e in band])
            k = int(np.sum(r > m))
            print(f"      the re-fit against the mean of the re-calibration draws: ratio of the means "
                  f"{r.mean() / m.mean():.3f}, paired median ratio {np.median(r / m):.3f}, the re-fit worse in "
                  f"{k} of {len(r)} (sign test p {stats.binomtest(k, len(r)).pvalue:.2g})")
    draws = [e for e in both if len(e.get("recal_draws_m", [])) > 1]
    if draws:
        cv = [np.std(e["recal_draws_m"], ddof=1) / np.mean(e["recal_draws_m"]) for e in draws]
        lo_hi = [max(e["recal_draws_m"]) / min(e["recal_draws_m"]) for e in draws]
        within = [np.mean(np.array(e["recal_draws_m"]) * 1.1 >= e["refit_error_m"]) for e in draws]
        pairs = [_worse_pairs(np.array(e["recal_draws_m"])) for e in draws]
        means = np.mean([e["refit_error_m"] for e in draws]) / np.mean([np.mean(e["recal_draws_m"]) for e in draws])
        expected = np.sqrt(np.mean([e["predicted_refit_m"] ** 2 for e in draws])
                           / np.mean([e["predicted_recal_m"] ** 2 for e in draws]))
        print(f"  re-calibrations on {len(draws[0]['recal_draws_m'])} fresh noise draws, {len(draws)} events: their "
              f"true TCP error varies by {np.median(cv) * 100:.1f} % (median coefficient of variation; largest / "
              f"smallest draw median {np.median(lo_hi):.2f}, max {max(lo_hi):.2f}); the re-fit within 10 % of a "
              f"draw in {np.mean(within) * 100:.0f} % of the draws; the re-fit / the draws' mean: median "
              f"{np.median([e['refit_error_m'] / np.mean(e['recal_draws_m']) for e in draws]):.3f}, ratio of the means "
              f"{means:.3f} (expected {expected:.3f}); one re-calibration "
              f"worse than another of the same event by > 10 % in {np.mean(pairs) * 100:.0f} % of the pairs")
    cal = [e for e in both if np.isfinite(e.get("calibration_error_m", np.nan))]
    if cal:
        a = np.array([e["refit_error_m"] for e in cal])
        c = np.array([e["calibration_error_m"] for e in cal])
        b = np.array([np.mean(e.get("recal_draws_m") or [e["recal_error_m"]]) for e in cal])
        print(f"  the calibration's own true TCP error before the change ({len(cal)} events): re-fit / it median "
              f"{np.median(a / c):.3f}; correlation of (re-fit - re-calibration) with (it - re-calibration) "
              f"{np.corrcoef(a - b, c - b)[0, 1]:.2f}")
        report_added(cal)


def report_added(events: list[dict], n_boot: int = 2000, seed: int = 0) -> None:
    """What the re-fit adds to the calibration's own error, realised against expected, per choice: the mean of
    (re-fit² − the calibration's own error²) over the mean of what the verdict adds for the re-fit (its expected
    error² less a re-calibration's: the change's estimation error and the registration's share), with a 95 %
    bootstrap interval over robots (seeded)."""
    rng = np.random.default_rng(seed)
    for choice in ("robot_changed", "recalibrate"):
        sel = [e for e in events if e["verdict"] == choice]
        if not sel:
            continue
        real = np.array([e["refit_error_m"] ** 2 - e["calibration_error_m"] ** 2 for e in sel])
        expected = np.array([e["predicted_refit_m"] ** 2 - e["predicted_recal_m"] ** 2 for e in sel])
        robots = np.array([e["robot"] for e in sel])
        ids = np.unique(robots)
        rows = [np.flatnonzero(robots == r) for r in ids]
        boot = []
        for _ in range(n_boot):
            idx = np.concatenate([rows[k] for k in rng.integers(0, len(ids), len(ids))])
            boot.append(real[idx].mean() / expected[idx].mean())
        lo, hi = np.percentile(boot, [2.5, 97.5])
        a = np.array([e["refit_error_m"] for e in sel])
        m = np.array([np.mean(e.get("recal_draws_m") or [e["recal_error_m"]]) for e in sel])

        def rms(x: np.ndarray) -> float:
            return float(np.sqrt(np.mean(x ** 2)))

        print(f"    {'re-fit' if choice == 'robot_changed' else 're-calibrate'} chosen ({len(sel)} events): the "
              f"re-fit adds to the calibration's own error {real.mean() / expected.mean():.2f} x the variance the "
              f"verdict expects it to add ({np.sqrt(expected.mean()) * 1e3:.4f} mm RMS; bootstrap over "
              f"{len(ids)} robots 95 % {lo:.2f}-{hi:.2f}); re-fit / the calibration's own error median "
              f"{np.median(a / np.array([e['calibration_error_m'] for e in sel])):.3f}; realised RMS / expected: "
              f"re-fit {rms(a) / rms(np.array([e['predicted_refit_m'] for e in sel])):.2f}, re-calibration (the "
              f"draws' mean) {rms(m) / rms(np.array([e['predicted_recal_m'] for e in sel])):.2f}")


def real(splits: int, draws: int = 0) -> None:
    from benchmarks.common import find_ipa_data, load_ipa_series
    from benchmarks.honest_sigma import calibrate
    from pin_kpi_oed.upkeep.check import check_calibration
    from pin_kpi_oed.model.noise import NoiseModel
    from pin_kpi_oed.model.tracker import TrackerModel

    folder = find_ipa_data()
    if folder is None:
        print("real UR10: IPA data not found ($PIN_KPI_OED_IPA_DATA)")
        return
    C, D = load_ipa_series(folder, "C"), load_ipa_series(folder, "D")
    model = TrackerModel(load_robot("ur10"), reflector_m=np.array([0.0, 0.0, 0.109]),
                         noise=NoiseModel(sigma_xyz_m=(1e-4,) * 3))
    print(f"real UR10: a model of a seeded half of Series C checked on 10 rows (alpha {ALPHA}, tolerance "
          f"{TOL * 1e3:.3g} mm; working configurations: 20 training rows)")
    print(f"{'split':>5} {'checked on':<12} {'verdict':<14} {'chi2':>7} {'dof':>4} {'p':>8} {'min power':>9} "
          f"{'reg. mm':>7} {'add':>4}  named")
    flagged = {"C other half": 0, "D": 0}
    undetermined = {"C other half": 0, "D": 0}
    extra: list[bool] = []
    per_split: dict[int, int] = {}
    transfer: list[list[float]] = []
    d_verdicts: list[str] = []
    for s in range(splits):
        tr, te = C.split(0.5, seed=s)
        cm = calibrate(model, tr, s)
        rng = np.random.default_rng(s)
        for k in range(draws):
            rows = te.subset(np.random.default_rng(1000 + k).choice(len(te), 10, replace=False))
            r = check_calibration(cm, rows, q_work=tr.q[:20], alpha=ALPHA, tolerance_m=TOL, seed=s)
            extra.append(r.verdict != "holds")
            per_split[s] = per_split.get(s, 0) + (r.verdict != "holds")
        for name, rows in (("C other half", te), ("D", D)):
            pick = rng.choice(len(rows), 10, replace=False)
            r = check_calibration(cm, rows.subset(pick), q_work=tr.q[:20], alpha=ALPHA, tolerance_m=TOL, seed=s)
            flagged[name] += r.verdict != "holds"
            undetermined[name] += not r.setup_determined
            print(f"{s:>5} {name:<12} {r.verdict:<14} {r.chi2:>7.1f} {r.dof:>4} {r.p_value:>8.3g} "
                  f"{min(r.power.values()):>9.2f} {r.registration_sigma_m * 1e3:>7.3f} {len(r.poses_to_add):>4}  "
                  f"{_named(r)}")
            if name == "D":
                d_verdicts.append(f"{r.verdict} {_named(r)}".strip())
            if name == "D":
                transfer.append(_transfer_errors(cm, r, rows, pick, s))
    if extra:
        from pin_kpi_oed.studies.check_robots import clopper_pearson

        lo, hi = clopper_pearson(int(sum(extra)), len(extra))
        print(f"anything but holds on C's other half over {splits} splits x {draws} seeded draws of 10 rows: "
              f"{int(sum(extra))} of {len(extra)} = {np.mean(extra) * 100:.1f} % (95 % CI {lo * 100:.1f}-{hi * 100:.1f}"
              f" %; stated false-alarm rate of the verdict: {ALPHA:.0%}); per split: "
              + ", ".join(str(per_split.get(k, 0)) for k in range(splits)))
    for name, k in flagged.items():
        print(f"anything but holds on {name}: {k} of {splits}; set-up not determined at the working configurations by "
              f"the 10 rows (poses to add named): {undetermined[name]} (stated false-alarm rate: {ALPHA:.0%})")
    if d_verdicts:
        from collections import Counter

        print(f"C's model checked on {len(d_verdicts)} seeded draws of 10 rows of D (re-registered by the check): "
              + "; ".join(f"{n} x {v}" for v, n in Counter(v.split(' (')[0] for v in d_verdicts).most_common()))
    if transfer:
        t = np.array(transfer)
        print("on D's other rows (mean 3-D error / mean honest sigma, mm; median over splits): re-registered on the 10 "
              f"check rows {np.median(t[:, 0]):.3f} / {np.median(t[:, 1]):.3f}; the verdict's model "
              f"{np.median(t[:, 2]):.3f} / {np.median(t[:, 3]):.3f}; re-registered on 60 rows {np.median(t[:, 4]):.3f} "
              f"/ {np.median(t[:, 5]):.3f}")


def _named(r) -> str:
    """The verdict's named part with its size: the group (or the parts the rows do not tell apart), the RMS TCP
    change at the working configurations ± its σ (mm), the set-up's shift (mm), "cannot size" when not sized."""
    what = " or ".join([r.group, *r.alike]) if r.group else "-"
    size = (f"change {r.change_tcp_m * 1e3:.3f} +- {r.change_tcp_sigma_m * 1e3:.3f} mm" if r.sized
            else "the check cannot size this change")
    return f"{what} ({size}; set-up shift {r.setup_shift_m * 1e3:.3f} mm)"


def _transfer_errors(cm, r, rows, pick, seed: int) -> list[float]:
    """Mean 3-D error and mean honest σ (mm) on the rows of another series not used by the check: the model
    re-registered on the check rows, the verdict's model (re-fitted when it named a determined group), the model
    re-registered on 60 seeded other rows."""
    from pin_kpi_oed.upkeep.transfer import register_setup

    rest = np.setdiff1d(np.arange(len(rows)), pick)
    other = rows.subset(rest)

    def score(model) -> tuple[float, float]:
        Y, sig, _ = model.predict_with_sigma(other.q, other, station="check" if "check" in model.setups else None)
        return (float(np.mean(np.linalg.norm(other.position_m - Y, axis=1))) * 1e3,
                float(np.mean(np.linalg.norm(sig, axis=1))) * 1e3)

    reg = register_setup(cm, rows.subset(pick), station="check", hold_reflector=True).model
    sixty = np.random.default_rng(seed).choice(rest, 60, replace=False)
    reg60 = register_setup(cm, rows.subset(sixty), station="check", hold_reflector=True).model
    return [*score(reg), *score(r.model), *score(reg60)]


def replay(n_rows: int) -> None:
    from benchmarks.common import cpu_time, find_ipa_data, load_ipa_series
    from benchmarks.honest_sigma import calibrate
    from pin_kpi_oed.upkeep.monitoring import monitor
    from pin_kpi_oed.model.noise import NoiseModel
    from pin_kpi_oed.threads import limited_threads
    from pin_kpi_oed.model.tracker import TrackerModel

    folder = find_ipa_data()
    if folder is None:
        print("monitor: IPA data not found ($PIN_KPI_OED_IPA_DATA)")
        return
    A = load_ipa_series(folder, "A", with_time=True)
    A = A.subset(np.argsort(A.time_s, kind="stable"))
    perm = np.random.default_rng(0).permutation(len(A))
    train, rest = np.sort(perm[:2000]), np.sort(perm[2000:])[:n_rows]
    model = TrackerModel(load_robot("ur10"), reflector_m=np.array([0.0, 0.0, 0.109]),
                         noise=NoiseModel(sigma_xyz_m=(1e-4,) * 3))
    cm = calibrate(model, A.subset(train), 0)
    cm.q_work = A.q[train[:20]]
    with limited_threads():     # the BLAS threads the command line allows (threads' busy waits count as CPU)
        t0 = cpu_time()
        log = monitor(cm, A.subset(rest), every=10, alpha=ALPHA, tolerance_m=TOL)
        cpu = (cpu_time() - t0) / len(rest)
    print(f"monitor, Series A: model of 2,000 seeded rows, {len(rest)} other rows replayed in time order "
          f"({(A.time_s[rest[-1]] - A.time_s[rest[0]]) / 3600:.1f} h of time stamps); working configurations: 20 "
          "training rows")
    print(log.summary() + f" ({cpu * 1e3:.1f} ms CPU per row, {cpu / MONITOR_CPU_TARGET_S:.2f} x the "
                          f"{MONITOR_CPU_TARGET_S * 1e3:.0f} ms target)")
    z = log.z
    print("standardised RMS per 1,000 rows (so far): " + ", ".join(
        f"{np.sqrt(np.mean(z[a:a + 1000] ** 2)):.2f} ({np.sqrt(np.mean(z[:a + 1000] ** 2)):.2f})"
        for a in range(0, len(z), 1000)))
    print("requests for poses at rows: " + (", ".join(f"{a['row']} ({a['reason']})" for a in log.asks) or "none"))


def parser() -> argparse.ArgumentParser:
    """The benchmark's options (module docstring)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--robots", type=int, default=2, help="simulated robots that are not the model (the figures: 40)")
    ap.add_argument("--none", type=int, default=5, help="unchanged checks per robot (default 5)")
    ap.add_argument("--changes", type=int, default=2, help="changes of each kind per robot (default 2)")
    ap.add_argument("--events-json", dest="events_json", default=None, help="write every simulated event here")
    ap.add_argument("--first", type=int, default=0, help="the first simulated robot's seed (runs in chunks)")
    ap.add_argument("--report", nargs="+", default=None,
                    help="only report the events of these JSONs (--events-json of one run or of its chunks)")
    ap.add_argument("--kinds", nargs="+", default=list(EVENT_KINDS[1:]), choices=[*EVENT_KINDS[1:], *COMBINED_KINDS],
                    help="the changes simulated (default: joint_offset tool tracker, the published figures); "
                         "placement_tracker: a joint's placement changed and the tracker moved at once")
    ap.add_argument("--recal-draws", dest="recal_draws", type=int, default=1,
                    help="re-calibrations on this many seeded noise draws per re-fitting event (default 1)")
    ap.add_argument("--real", action="store_true", help="also the real UR10 checks (IPA data)")
    ap.add_argument("--splits", type=int, default=3, help="seeded splits of Series C (the figures: 20)")
    ap.add_argument("--draws", type=int, default=0,
                    help="also this many seeded draws of 10 check rows per split of Series C (the false-alarm rate)")
    ap.add_argument("--monitor", type=int, default=0, help="replay this many rows of Series A (0: none)")
    return ap


def main(argv: list[str] | None = None) -> int:
    args = parser().parse_args(argv)
    if args.report:
        import json

        report_simulated([e for path in args.report for e in json.loads(open(path).read())])
        return 0
    if args.robots:
        simulated(args.robots, args.none, args.changes, args.events_json, args.first, args.recal_draws,
                  tuple(args.kinds))
    if args.real:
        real(args.splits, args.draws)
    if args.monitor:
        replay(args.monitor)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
