"""Identifiability: the base (identifiable) parameter set and KPI estimability.

The weighted Jacobian F of a rich random excitation (many configurations
within the joint limits) is rank deficient: some parameter combinations move
no measurement. A 6R arm measured at one reflector has 45 raw parameters and
rank 27 = 4·6 + 6 − 3: per joint, the translation along and the rotation about
its axis commute with the joint motion and are absorbed by the next placement;
joint 1's placement is absorbed by the tracker pose; the last joint's two by
the reflector offset.

Selection (QR with ordered pivoting) on a scaled basis: every column of F is
scaled to unit norm — the measurements' change for a parameter error of its own
size, so metres and radians, a tolerance or any other physical scale of a
parameter give the same decision — and the columns are visited in a preference
order; a column is kept when the share of it that the columns kept so far cannot
reproduce (its orthogonal residual, 0 … 1) exceeds :data:`RANK_TOL` = 1e-2. The
rank is that count; SciPy's QR with column pivoting at the same tolerance
cross-checks it (a disagreement is noted).

**Why 1e-2.** A URDF states its numbers rounded (``rpy="1.5708 0 0"``, not
π/2; 4 decimals leave errors up to 5e-5 rad and 5e-5 m, hand-written files
1e-4). Rounding does not change how many directions the measurements see (the
structure of an arm's null space does not depend on its numbers), it tilts the
exact dependencies: a column that the kept ones reproduce exactly at π/2
keeps a residual of the size of the rounding error (measured: at most 4.5e-6
on the 16 arms of ``benchmarks.urdf_rounding``, whose rounded angles are off
by 3.7e-6: 1.2 × the angle error). A tolerance of 1e-6 kept
such columns as "identifiable" in place of genuinely identifiable ones, and
the design's information matrix was singular. 1e-2 is 100 × above the
rounding of a 1e-4 rad angle and below real information: the smallest
residual of a kept column on the serial arms of example-robot-data with a
reflector off the tool axis is 0.13 (SO-101) … 0.49 (``python -m
benchmarks.urdf_rounding``), and a column with a residual below 1e-2 holds
less than 1e-4 of its effect apart from the others (its σ 100 × the σ it
would have alone: a 1 mrad error at a 1 m lever then moves the measurements by
10 µm, the noise of a tracker), which no calibration can estimate. So the
identifiable set and every design figure are the same for ``1.5708`` and π/2.

**Convention** (the paper's, implicitly):
measurement-set-up parameters (the device's groups: tracker, reflector, probe) come first, so when a
robot parameter is confounded with a set-up parameter, the *robot* parameter is
the one held at its nominal value. Every dropped parameter is reported with
the kept parameters it is confounded with.

This is what makes the regularity condition (PD) of the paper (eq. 15) hold.

KPI estimability: a KPI s with sensitivity E is estimable under this
convention iff E n = 0 for every null direction n of F that leaves the
device's target groups (reflector and probe) unchanged (those directions only
re-label which physical point is the tool frame, which the convention fixes). A TCP in the robot base
frame fails when the tracker pose is unknown (joint 1 ↔ tracker), and a TCP
away from a reflector that sits on the last joint axis fails (the tool's
rotation about that axis is invisible).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import cast

import numpy as np

from pin_kpi_oed.errors import IdentifiabilityError
from pin_kpi_oed.model.device import MeasurementModel
from pin_kpi_oed.results import Result


@dataclass
class Identifiability(Result):
    """Result of the identifiability analysis (a :class:`~pin_kpi_oed.results.Result`: ``status`` ``full rank`` or
    ``rank deficient`` — the free parameters the data cannot tell apart are dropped, a normal outcome: ``success``
    either way —, ``message`` the rank in words).

    Attributes:
        names: raw parameter names.
        base: indices of the identifiable parameters (vector order).
        rank: rank of the free columns of F.
        n_raw: number of raw parameters.
        n_free: number of parameters not fixed by the user.
        dropped: one entry per free but non-identifiable parameter:
            ``{"name", "confounded_with": [...], "convention": bool}``.
        notes: plain-words explanations (e.g. reflector on the last joint axis).
        null_space: basis of the null space of F over all raw parameters, (n_raw, k) (unscaled).
        setup_groups: the measurement device's set-up groups (e.g. ``tracker``, ``reflector``).
    """

    names: list[str]
    base: np.ndarray
    rank: int
    n_raw: int
    n_free: int
    dropped: list[dict] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    null_space: np.ndarray | None = None
    setup_groups: tuple[str, ...] = ()

    @property
    def base_names(self) -> list[str]:
        """Names of the identifiable parameters."""
        return [self.names[i] for i in self.base]

    def groups_text(self) -> list[str]:
        """Confounded groups in plain words, one line per (held group, partners) pair."""
        agg: dict[tuple[str, str], list[str]] = {}
        for d in self.dropped:
            grp = d["name"].split(".")[0]
            partners = sorted({c.split(".")[0] for c in d["confounded_with"]})
            key = (grp, ", ".join(partners) if partners else "nothing")
            agg.setdefault(key, []).append(d["name"].split(".")[1])
        lines = []
        for (grp, with_text), comps in agg.items():
            conv = " (convention: the robot parameter is held nominal)" if any(
                p in with_text for p in self.setup_groups) else ""
            if with_text == "nothing":
                lines.append(f"{grp}.{{{','.join(comps)}}} held at nominal: not observable with this set-up")
            else:
                lines.append(f"{grp}.{{{','.join(comps)}}} held at nominal: confounded with {with_text}{conv}")
        return lines

    def summary(self) -> str:
        """Readable multi-line summary."""
        out = [f"raw parameters: {self.n_raw}, free: {self.n_free}, identifiable (rank): {self.rank}"]
        out += ["  " + s for s in self.groups_text()]
        out += ["  note: " + s for s in self.notes]
        return "\n".join(out)

    def to_dict(self) -> dict:
        """Plain JSON-able dict."""
        return {**self.result_dict(), "n_raw": self.n_raw, "n_free": self.n_free, "rank": self.rank,
                "identifiable": self.base_names, "dropped": self.dropped, "groups": self.groups_text(),
                "notes": self.notes}


def pivoted_qr_diagonal(A: np.ndarray) -> np.ndarray:
    """|R_kk| of the QR factorisation with column pivoting of A (Householder, the column of largest remaining norm
    first, as LAPACK's ``geqp3``; the remaining norms recomputed at each step), in NumPy: the rank needs no SciPy.

    Args:
        A: (m, n) matrix.

    Returns:
        (min(m, n),) the diagonal of R in absolute value, non-increasing up to rounding.
    """
    R = np.array(A, float, copy=True)
    if R.shape[0] > R.shape[1]:
        # A = Q₀R₀ (Householder, no pivoting; Q₀ orthonormal): every column norm and every projection the pivoted
        # factorisation takes is the same on R₀ (n x n) as on A, so its |R_kk| are A's, at a fraction of the work
        R = cast(np.ndarray, np.linalg.qr(R, mode="r"))  # mode "r": R alone (typed as the pair)
    m, n = R.shape
    out = np.zeros(min(m, n))
    for k in range(min(m, n)):
        rest = np.einsum("ij,ij->j", R[k:, k:], R[k:, k:])
        j = k + int(np.argmax(rest))
        if j != k:
            R[:, [k, j]] = R[:, [j, k]]
        x = R[k:, k]
        alpha = float(np.linalg.norm(x))
        out[k] = alpha
        if alpha == 0.0:
            break
        v = x.copy()
        v[0] += np.copysign(alpha, x[0])
        v /= np.linalg.norm(v)
        R[k:, k + 1:] -= 2.0 * np.outer(v, v @ R[k:, k + 1:])
    return out


def excitation(model: MeasurementModel, n: int = 200, seed: int = 0) -> np.ndarray:
    """Rich random excitation: ``n`` configurations uniform within the joint limits (rad)."""
    return model.robot.random_q(np.random.default_rng(seed), n)


#: the residual share below which a parameter's effect on the measurements counts as reproduced by the kept
#: parameters (scaled basis: unit-norm columns); see the module docstring for the choice
RANK_TOL = 1e-2


def ordered_selection(Fs: np.ndarray, order: list[int], tol: float = RANK_TOL) -> tuple[list[int], np.ndarray]:
    """Columns of ``Fs`` (unit norm) kept in the given order: each whose orthogonal residual to the columns kept
    before it exceeds ``tol``.

    Args:
        Fs: unit-norm columns, (rows, k).
        order: the visiting order (column indices of ``Fs``).
        tol: the residual share (0 … 1) below which a column is reproduced by the kept ones.

    Returns:
        (kept column indices in visiting order, the residual share of every column in ``Fs``'s order).
    """
    F = np.asarray(Fs, float)
    if F.shape[0] > F.shape[1]:
        # Fs = Q₀R₀: the residuals of R₀'s columns are those of Fs's (Q₀ orthonormal); mode "r": R₀ alone
        F = cast(np.ndarray, np.linalg.qr(F, mode="r"))
    basis = np.zeros((len(order), F.shape[0]))  # the kept unit residuals, one per row
    kept: list[int] = []
    resid = np.zeros(F.shape[1])
    for c in order:
        v = F[:, c].copy()
        B = basis[:len(kept)]
        for _ in range(2):  # classical Gram-Schmidt, twice ("twice is enough" for orthogonality to rounding)
            v -= B.T @ (B @ v)
        resid[c] = nv = float(np.linalg.norm(v))
        if nv > tol:
            basis[len(kept)] = v / nv
            kept.append(c)
    return kept, resid


def analyse(model: MeasurementModel, Q: np.ndarray | None = None, prefer: list[str] | None = None,
            tol: float = RANK_TOL, seed: int = 0) -> Identifiability:
    """Find the identifiable parameter set.

    Args:
        model: measurement model (its layout's ``fixed`` parameters are excluded).
        Q: excitation configurations (rad); default 200 random ones (``seed``).
        prefer: name patterns to keep first (overrides the convention's order; e.g.
            ``["joint_a1.*"]`` keeps joint 1's placement instead of the tracker pose).
        tol: the residual share (0 … 1) of a unit-norm column below which the kept columns reproduce it
            (:data:`RANK_TOL`; dimensionless, the same for every unit and scale of a parameter).
        seed: seed of the default excitation.

    Returns:
        The :class:`Identifiability`.
    """
    L = model.layout
    if Q is None:
        Q = excitation(model, seed=seed)
    p0 = np.zeros(L.n)
    F = model.weighted_jacobian(p0, Q).reshape(-1, L.n)
    free = np.flatnonzero(~L.fixed)
    norms = np.linalg.norm(F, axis=0)
    zero = [int(i) for i in free if norms[i] <= 1e-12 * max(norms.max(), 1e-300)]
    cand = [int(i) for i in free if i not in zero]
    Fs = F[:, cand] / norms[cand]
    # ordered selection: user preference, then set-up parameters, then robot base-to-tip
    setup = L.is_setup()
    pref = L.select(prefer) if prefer else np.zeros(L.n, bool)
    order = sorted(range(len(cand)), key=lambda c: (not pref[cand[c]], not setup[cand[c]], cand[c]))
    kept, _ = ordered_selection(Fs, order, tol)
    kept_idx = sorted(cand[c] for c in kept)
    rank = len(kept_idx)
    dropped = _dropped(L, F, norms, free, zero, kept_idx, setup)
    # null space over the free parameters (for KPI checks), unscaled
    _, s, Vt = np.linalg.svd(F[:, free] / np.where(norms[free] > 0, norms[free], 1.0), full_matrices=False)
    null_free = Vt[rank:].T / np.where(norms[free] > 0, norms[free], 1.0)[:, None]
    N = np.zeros((L.n, null_free.shape[1]))
    N[free] = null_free
    notes = model.identifiability_notes()
    qr_rank = _qr_rank(Fs, tol)
    if qr_rank != rank:
        notes.append(f"the ordered selection kept {rank} columns, the pivoted QR at the same tolerance {tol:g} "
                     f"counts {qr_rank}: some parameters are nearly confounded")
    return Identifiability(L.names, np.array(kept_idx, int), rank, L.n, len(free), dropped, notes, N,
                           L.setup_groups, success=True, status="full rank" if rank == len(free) else "rank deficient",
                           message=f"{rank} of {len(free)} free parameters identifiable")


def _qr_rank(Fs: np.ndarray, tol: float) -> int:
    """Rank of unit-norm columns by the QR with column pivoting (:func:`pivoted_qr_diagonal`): diagonal entries
    above ``tol`` (the greedy residual shares)."""
    if Fs.size == 0:
        return 0
    return int(np.sum(pivoted_qr_diagonal(Fs) > tol))


def _dropped(L, F: np.ndarray, norms: np.ndarray, free: np.ndarray, zero: list[int], kept_idx: list[int],
             setup: np.ndarray) -> list[dict]:
    """One entry per free parameter not kept: its name and the kept parameters it is confounded with."""
    B = F[:, kept_idx] / norms[kept_idx]
    dropped = []
    others = [int(i) for i in free if i not in kept_idx and i not in zero]
    # every dropped column on the kept ones in one least-squares solve (B has full column rank)
    X = np.linalg.lstsq(B, F[:, others] / norms[others], rcond=None)[0] if others else np.zeros((0, 0))
    for i in [i for i in free if i not in kept_idx]:
        if i in zero:
            dropped.append({"name": L.names[i], "confounded_with": [], "convention": False,
                            "reason": "moves no measurement"})
            continue
        x = X[:, others.index(int(i))]
        big = np.argsort(-np.abs(x))
        partners = [L.names[kept_idx[k]] for k in big[:4] if abs(x[k]) > 1e-3 * np.abs(x).max()]
        conv = (not setup[i]) and any(setup[L.index(p)] for p in partners)
        dropped.append({"name": L.names[i], "confounded_with": partners, "convention": bool(conv)})
    return dropped


def check_kpi(ident: Identifiability, model: MeasurementModel, E: np.ndarray, what: str = "KPI", tol: float = 1e-6
              ) -> None:
    """Raise if the KPI with sensitivity ``E`` (n_s, n_raw) is not estimable under the convention.

    Raises:
        IdentifiabilityError: naming the offending direction and what to change.
    """
    L = model.layout
    N = ident.null_space
    if N is None or N.shape[1] == 0:
        return
    setup_point = np.zeros(L.n, bool)
    for g in model.target_groups:
        setup_point[L.group_slice(g)] = True
    C = N[setup_point]
    if C.size:
        import scipy.linalg as sla

        Z = sla.null_space(C)
        N = N @ Z
    if N.shape[1] == 0:
        return
    N = N / np.linalg.norm(N, axis=0)
    scale = np.linalg.norm(E) + 1e-300
    EN = E @ N
    worst = int(np.argmax(np.linalg.norm(EN, axis=0)))
    if np.linalg.norm(EN[:, worst]) > tol * scale:
        n = N[:, worst]
        top_idx = np.argsort(-np.abs(n))[:4]
        top = [L.names[k] for k in top_idx]
        dev, target = model.frame_group, model.target_groups[0]
        hint = (f"express the KPI in the {dev} frame (the robot base frame is not observable when the {dev} pose "
                f"is unknown), or fix the {dev} pose as known") if any(L.group[k] == dev for k in top_idx) else (
                f"move the {target} off the last joint axis, use a 6-DoF probe, or put the TCP at the {target}")
        raise IdentifiabilityError(f"{what} is not estimable: it moves along the unobservable direction "
                                   f"{' / '.join(top)}; {hint}")
