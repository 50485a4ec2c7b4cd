"""URDFs as they ship: a xacro-generated file with ``${prefix}`` in a comment loads, a real xacro file is refused; the
identifiable set and the design figures do not depend on the rounding of a URDF's numbers (``1.5708`` vs π/2); a
near-singular information is refused naming the parameters, never printed as a covariance with a negative
eigenvalue."""

from __future__ import annotations

import re

import numpy as np
import pytest

from benchmarks.urdf_rounding import exact_urdf_text, rounded_urdf_text, tracker_model
from pin_kpi_oed.errors import IdentifiabilityError, RobotLoadError
from pin_kpi_oed.model.robot import erd_root, load_robot
from pin_kpi_oed.oed.evaluate import score_design
from pin_kpi_oed.oed.identifiability import RANK_TOL, analyse

XARM = "xarm_description/urdf/xarm7.urdf"


@pytest.fixture(scope="module")
def xarm_copies(tmp_path_factory):
    """The xArm7 URDF as it ships (``rpy="1.5708 0 0"``), with exact π/2, and with every number rounded to 4
    decimals."""
    d = tmp_path_factory.mktemp("xarm")
    text = (erd_root() / XARM).read_text()
    (d / "exact.urdf").write_text(exact_urdf_text(text))
    (d / "rounded.urdf").write_text(rounded_urdf_text(text))
    assert "1.5707963267948966" in (d / "exact.urdf").read_text() and "1.5708" in text
    return {"shipped": erd_root() / XARM, "exact": d / "exact.urdf", "rounded": d / "rounded.urdf"}


def test_xacro_text_in_a_comment_is_plain_urdf(tmp_path):
    """The xArm7 as it ships keeps '${prefix}' and 'xacro' inside XML comments: it loads; the same text in an
    element's text too; a property in an attribute value or a xacro element is refused, naming the file, the
    construct and the command that expands it."""
    text = (erd_root() / XARM).read_text()
    assert "${prefix}" in text and "<!--" in text
    robot = load_robot(str(erd_root() / XARM), tool_frame="link7")
    assert robot.nq == 7
    kr = (erd_root() / "ur_description/urdf/ur5_robot.urdf").read_text()
    ok = tmp_path / "commented.urdf"
    ok.write_text(kr.replace("</robot>", "<!-- <xacro:macro name='m'> ${prefix}link </xacro:macro> -->"
                                         "<description>made by xacro from ${prefix}ur.xacro</description></robot>"))
    assert load_robot(str(ok), tool_frame="tool0").nq == 6
    bad = tmp_path / "prop.urdf"
    bad.write_text(kr.replace('xyz="0.0 0.0 0.089159"', 'xyz="0.0 0.0 ${d1}"', 1))
    with pytest.raises(RobotLoadError, match=r"prop\.urdf: a xacro file.*xyz='0\.0 0\.0 \$\{d1\}'.*'xacro .*prop\.urdf "
                                             r"> robot\.urdf'"):
        load_robot(str(bad), tool_frame="tool0")
    real = erd_root() / "hector_description/robots/quadrotor_base.urdf.xacro"
    with pytest.raises(RobotLoadError, match=r"quadrotor_base\.urdf\.xacro: a xacro file, not plain URDF \(element "
                                             r"<xacro:property>\): expand it first \('xacro "):
        load_robot(str(real))


