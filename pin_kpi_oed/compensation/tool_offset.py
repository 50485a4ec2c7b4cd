r"""What a reflector calibration cannot see at a TCP away from the reflector, under the manufacturing tolerances.

One reflector on the tool determines the reflector's path, not the whole flange pose: joint-placement parameters
that no reflector measurement determines (e.g. the last joint's translation along its axis and its rotation about
it) are held at nominal and absorbed by the identified parameters and the fitted reflector offset, exactly for the
reflector and not for another point c of the tool. With the absorption A of the fit (p̂_B − p_B = A p_N, stored in
the model file by ``identify``: ``geometry.parameters.held``, :class:`~pin_kpi_oed.oed.held.HeldTerm`), E_B and E_N
the Jacobians of c (tracker frame of the station; c does not follow the fitted reflector offset) w.r.t. the
identified and the held parameters, a true p_N moves c by

    G(q) p_N,    G(q) = E_B(q) A − E_N(q)

so its covariance is G Σ_N Gᵀ with Σ_N = diag(tolerance²) (:class:`~pin_kpi_oed.model.tolerances.Tolerances`). At the
fitted reflector itself G = 0. A model file written before the absorption was stored gets the structural one
(:func:`~pin_kpi_oed.oed.covariance.held_absorption` on seeded configurations: the same for an exact dependency).
Every command that states a σ at a TCP adds this term (``compensate``, ``check``; ``identify`` computes it on its
own rows).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from pin_kpi_oed.model.tolerances import Tolerances, held_columns
from pin_kpi_oed.model.tracker import TrackerModel
from pin_kpi_oed.oed.covariance import held_absorption
from pin_kpi_oed.oed.held import HeldTerm

__all__ = ["unobservable_tcp_sigma", "unobservable_map", "held_tcp_covariance"]


def unobservable_tcp_sigma(cm: Any, station: str | None, tcp_m: np.ndarray, Q: np.ndarray,
                           tolerances: Tolerances | None = None, seed: int = 0, n_fit: int = 60,
                           frame: str = "cell") -> np.ndarray:
    """3-D standard deviation (m) at the TCP ``tcp_m`` of what the calibration cannot determine, per row of Q.

    Args:
        cm: the :class:`~pin_kpi_oed.calibrated.model_file.CalibratedModel` (its ``parameters`` say which
            joint-placement parameters were identified and, written by ``identify``, how the fit absorbed the others).
        station: the station whose set-up (tracker pose, fitted reflector) is used.
        tcp_m: the point in the tool frame (m).
        Q: configurations (m, n) rad / m.
        tolerances: the spread of real robots around the nominal model (default: the one the fit stored, else
            :class:`Tolerances`).
        seed: seed of the configurations a model file without a stored absorption has it solved on.
        n_fit: their number.
        frame: ``cell`` (the station's tracker frame) or ``base`` (the robot base frame: the tracker pose does not
            move the point, so joint 1's placement, held for it, counts with its tolerance).

    Returns:
        (m,) m; zeros at the fitted reflector in the tracker frame, or when the model does not list its identified
        parameters.
    """
    C = held_tcp_covariance(cm, station, tcp_m, Q, tolerances, seed, n_fit, frame)[0]
    return np.sqrt(np.maximum(np.einsum("maa->m", C), 0.0))


def held_tcp_covariance(cm: Any, station: str | None, tcp_m: np.ndarray, Q: np.ndarray,
                        tolerances: Tolerances | None = None, seed: int = 0, n_fit: int = 60, frame: str = "cell"
                        ) -> tuple[np.ndarray, np.ndarray, HeldTerm | None]:
    """(G Σ_N Gᵀ (m, 3, 3) m², the held parameters' RMS σ over the rows (k,) m, the :class:`HeldTerm` or None) at
    the point ``tcp_m`` (tool frame) for configurations Q, tracker frame of the station (module docstring; Args as
    :func:`unobservable_tcp_sigma`; in the robot base frame for ``frame="base"``)."""
    G, term = unobservable_map(cm, station, tcp_m, Q, seed, n_fit, tolerances, frame)
    if term is None:
        return np.zeros((len(np.atleast_2d(Q)), 3, 3)), np.zeros(0), None
    return term.covariance(G), term.contributions(G), term


def unobservable_map(cm: Any, station: str | None, tcp_m: np.ndarray, Q: np.ndarray, seed: int = 0,
                     n_fit: int = 60, tolerances: Tolerances | None = None, frame: str = "cell"
                     ) -> tuple[np.ndarray, HeldTerm | None]:
    """(G (m, 3, k) in m per parameter unit, the :class:`HeldTerm`): the displacement of the point ``tcp_m`` per unit
    of each held joint-placement parameter (module docstring). None and an empty G at the fitted reflector or when
    the model does not list its identified parameters."""
    Q = np.atleast_2d(np.asarray(Q, float))
    names = list((cm.parameters or {}).get("names") or [])
    model_r, p = cm.station_model(station)
    c = np.asarray(tcp_m, float).reshape(3)
    L = model_r.layout
    model_c = TrackerModel(cm.robot, tracker_T_base=model_r.tracker_T_base, reflector_m=c, noise=cm.noise, layout=L)
    term = _stored_term(cm, names) if names else None
    if term is None and names:
        term = _structural_term(cm, model_r, p, names, seed, n_fit)
    at_reflector = frame != "base" and np.allclose(c, model_r.reflector_m, rtol=0.0, atol=1e-12)
    if term is None or not term.k or at_reflector:
        return np.zeros((len(Q), 3, 0)), None
    if tolerances is not None:
        term = term.with_sigma(tolerances.sigma_vector(model_c)[[L.names.index(n) for n in term.names]])
    Jc = model_c.jacobian(p, Q)[:, :3, :]
    Jc[:, :, L.reflector] = 0.0  # the point does not follow the fitted reflector offset
    if frame == "base":  # the tracker pose does not move a point in the base frame
        Jc = np.einsum("ba,mbp->map", model_r.tracker_pose(p).rotation, Jc)
        Jc[:, :, L.tracker] = 0.0
    E_B = np.zeros((len(Q), 3, len(term.rows)))
    own = _own_label(term.rows, cm.station(station))
    for i, n in enumerate(term.rows):
        k = _station_column(L, n, own)
        if k is not None:
            E_B[:, :, i] = Jc[:, :, k]
    E_N = Jc[:, :, [L.names.index(n) for n in term.names]]
    return term.gain(E_B, E_N), term


def _own_label(rows: list[str], label: str) -> str | None:
    """The fitted station whose set-up rows stand for station ``label``'s: itself when the fit had it, else the
    first fitted one (a station registered later re-fits its own set-up, which absorbs the held parameters as the
    fitted one did); None for a one-station fit (unprefixed names)."""
    from pin_kpi_oed.identification.problem import STATION_SEP

    labels = [n.partition(STATION_SEP)[2].split(".", 1)[0] for n in rows if STATION_SEP in n]
    return None if not labels else (label if label in labels else labels[0])


def _station_column(L: Any, name: str, own: str | None) -> int | None:
    """The station layout's column of a fit parameter name: a robot parameter, or a set-up parameter (a
    several-station fit's ``tracker@own.tx`` read as ``tracker.tx``; another station's: None); None for effect
    parameters."""
    from pin_kpi_oed.identification.problem import STATION_SEP

    g = name
    if STATION_SEP in name:
        head, _, rest = name.partition(STATION_SEP)
        lab, _, comp = rest.partition(".")
        if lab != own:
            return None
        g = f"{head}.{comp}"
    return L.names.index(g) if g in L.names else None


def _stored_term(cm: Any, names: list[str]) -> HeldTerm | None:
    """The model file's stored absorption (``geometry.parameters.held``), or None."""
    d = (cm.parameters or {}).get("held")
    if not d:
        return None
    return d if isinstance(d, HeldTerm) else HeldTerm.from_dict(d, names)


def _structural_term(cm: Any, model_r: TrackerModel, p: np.ndarray, names: list[str], seed: int,
                     n_fit: int) -> HeldTerm | None:
    """The absorption of a model file without a stored one: :func:`held_absorption` on ``n_fit`` seeded
    configurations over the identified robot parameters and the station's set-up (exact for a structural
    dependency), the default tolerances."""
    L = model_r.layout
    ident = [n for n in names if n in L.names[:6 * cm.robot.nq]]
    held = held_columns(model_r, ident)
    if not held.size:
        return None
    b = [L.names.index(n) for n in ident] + list(range(L.tracker.start, L.tracker.stop)) + list(
        range(L.reflector.start, L.reflector.stop))
    Qfit = cm.robot.random_q(np.random.default_rng(seed), n_fit)
    F = model_r.jacobian(p, Qfit)[:, :3, :].reshape(-1, L.n)
    A = held_absorption(F[:, b], F[:, held])
    return HeldTerm([L.names[i] for i in held], Tolerances().sigma_vector(model_r)[held], [L.names[i] for i in b], A)
