r"""The parameters a calibration holds at nominal, as a term of the TCP's covariance.

A fit over the identified parameters p_B absorbs the held ones p_N (prior N(0, Σ_N), the manufacturing tolerances):
p̂_B − p_B = A p_N + noise with A = M⁻¹ F_Bᵀ F_N (:func:`~pin_kpi_oed.oed.covariance.held_absorption`). A point s of
the tool then errs by G p_N, G = E_B A − E_N (:func:`~pin_kpi_oed.oed.covariance.held_covariance`): zero at the
reflector for a structural dependency, not at a TCP away from it. :class:`HeldTerm` keeps what the fit determined
(the held parameters' names and σ, A over the fit's parameter names), so that every command computes the same σ at
any TCP and configuration from E_B and E_N there; :func:`held_advice` says which held parameter contributes what and
what removes it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from pin_kpi_oed.errors import InputError

if TYPE_CHECKING:
    from pin_kpi_oed.model.tolerances import Tolerances
    from pin_kpi_oed.model.tracker import TrackerModel

__all__ = ["HeldTerm", "HeldShare", "held_advice", "design_term", "design_held"]


@dataclass
class HeldTerm:
    """The held parameters of a fit and how the fit absorbed them (SI units).

    Attributes:
        names: the held raw parameters' names (``joint_a6.tz``), (k,).
        sigma: their prior standard deviations, the tolerances (m or rad), (k,).
        rows: the names of the fit's parameters A's rows belong to, (nb,).
        absorption: A, (nb, k): the fit's estimate moves by A p_N.
    """

    names: list[str]
    sigma: np.ndarray
    rows: list[str]
    absorption: np.ndarray

    def __post_init__(self) -> None:
        self.sigma = np.asarray(self.sigma, float).reshape(-1)
        self.absorption = np.asarray(self.absorption, float).reshape(len(self.rows), len(self.names))

    @property
    def k(self) -> int:
        """Number of held parameters."""
        return len(self.names)

    def gain(self, E_B: np.ndarray, E_N: np.ndarray) -> np.ndarray:
        """G = E_B A − E_N, (..., k) m per parameter unit: E_B over :attr:`rows` (..., nb), E_N over :attr:`names`."""
        return E_B @ self.absorption - E_N

    def covariance(self, G: np.ndarray) -> np.ndarray:
        """G Σ_N Gᵀ per point: G (m, 3, k) → (m, 3, 3) m²."""
        Gs = G * self.sigma
        return np.einsum("mak,mbk->mab", Gs, Gs)

    def contributions(self, G: np.ndarray) -> np.ndarray:
        """RMS over the points of each held parameter's 3-D σ at them, (k,) m: sqrt(mean_i ‖G_i[:, k]‖² σ_k²)."""
        return np.sqrt(np.mean(np.sum(G ** 2, axis=1), axis=0)) * self.sigma

    def with_sigma(self, sigma: np.ndarray) -> HeldTerm:
        """The same absorption under other tolerances (k,)."""
        return HeldTerm(list(self.names), np.asarray(sigma, float), list(self.rows), self.absorption.copy())

    def to_dict(self) -> dict:
        """The model file's ``geometry.parameters.held`` block (A's rows are ``parameters.names``)."""
        return {"names": list(self.names), "sigma": self.sigma.tolist(), "absorption": self.absorption.tolist()}

    @classmethod
    def from_dict(cls, d: dict, rows: list[str], where: str = "model file") -> HeldTerm:
        """The block of :meth:`to_dict` with A's row names ``rows``.

        Raises:
            InputError: shapes that do not match (named with ``where``).
        """
        names = [str(n) for n in d.get("names") or []]
        try:
            return cls(names, np.asarray(d.get("sigma") or [], float), list(rows),
                       np.asarray(d.get("absorption") or np.zeros((len(rows), 0)), float))
        except ValueError:
            raise InputError(f"{where}: field geometry.parameters.held: the absorption is not "
                             f"{len(rows)} x {len(names)} numbers") from None


def held_advice(names: list[str], contrib_m: np.ndarray, total_m: float, top: int = 2) -> str:
    """One line: how much of the TCP's σ the held parameters make and what removes it, e.g. "0.41 mm of the TCP's σ
    (RMS 0.45 mm) is from joint7.tz, which no reflector measurement determines; ...".

    Args:
        names: the held parameters; contrib_m: their contributions (:meth:`HeldTerm.contributions`), m;
        total_m: the TCP's σ with them (RMS over the working configurations, m); top: parameters named.

    Returns:
        The line, or "" when the held parameters contribute nothing (below 1e-9 m).
    """
    contrib_m = np.asarray(contrib_m, float)
    held = float(np.sqrt(np.sum(contrib_m ** 2)))
    if held < 1e-9:
        return ""
    order = [i for i in np.argsort(-contrib_m)[:top] if contrib_m[i] > 0.05 * held]
    named = " and ".join(f"{names[i]} ({contrib_m[i] * 1e3:.3g} mm)" for i in order)
    moves = {names[i].rsplit(".", 1)[-1].startswith("t") for i in order}
    fixes = []
    if True in moves:  # a translation of the link carrying the tool: every point on it moves alike
        fixes.append("a translation moves every reflector nest on the tool alike, so no set of nests determines it: "
                     "measuring the TCP itself (a nest at the TCP, or the TCP's position relative to the nest from "
                     "a tool calibration) removes it")
    if False in moves:  # a rotation: points at different places on the tool move differently
        fixes.append("a rotation is determined by a second reflector nest away from the first (off the last joint's "
                     "axis) or a 6-DoF probe")
    return (f"{held * 1e3:.3g} mm of the TCP's sigma (RMS {total_m * 1e3:.3g} mm at the working configurations) is "
            f"from parameters held at their tolerance, mostly {named}, which no measurement of this reflector "
            "determines; " + "; ".join(fixes))