def test_rounded_urdf_gives_the_same_identifiable_set_and_design_figures(xarm_copies):
    """1.5708 against π/2 (and every number rounded to 4 decimals): the same identifiable parameters, and the same
    tr C_s and criteria of one seeded design within 0.1 % (measured: within 1e-5)."""
    models = {k: tracker_model(load_robot(str(p), tool_frame="link7")) for k, p in xarm_copies.items()}
    idents = {k: analyse(m) for k, m in models.items()}
    assert idents["shipped"].base_names == idents["exact"].base_names == idents["rounded"].base_names
    assert idents["exact"].rank == 31  # 4 per joint + 6 - 3 for a 7R arm with the reflector off the tool axis
    rng = np.random.default_rng(3)
    robot = models["exact"].robot
    Q, W = robot.random_q(rng, 35), robot.random_q(rng, 3)
    scores = {k: score_design(m, Q, W, ident=idents[k]) for k, m in models.items()}
    ref = scores["exact"]
    for k in ("shipped", "rounded"):
        s = scores[k]
        assert s.status == "scored" and s.trace_cs_m2 == pytest.approx(ref.trace_cs_m2, rel=1e-3)
        for name in ("kpi", "param", "E", "cond"):
            assert s.criteria[name] == pytest.approx(ref.criteria[name], rel=1e-3), (k, name)
        for name in ("O1", "O3"):  # log criteria: their argument within 0.1 %
            assert abs(s.criteria[name] - ref.criteria[name]) < 1e-3, (k, name)
        assert abs(s.criteria["D"] - ref.criteria["D"]) / ref.rank < 1e-3  # det M within 0.1 % per parameter


def test_a_tolerance_below_the_rounding_reproduces_the_failure_and_it_is_refused(xarm_copies):
    """The old tolerance (1e-6, below the 4e-6 that 1.5708 leaves) keeps rounding-induced columns: the information of
    a good design is then numerically singular. It is refused naming the parameters that move the measurements alike,
    never scored with a negative eigenvalue (the E criterion was printed as -251274)."""
    model = tracker_model(load_robot(str(xarm_copies["shipped"]), tool_frame="link7"))
    loose = analyse(model, tol=1e-6)
    assert loose.rank > analyse(model).rank and RANK_TOL >= 1e-2
    rng = np.random.default_rng(3)
    Q, W = model.robot.random_q(rng, 35), model.robot.random_q(rng, 3)
    # which rounding-induced columns a 1e-6 tolerance keeps is itself decided at rounding level: two or more are named
    with pytest.raises(IdentifiabilityError, match=r"singular information matrix: '[\w.]+' and '[\w.]+'( \(and \d+ "
                                                   r"more\))? move the measurements alike in every measured pose \(the "
                                                   r"combination "):
        score_design(model, Q, W, ident=loose)


def test_e_criterion_of_an_ill_conditioned_information_is_positive():
    """E-optimality is the largest eigenvalue of C_p, taken from C_p: positive for a positive definite but badly
    conditioned M (1/λ_min(M) gave a negative number when eigh returned λ_min < 0), and refused once M is singular on
    the scaled basis."""
    from pin_kpi_oed.oed.criteria import CRITERIA

    rng = np.random.default_rng(0)
    A = rng.standard_normal((40, 6))
    A[:, 5] = A[:, 4] + 1e-5 * rng.standard_normal(40)  # nearly parallel columns: condition about 1e10
    val = CRITERIA["E"].value(A)
    assert val > 0 and val == pytest.approx(np.linalg.svd(A, compute_uv=False)[-1] ** -2, rel=1e-5)
    A[:, 5] = A[:, 4] * (1 + 1e-15)
    with pytest.raises(IdentifiabilityError, match="'column 5' and 'column 4' move the measurements alike|"
                                                   "'column 4' and 'column 5' move the measurements alike"):
        CRITERIA["E"].value(A)


def test_a_singular_criterion_is_printed_as_singular_not_a_number(xarm_copies):
    """With a prior the covariance exists while F alone is singular (one pose repeated): C_s is scored, the criteria
    of F (cond, O1-O5) say 'singular' with the parameters and what to change, and the status is not ok."""
    model = tracker_model(load_robot(str(xarm_copies["exact"]), tool_frame="link7"))
    model.layout.prior_sigma[:] = 1e-3
    q = model.robot.random_q(np.random.default_rng(1), 1)
    score = score_design(model, np.repeat(q, 12, axis=0), q)
    assert np.isfinite(score.trace_cs_m2) and score.trace_cs_m2 > 0
    assert {"cond", "O2", "O3"} <= set(score.singular) and not score.success and score.status == "singular"
    text = score.summary()
    assert "cond    singular" in text and not re.search(r"^\S+\s+-?inf\b", text, re.M)
    assert "move the measurements alike in every measured pose" in text and "add measurement configurations" in text
    assert score.to_dict()["criteria"]["cond"] == float("inf")  # written as null by the JSON helper, never a number
