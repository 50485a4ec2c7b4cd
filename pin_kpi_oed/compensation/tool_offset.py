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
Every command that states a σ at a TCP adds this term through
:func:`~pin_kpi_oed.calibrated.tcp_sigma.tcp_sigma`, the one σ at the TCP.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from pin_kpi_oed.calibrated.tcp_sigma import held_map
from pin_kpi_oed.model.tolerances import Tolerances
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
    of each held joint-placement parameter (:func:`~pin_kpi_oed.calibrated.tcp_sigma.held_map`, the one
    implementation). None and an empty G at the fitted reflector or when the model does not list its identified
    parameters."""
    return held_map(cm, station, tcp_m, Q, seed, n_fit, tolerances, frame)