@dataclass
class HeldShare:
    """What the held parameters add to a design's tr C_s at the working configurations (SI units).

    Attributes:
        trace_m2: tr(G Σ_N Gᵀ) over the working configurations (m²): constant in the design (zero gradient for a
            structural dependency), what no measurement of this reflector removes.
        names: the held parameters; contrib_m: each one's RMS 3-D σ at the TCP over the working configurations (m).
    """

    trace_m2: float = 0.0
    names: list[str] = field(default_factory=list)
    contrib_m: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def line(self, trace_cs_m2: float, t: int) -> str:
        """One line: the held share of tr C_s (the identified part ``trace_cs_m2``, m², at ``t`` working
        configurations) and what removes it (:func:`held_advice`), or ""."""
        if not self.names or self.trace_m2 <= 0:
            return ""
        total = trace_cs_m2 + self.trace_m2
        head = (f"{self.trace_m2 * 1e6:.4g} mm^2 of tr(C_s) = {total * 1e6:.4g} mm^2 "
                f"({100 * self.trace_m2 / total:.0f} %) no measurement of this reflector removes: ")
        return head + held_advice(self.names, self.contrib_m, float(np.sqrt(total / max(t, 1))))


def design_term(model: TrackerModel, base: np.ndarray, Q_meas: np.ndarray, tolerances: Tolerances | None = None,
                p: np.ndarray | None = None) -> HeldTerm | None:
    """The :class:`HeldTerm` a fit on the measurement configurations would store: the held joint-placement
    parameters, their tolerances and A = M⁻¹F_BᵀF_N over the identified parameters (module docstring).

    Args:
        model: the measurement model (its layout and prior); base: the identified parameters' raw indices;
        Q_meas: measurement configurations (m, n) rad; tolerances: the held parameters' prior (default
        :class:`~pin_kpi_oed.model.tolerances.Tolerances`); p: the linearisation point (default nominal).

    Returns:
        The term (A's rows named by the layout's names of ``base``), or None when nothing is held.

    Raises:
        IdentifiabilityError: Q_meas does not identify the parameters.
    """
    from pin_kpi_oed.model.tolerances import Tolerances, held_columns
    from pin_kpi_oed.oed.covariance import held_absorption, prior_of

    base = np.asarray(base, int)
    N = held_columns(model, base)
    if not N.size:
        return None
    p0 = np.zeros(model.n_params) if p is None else np.asarray(p, float)
    F = model.weighted_jacobian(p0, np.atleast_2d(Q_meas)).reshape(-1, model.n_params)
    A = held_absorption(F[:, base], F[:, N], prior_of(model, base))
    names = model.layout.names
    return HeldTerm([names[i] for i in N], (tolerances or Tolerances()).sigma_vector(model)[N],
                    [names[i] for i in base], A)


def design_held(model: TrackerModel, base: np.ndarray, Q_meas: np.ndarray, Q_work: np.ndarray,
                tolerances: Tolerances | None = None, p: np.ndarray | None = None) -> HeldShare:
    """The held parameters' share of a design's C_s: tr(G Σ_N Gᵀ) with G = E_B A − E_N at the working
    configurations and A = M⁻¹F_BᵀF_N of the measurement configurations (module docstring, :func:`design_term`).

    Args:
        model: the measurement model (its TCP, layout and prior); base: the identified parameters' raw indices;
        Q_meas: measurement configurations (m, n) rad; Q_work: working configurations (t, n) rad;
        tolerances: the held parameters' prior (default :class:`~pin_kpi_oed.model.tolerances.Tolerances`);
        p: the linearisation point (default nominal).

    Returns:
        The :class:`HeldShare` (zero when nothing is held).

    Raises:
        IdentifiabilityError: Q_meas does not identify the parameters.
    """
    base = np.asarray(base, int)
    term = design_term(model, base, Q_meas, tolerances, p)
    if term is None:
        return HeldShare()
    p0 = np.zeros(model.n_params) if p is None else np.asarray(p, float)
    E = model.kpi_jacobian(p0, np.atleast_2d(Q_work))
    N = [model.layout.names.index(n) for n in term.names]
    Gs = term.gain(E[:, base], E[:, N]) * term.sigma
    t = E.shape[0] // 3
    return HeldShare(float(np.sum(Gs ** 2)), list(term.names), np.sqrt(np.sum(Gs ** 2, axis=0) / t))
