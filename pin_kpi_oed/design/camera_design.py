r"""KPI designs of a camera calibration whose every pose sees the board (paper eq. 24 with the camera's constraints).

The design problem of a camera (:class:`~pin_kpi_oed.model.camera.CameraModel`, eye-in-hand or eye-to-hand) in a
cell built in code (:func:`~pin_kpi_oed.cell.camera_view.camera_cell`)::

    min_Q   φ(C(Q)) / φ(C(Q₀))                            (24a; φ = tr C_s, the TCP in the device frame)
    s.t.    q_lo ≤ q_i ≤ q_hi
            c(q_i) ≥ δ                                    (the KS aggregate of the capsule pairs and half-spaces)
            v_k(q_i) ≥ δ,  k = image, depth, angle, rays  (the camera's rows, :mod:`pin_kpi_oed.cell.camera_view`)

as the tracker's (:mod:`pin_kpi_oed.design.optimize`): the criterion of the information matrix is
:class:`~pin_kpi_oed.oed.objective.DesignCriterion` on the camera's weighted Jacobian, the constraints enter the one
IPOPT run (:func:`~pin_kpi_oed.design.ipopt.solve_ipopt`) as one more constraint set (:class:`CameraConstraints`:
the cell's aggregated collision rows and the camera's four aggregated rows, each ≥ 0 only when every row it
aggregates is). The tracker's laser beam and incidence are not part of a camera cell.

Candidates. A camera sees the board from a small part of the joint space, so the pool is sampled around
configurations known to see it (the working configurations by default), uniformly in a box of ``spread`` rad,
clipped to the joint bounds, and kept when every constraint holds (:meth:`CameraDesignProblem.pool`). The pool
selection of the KPI criterion comes with its certificate (:func:`~pin_kpi_oed.oed.certificate.certify_pool`: the
relaxation's lower bound of tr C_s over every m-pose design from the pool), and starts IPOPT; the design returned
is the better of the two that passes the fast feasibility path, then the independent check
(:func:`~pin_kpi_oed.cell.camera_check.check_camera_poses`: OpenCV's projection, Coal's ray distances).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from pin_kpi_oed.cell.aggregate import AggregatedConstraints
from pin_kpi_oed.cell.camera_check import CameraCheck, check_camera_poses
from pin_kpi_oed.cell.camera_view import CameraView, ViewLimits
from pin_kpi_oed.cell.cell_model import Cell
from pin_kpi_oed.cell.collision import CollisionModel
from pin_kpi_oed.design.ipopt import IpoptRun, solve_ipopt
from pin_kpi_oed.errors import InfeasibleError, InputError
from pin_kpi_oed.model.camera import CameraModel
from pin_kpi_oed.oed.certificate import Certificate, certify_pool
from pin_kpi_oed.oed.identifiability import analyse, check_kpi
from pin_kpi_oed.oed.objective import DesignCriterion
from pin_kpi_oed.results import Result
from pin_kpi_oed.threads import limit_threads

__all__ = ["CameraConstraints", "CameraDesignProblem", "CameraDesign", "design_camera"]


class CameraConstraints:
    """The rows IPOPT sees per configuration: the cell's aggregated collision rows, then the camera's aggregated
    rows (image px, depth m, angle cos, rays m); block-sparse, dense within a configuration.

    Args:
        coll: the cell's collision model (capsule pairs, half-spaces; no incidence row).
        view: the camera's constraints.
        ks_length_m: KS smoothing length of the collision rows (m).
    """

    def __init__(self, coll: CollisionModel, view: CameraView, ks_length_m: float = 2e-3):
        self.coll_rows = AggregatedConstraints(coll, "ks", ks_length_m, backend="numpy")
        self.view, self.coll = view, coll
        self.n = coll.n
        self.units = list(self.coll_rows.units) + view.aggregate_units
        self.names = list(self.coll_rows.names) + view.aggregate_names
        self.n_rows = len(self.units)
        r, c = np.meshgrid(np.arange(self.n_rows), np.arange(self.n), indexing="ij")
        self.jac_rows, self.jac_cols = r.ravel(), c.ravel()

    def evaluate(self, Q: np.ndarray, with_grad: bool = True) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
        """Rows (m, n_rows) and, with ``with_grad``, ∂/∂q (m, n_rows, n) (m, px, cos)."""
        Q = np.atleast_2d(np.asarray(Q, float))
        if not with_grad:
            gc = self.coll_rows.evaluate(Q, with_grad=False)
            return np.concatenate([gc, self.view.aggregate(Q, False)[0]], axis=1)
        gc, Gc = self.coll_rows.evaluate(Q, with_grad=True)
        gv, Gv = self.view.aggregate(Q, True)
        assert Gv is not None
        return np.concatenate([gc, gv], axis=1), np.concatenate([Gc, Gv], axis=1)

    def feasible(self, Q: np.ndarray, tol: float = 0.0) -> np.ndarray:
        """Every raw row (collision and camera) ≥ −tol and within the joint bounds, (m,) bool."""
        Q = np.atleast_2d(np.asarray(Q, float))
        return self.coll.feasible(Q, tol) & self.view.feasible(Q, tol)


class CameraDesignProblem:
    """The design problem of a camera in a cell (module docstring); what :func:`solve_ipopt` reads (``cell``,
    ``cons``, ``coll``, ``criterion``).

    Args:
        cell: the cell (robot capsules, obstacles, half-spaces, joint bounds; its tracker is not used).
        camera: the nominal camera model (its TCP is the KPI point).
        limits: what the camera needs to see the board (:class:`~pin_kpi_oed.cell.camera_view.ViewLimits`).
        q_work: working configurations of the KPI (t, n) rad; they also seed the candidate pool.
        excitation: configurations for the identifiability analysis (default 15 feasible ones around ``q_work``).

    Raises:
        InputError: no working configuration, or a robot of another joint count.
        IdentifiabilityError: the TCP at the working configurations is not estimable from the camera.
    """

    @limit_threads  # the identifiability analysis (QR, lstsq) with every BLAS thread on a busy machine: 10x slower
    def __init__(self, cell: Cell, camera: CameraModel, limits: ViewLimits | None, q_work: np.ndarray,
                 excitation: np.ndarray | None = None):
        self.cell, self.model = cell, camera
        self.q_work = np.atleast_2d(np.asarray(q_work, float))
        if self.q_work.size == 0 or self.q_work.shape[1] != cell.robot.nq:
            raise InputError(f"q_work: working configurations of {cell.robot.nq} joint values needed, got "
                             f"{self.q_work.shape}")
        self.collision_model = CollisionModel(cell, collision=True, incidence=False)
        self.view = CameraView(camera, limits, self.collision_model)
        self.coll = self.cons = CameraConstraints(self.collision_model, self.view)
        self.p0 = np.zeros(camera.n_params)
        if excitation is None:
            excitation = self.pool(15, seed=12345)[0]
        self.ident = analyse(camera, Q=excitation)
        E_full = camera.kpi_jacobian(self.p0, self.q_work)
        check_kpi(self.ident, camera, E_full, "the camera design: the TCP at the working configurations")
        self.base = self.ident.base
        self.E = E_full[:, self.base]

    @property
    def n(self) -> int:
        """Joints per configuration."""
        return self.cell.robot.nq

    def criterion(self, name: str) -> DesignCriterion:
        """The design objective of a registered criterion of the information matrix (``kpi``: tr C_s)."""
        return DesignCriterion(self.model, self.base, name, self.E)

    def pool(self, size: int, seed: int = 0, around: np.ndarray | None = None, spread: float = 0.8,
             max_tries: int = 200_000) -> tuple[np.ndarray, int]:
        """Feasible candidates: uniform within ``spread`` (rad, m) of configurations seeing the board, clipped to
        the joint bounds, every constraint satisfied (module docstring).

        Args:
            size: candidates wanted.
            seed: seed of the sampling.
            around: configurations to sample around (k, n); default the working configurations.
            spread: half width of the box around each (rad for revolute, m for prismatic joints).
            max_tries: sampling budget.

        Returns:
            (Q (size, n) rad, samples drawn).

        Raises:
            InfeasibleError: fewer than ``size`` feasible candidates in ``max_tries`` samples.
        """
        rng = np.random.default_rng(seed)
        centres = self.q_work if around is None else np.atleast_2d(np.asarray(around, float))
        lo, hi = self.cell.q_lower, self.cell.q_upper
        found: list[np.ndarray] = []
        drawn = 0
        while sum(len(f) for f in found) < size and drawn < max_tries:
            k = min(4000, max_tries - drawn)
            Q = centres[rng.integers(len(centres), size=k)] + rng.uniform(-spread, spread, (k, self.n))
            Q = np.clip(Q, lo, hi)
            drawn += k
            found.append(Q[self.cons.feasible(Q)])
        Q = np.concatenate(found) if found else np.zeros((0, self.n))
        if len(Q) < size:
            raise InfeasibleError(f"camera design: {len(Q)} of {size} candidates see the board and are collision-"
                                  f"free in {drawn} samples; widen spread or the view limits, or give configurations "
                                  f"that see the board (around)")
        return Q[:size], drawn

    def trace_cs(self, Q: np.ndarray) -> float:
        """tr C_s (m²) of a design over the identifiable parameters (eq. 19, the held ones not counted)."""
        return float(self.criterion("kpi").value(np.atleast_2d(Q)))


@dataclass(kw_only=True)
class CameraDesign(Result):
    """A camera design (a :class:`~pin_kpi_oed.results.Result`; ``success``: every pose passed the independent
    check).

    Attributes:
        Q: the design (m, n) rad; trace_cs_m2: its tr C_s (m²).
        Q_selection: the pool selection (IPOPT's start); selection_trace_cs_m2: its tr C_s (m²).
        certificate: the pool's relaxation bound (:class:`~pin_kpi_oed.oed.certificate.Certificate`).
        efficiency: bound / tr C_s of the design (1 = certified optimal over the pool; the bound covers the designs
            made of the pool's candidates, and IPOPT's poses leave the pool, so an IPOPT design may exceed 1: then it
            is no efficiency, :attr:`stated_efficiency` is None).
        ipopt: the IPOPT run, or None; source: ``ipopt`` or ``selection`` (the design returned).
        check: the independent check of the returned design.
    """

    Q: np.ndarray
    trace_cs_m2: float
    Q_selection: np.ndarray
    selection_trace_cs_m2: float
    certificate: Certificate
    efficiency: float
    ipopt: IpoptRun | None
    source: str
    check: CameraCheck

    @property
    def stated_efficiency(self) -> float | None:
        """The efficiency when it is one (at most 1 + :data:`EFFICIENCY_SLACK`: a design of the pool's candidates,
        or an IPOPT design the bound still covers), else None: the design left the pool and beat the bound of the
        pool's designs, which says the pool misses the best poses, not how near the optimum the design is."""
        return self.efficiency if self.efficiency <= 1.0 + EFFICIENCY_SLACK else None

    def efficiency_text(self) -> str:
        """``efficiency X % of the pool's bound``, or why none is stated."""
        eff = self.stated_efficiency
        if eff is not None:
            return f"efficiency {eff:.1%} of the pool's bound"
        return (f"below the pool's bound by a factor {self.efficiency:.2f} (its poses leave the pool: no efficiency; "
                f"the pool selection's is {self.certificate.efficiency(self.selection_trace_cs_m2):.1%})")


    def ipopt_note(self) -> str:
        """A note when IPOPT ran and did not converge (its iteration or time limit, a stall, a failure): the design
        is then the best feasible point found, not a local optimum.

        Returns:
            One line starting ``note: IPOPT not converged``, or "" when IPOPT converged or did not run.
        """
        run = self.ipopt
        if run is None or run.status in ("converged", "acceptable"):
            return ""
        why = {"max_iter": f"stopped at its iteration limit ({run.nit})", "max_time": "stopped at its time limit",
               "stalled": "stalled"}.get(run.status, "failed")
        kept = ("its last feasible point is the design" if self.source == "ipopt"
                else "the pool selection is the design")
        return (f"note: IPOPT not converged: {why} after {run.nit} iterations ({run.status}: {run.solver_status}); "
                f"{kept}, not a local optimum" + (": raise --max-iter" if run.status == "max_iter" else ""))


#: Rounding slack of an efficiency (a pool design's tr C_s recomputed is at the bound to ~1e-12).
EFFICIENCY_SLACK = 1e-9


def square_roots(Fp: np.ndarray) -> np.ndarray:
    """Each candidate's rows replaced by the triangular factor of its information (QR: R_iᵀR_i = F_iᵀF_i), (N, k,
    nb) with k = min(nh, nb): the same information, so the same selection and certificate, on fewer rows (an image
    has 2 rows per corner, 96 for an 8 x 6 board, against some 30 parameters)."""
    if Fp.shape[1] <= Fp.shape[2]:
        return Fp
    return np.asarray(np.linalg.qr(Fp, mode="r"))


@limit_threads
def design_camera(problem: CameraDesignProblem, m: int, seed: int = 0, pool_size: int = 600,
                  ipopt: bool = True, ipopt_options: dict | None = None) -> CameraDesign:
    """The KPI design of m poses: pool selection with its certificate, then IPOPT from it (module docstring).

    Args:
        problem: the camera's design problem.
        m: poses.
        seed: seed of the pool.
        pool_size: feasible candidates.
        ipopt: refine the selection by IPOPT (False: the selection is the design).
        ipopt_options: IPOPT options (default :func:`~pin_kpi_oed.design.ipopt.ipopt_options`).

    Returns:
        The :class:`CameraDesign`.

    Raises:
        InputError: m too small to identify the parameters.
        InfeasibleError: not enough feasible candidates.
    """
    t0 = time.perf_counter()
    if m * problem.model.nh < problem.base.size:
        raise InputError(f"m={m} images cannot identify {problem.base.size} parameters")
    Q_pool, drawn = problem.pool(pool_size, seed)
    crit = problem.criterion("kpi")
    cert = certify_pool(square_roots(crit.jacobians(Q_pool)), m, problem.E, Q_pool, drawn)
    Q_sel = Q_pool[cert.pool_selection]
    v_sel = problem.trace_cs(Q_sel)
    Q, v, run, source = Q_sel, v_sel, None, "selection"
    if ipopt:
        run = solve_ipopt(problem, "kpi", Q_sel, ipopt_options)
        if run.success and problem.cons.feasible(run.Q).all() and run.value < v_sel:
            Q, v, source = run.Q, problem.trace_cs(run.Q), "ipopt"
    chk = check_camera_poses(problem.view, Q)
    ok = bool(chk.ok.all())
    design = CameraDesign(Q=Q, trace_cs_m2=v, Q_selection=Q_sel, selection_trace_cs_m2=v_sel, certificate=cert,
                          efficiency=cert.efficiency(v), ipopt=run, source=source, check=chk, success=ok,
                          status="feasible" if ok else "infeasible", nit=run.nit if run else 0,
                          nfev=run.nfev if run else 0, time_s=time.perf_counter() - t0)
    design.message = (f"{m} poses ({source}): tr C_s {v:.4g} m^2, {design.efficiency_text()}; independent check: "
                      f"{int(chk.ok.sum())} of {m} poses see the board")
    return design
