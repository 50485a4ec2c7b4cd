"""monitor follows a file that grows while it is read and one truncated while read: a warning, nothing lost."""

from __future__ import annotations

import json

import numpy as np
import pytest

from pin_kpi_oed import load_robot
from pin_kpi_oed.cli.app import main
from pin_kpi_oed.data.measurement_follow import FollowedFile
from pin_kpi_oed.data.measurements import MeasurementSet, write_measurements
from pin_kpi_oed.studies.check_events import simulated_model

SIGMA = 2e-5


@pytest.fixture(scope="module")
def rows(tmp_path_factory):
    """A simulated model (file) and the lines of 60 rows measured on it: (model path, header, row lines)."""
    rb = load_robot("ur10")
    rng = np.random.default_rng(0)
    model = simulated_model(rb, 0.5 * rng.uniform(rb.q_lower, rb.q_upper, size=(5, rb.nq)), SIGMA, 0)
    Q = 0.7 * rng.uniform(rb.q_lower, rb.q_upper, size=(60, rb.nq))
    Y = model.predict(Q) + rng.normal(size=(60, 3)) * SIGMA
    d = tmp_path_factory.mktemp("follow")
    write_measurements(MeasurementSet(list(rb.joint_names), Q, Y), d / "all.csv")
    lines = (d / "all.csv").read_text().splitlines(keepends=True)
    model.save(d / "model.json")
    k = next(i for i, line in enumerate(lines) if not line.startswith("#"))
    return d / "model.json", "".join(lines[:k + 1]), lines[k + 1:]


def test_followed_file_returns_each_row_once_and_survives_truncation(rows, tmp_path):
    mp, head, body = rows
    rb = load_robot("ur10")
    f = FollowedFile(tmp_path / "live.csv", {"joint_names": rb.joint_names})
    path = tmp_path / "live.csv"
    path.write_text(head + "".join(body[:10]) + body[10][:15])            # a last line being written
    new, warn = f.poll()
    assert len(new) == 10 and warn == ""
    path.write_text(head + "".join(body[:16]))
    new, warn = f.poll()
    assert len(new) == 6 and warn == "" and f.returned == 16
    assert f.poll() == (None, "")
    path.write_text(head + "".join(body[30:33]))                           # truncated and rewritten
    new, warn = f.poll()
    assert len(new) == 3 and "truncated or rewritten" in warn and "16 row(s) used before" in warn
    assert "\n" not in warn
    path.write_text(head + "".join(body[30:35]))
    new, warn = f.poll()
    assert len(new) == 2 and warn == "" and f.returned == 21


def test_monitor_follows_a_growing_and_truncated_file(rows, tmp_path, capsys, monkeypatch):
    """The monitor follows a file that grows twice and is then truncated and rewritten while it is read: one
    warning, every row once. The tracker's writes come between the monitor's polls: each as soon as a poll has
    returned the rows written before it (a hook on the polls, not a clock), so no poll can miss a write or find the
    file idle however loaded the machine is; the idle limit (measured from the last row seen) only ends the run."""
    from pin_kpi_oed.data import measurement_follow

    mp, head, body = rows
    path = tmp_path / "live.csv"
    path.write_text(head + "".join(body[:12]))

    def append(a: int, b: int) -> None:
        with open(path, "a") as fh:
            fh.write("".join(body[a:b]))

    writes = {12: lambda: append(12, 25), 25: lambda: append(25, 40),     # grows twice
              40: lambda: path.write_text(head + "".join(body[40:60]))}     # truncated while read: new rows only
    done = []

    class Written(measurement_follow.FollowedFile):
        def poll(self):
            new, warning = super().poll()
            if new is not None and self.returned in writes:                  # the tracker writes after this poll
                writes[self.returned]()
                done.append(self.returned)
            return new, warning

    monkeypatch.setattr(measurement_follow, "FollowedFile", Written)
    out_json = tmp_path / "log.json"
    code = main(["monitor", "--model", str(mp), "--data", str(path), "--follow", "--poll", "0.05", "--idle", "0.3",
                 "--every", "50",
                 "--json", str(out_json)])
    assert code == 0 and done == [12, 25, 40]
    err = capsys.readouterr().err
    assert err.count("truncated or rewritten") == 1 and "40 row(s) used before" in err
    log = json.loads(out_json.read_text())
    assert log["rows"] == 60 and len(log["error_m"]) == 60                  # nothing lost, nothing twice
    assert log["z_rms"] < 2.0


@pytest.mark.parametrize("opt", ["--poll", "--idle"])
def test_follow_timing_options_must_be_positive_seconds(tmp_path, capsys, opt):
    """--poll / --idle of 0 s: one line naming the option, exit 2, before any file is read."""
    code = main(["monitor", "--model", str(tmp_path / "none.json"), "--data", str(tmp_path / "none.csv"), "--follow",
                 opt, "0"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and opt in err and "none.json" not in err
