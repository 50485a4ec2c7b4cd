"""monitor names what it cannot trust: an out-of-band standardised RMS with its likely cause, rows whose time goes
backwards or repeats, a model without working configurations (the training's region, said so); it ends with the exit
code --fail-on asks for; a followed file is refused as the same file without --follow is."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from pin_kpi_oed import load_robot
from pin_kpi_oed.cli.app import main
from pin_kpi_oed.data.measurements import MeasurementSet, write_measurements
from pin_kpi_oed.discrepancy.coverage import JointCoverage
from pin_kpi_oed.model.noise import NoiseModel
from pin_kpi_oed.studies.check_events import simulated_model
from pin_kpi_oed.upkeep.monitoring import monitor

SIGMA = 2e-5


@pytest.fixture(scope="module")
def setting():
    rb = load_robot("ur10")
    rng = np.random.default_rng(0)
    model = simulated_model(rb, 0.5 * rng.uniform(rb.q_lower, rb.q_upper, size=(5, rb.nq)), SIGMA, 0)
    Q = 0.7 * rng.uniform(rb.q_lower, rb.q_upper, size=(40, rb.nq))
    Y = model.predict(Q) + rng.normal(size=(40, 3)) * SIGMA
    return rb, model, Q, Y


def test_an_overstated_sigma_is_named_with_its_cause(setting):
    rb, model, Q, Y = setting
    loud = dataclasses.replace(model, noise=NoiseModel(sigma_xyz_m=(5 * SIGMA,) * 3))
    log = monitor(loud, MeasurementSet(list(rb.joint_names), Q, Y), every=10)
    assert log.z_rms < 0.67
    warn = [e for e in log.events if "outside the honest" in e]
    assert len(warn) == 1 and "stated noise" in warn[0] and "--sigma" in warn[0]
    honest = monitor(model, MeasurementSet(list(rb.joint_names), Q, Y), every=10)
    assert 0.67 <= honest.z_rms <= 1.5 and not any("outside the honest" in e for e in honest.events)


def test_time_going_backwards_or_repeated_is_named(setting):
    rb, model, Q, Y = setting
    t = np.arange(40, dtype=float) * 5.0
    t[12] = t[11]              # repeated
    t[20] = 3.0                # backwards
    log = monitor(model, MeasurementSet(list(rb.joint_names), Q, Y, time_s=t), every=10)
    lines = [e for e in log.events if "time" in e]
    assert any("row 13" in e and "repeats" in e for e in lines)
    assert any("row 21" in e and "goes backwards" in e for e in lines)
    assert log.time_backwards == 1 and log.time_repeated == 1
    const = monitor(model, MeasurementSet(list(rb.joint_names), Q, Y, time_s=np.zeros(40)), every=10)
    assert any("time column is constant" in e for e in const.events)
    assert const.drift_level_m_per_sqrt_s <= log.drift_level_m_per_sqrt_s * 10 + 1e-9


def test_without_working_configurations_the_training_region_is_used_and_said(setting):
    rb, model, Q, Y = setting
    bare = dataclasses.replace(model, q_work=None, coverage=JointCoverage.from_training(Q[::2]))
    log = monitor(bare, MeasurementSet(list(rb.joint_names), Q, Y), every=10)
    assert log.work_source.startswith("the model has no working configurations") and "training's region" in \
        log.work_source
    assert log.events[0] == f"monitor: {log.work_source}"
    none = dataclasses.replace(model, q_work=None, coverage=None)
    log2 = monitor(none, MeasurementSet(list(rb.joint_names), Q, Y), every=10)
    assert "no power" in log2.work_source


def test_monitor_exit_code_and_fail_on(setting, tmp_path, capsys, monkeypatch):
    import pinocchio as pin

    from pin_kpi_oed.upkeep import check_design

    # the runs on one file ask for the same check design (seeded, the same model file): designed once, then reused,
    # since the check design is most of a run's time and this test is about the exit codes
    designed, real = {}, check_design.design_check

    def design_once(model, **kw):
        key = repr(sorted((k, np.asarray(v).tobytes() if isinstance(v, np.ndarray) else v) for k, v in kw.items()))
        if key not in designed:
            designed[key] = real(model, **kw)
        return designed[key]

    monkeypatch.setattr(check_design, "design_check", design_once)
    rb, model, Q, Y = setting
    mp = tmp_path / "m.json"
    model.save(mp)
    st = model.setups["A"]
    moved = model.with_setup("A", dataclasses.replace(st, tracker_T_base=(
        pin.SE3(st.tracker_T_base) * pin.exp6(np.r_[0.02, 0.0, 0.0, 0.0, 0.0, 0.01])).homogeneous))
    Y2 = np.vstack([Y[:20], moved.predict(Q[20:]) + (Y[20:] - model.predict(Q[20:]))])
    dp = tmp_path / "rows.csv"
    write_measurements(MeasurementSet(list(rb.joint_names), Q, Y2), dp)
    assert main(["monitor", "--model", str(mp), "--data", str(dp)]) == 0              # a moved set-up: followed
    assert main(["monitor", "--model", str(mp), "--data", str(dp), "--fail-on", "changed"]) == 1
    noisy = tmp_path / "noisy.csv"
    write_measurements(MeasurementSet(list(rb.joint_names), Q, Y + np.random.default_rng(1).normal(
        size=Y.shape) * 10 * SIGMA), noisy)
    assert main(["monitor", "--model", str(mp), "--data", str(noisy)]) == 3
    assert main(["monitor", "--model", str(mp), "--data", str(noisy), "--fail-on", "never"]) == 0
    assert len(designed) == 1                      # the two runs on the noisy file asked for the same poses
    capsys.readouterr()


def test_the_poses_the_monitor_asks_for_are_check_designs(setting):
    """The monitor asks for check design's poses without the poses the verdict needs (``size=False``, which it does
    not use): the same poses, powers and selection as the full design, bit for bit; only ``poses_needed`` is left
    out. A pool of 40 and 6 poses: the selection is the same code whatever the sizes, and the full design's
    ``poses_needed`` is still found (8 poses: the size is computed, not skipped by chance)."""
    from pin_kpi_oed.upkeep.check_design import design_check

    model = setting[1]
    kw = dict(m=6, tolerance_m=1e-4, pool_size=40, seed=0, n_random=1)
    full, poses = design_check(model, **kw), design_check(model, **kw, size=False)
    assert full.poses_needed > 0, "the full design found no size: the comparison would prove little"
    assert np.array_equal(poses.Q, full.Q) and np.array_equal(poses.selection.indices, full.selection.indices)
    assert poses.power == full.power and poses.verdict_power == full.verdict_power
    assert poses.poses_needed == 0


def test_a_followed_file_with_a_malformed_row_is_refused_naming_it(setting, tmp_path, capsys):
    rb, model, Q, Y = setting
    mp = tmp_path / "m.json"
    model.save(mp)
    path = tmp_path / "live.csv"
    write_measurements(MeasurementSet(list(rb.joint_names), Q, Y), path)
    lines = path.read_text().splitlines(keepends=True)
    k = next(i for i, line in enumerate(lines) if not line.startswith("#"))
    lines[k + 4] = "0.1,abc" + lines[k + 4][7:]
    path.write_text("".join(lines))
    plain = main(["monitor", "--model", str(mp), "--data", str(path)])
    err_plain = capsys.readouterr().err
    followed = main(["monitor", "--model", str(mp), "--data", str(path), "--follow", "--poll", "0.05", "--idle", "0.3"])
    err = capsys.readouterr().err
    assert plain == followed == 2
    assert err.count("\n") == 1 and str(path) in err and "tmp" not in err.replace(str(tmp_path), "")
    assert err.strip() == err_plain.strip()


def test_a_rewritten_file_with_other_times_is_named():
    from pin_kpi_oed.data.measurement_follow import FollowedFile

    rb = load_robot("ur10")
    rng = np.random.default_rng(3)
    Q = 0.5 * rng.uniform(rb.q_lower, rb.q_upper, size=(6, rb.nq))
    Y = rng.normal(size=(6, 3))
    import tempfile
    from pathlib import Path

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "live.csv"
        write_measurements(MeasurementSet(list(rb.joint_names), Q, Y, time_s=np.arange(6.0)), path)
        f = FollowedFile(path, {"joint_names": rb.joint_names})
        new, warn = f.poll()
        assert len(new) == 6 and warn == ""
        write_measurements(MeasurementSet(list(rb.joint_names), Q, Y, time_s=100 + np.arange(6.0)), path)
        new, warn = f.poll()
        assert len(new) == 6 and "rewritten" in warn


def test_every_block_of_rows_has_its_standardised_rms(setting, monkeypatch, tmp_path, capsys):
    """The standardised RMS of every block of rows (the last one as long as it is), from the rows' own z, in the log
    and in one line of the command; a second flush does not count the last block twice."""
    from pin_kpi_oed.upkeep import monitoring

    rb, model, Q, Y = setting
    monkeypatch.setattr(monitoring, "BLOCK_ROWS", 15)
    mon = monitoring.Monitor(model, every=10)
    mon.feed(MeasurementSet(list(rb.joint_names), Q, Y))
    mon.flush()
    mon.flush()
    log = mon.log()
    assert [(b["first_row"], b["last_row"]) for b in log.blocks] == [(1, 15), (16, 30), (31, 40)]
    for b in log.blocks:
        z = log.z[b["first_row"] - 1:b["last_row"]]
        assert b["z_rms"] == pytest.approx(np.sqrt(np.mean(z ** 2)))
    assert 0.5 < log.blocks[0]["z_rms"] < 2.0
    model.save(tmp_path / "m.json")
    write_measurements(MeasurementSet(list(rb.joint_names), Q, Y), tmp_path / "rows.csv")
    assert main(["monitor", "--model", str(tmp_path / "m.json"), "--data", str(tmp_path / "rows.csv")]) == 0
    out = [ln for ln in capsys.readouterr().out.splitlines() if "per block of 15 rows" in ln]
    assert len(out) == 1 and "1-15 " in out[0] and "31-40 " in out[0] and "outside the band: " in out[0]


def test_without_a_time_column_the_drift_level_is_per_row_and_said_so(setting):
    rb, model, Q, Y = setting
    untimed = monitor(model, MeasurementSet(list(rb.joint_names), Q, Y), every=10)
    assert not untimed.timed and "nm/sqrt(row) (no time column: one row taken as one second)" in untimed.summary()
    assert "nm/sqrt(s)" not in untimed.summary() and untimed.to_dict()["timed"] is False
    timed = monitor(model, MeasurementSet(list(rb.joint_names), Q, Y, time_s=np.arange(40.0) * 5), every=10)
    assert timed.timed and "nm/sqrt(s)" in timed.summary() and "sqrt(row)" not in timed.summary()
