r"""What a reflector calibration cannot see at a TCP away from the reflector, under the manufacturing tolerances.

One reflector on the tool determines the reflector's path, not the whole flange pose: joint-placement errors that are
not identifiable (e.g. the last joint's translation along its axis and its rotation about it) are absorbed by the
identifiable parameters and the fitted reflector offset, exactly for the reflector and not for another point c of the
tool. With J_r the reflector's Jacobian w.r.t. the raw parameters, b the identified columns (plus the set-up: tracker
pose, reflector offset) and u the joint-placement columns the fit held at zero, the absorption is the structural
B = argmin ‖J_r,b B − J_r,u‖ (over seeded configurations; exact for a structural dependency), and a true δ_u moves
the compensated point c (which does not follow the fitted reflector offset) by

    G(q) δ_u,    G(q) = J_c,u(q) − J_c,b(q) B     (J_c with its reflector columns zero)

so its covariance is G Σ_u Gᵀ with Σ_u = diag(tolerance²) (:class:`~pin_kpi_oed.model.tolerances.Tolerances`). At the
fitted reflector itself G = 0. ``compensate`` adds this σ to the model's σ of a TCP away from the reflector and
says so.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from pin_kpi_oed.model.tolerances import Tolerances
from pin_kpi_oed.model.tracker import TrackerModel

__all__ = ["unobservable_tcp_sigma", "unobservable_map"]


def unobservable_tcp_sigma(cm: Any, station: str | None, tcp_m: np.ndarray, Q: np.ndarray,
                           tolerances: Tolerances | None = None, seed: int = 0, n_fit: int = 60) -> np.ndarray:
    """3-D standard deviation (m) at the TCP ``tcp_m`` of what the calibration cannot determine, per row of Q.

    Args:
        cm: the :class:`~pin_kpi_oed.calibrated.model_file.CalibratedModel` (its ``parameters.names`` say
            which joint-placement parameters were identified).
        station: the station whose set-up (tracker pose, fitted reflector) is used.
        tcp_m: the compensated point in the tool frame (m).
        Q: configurations (m, n) rad / m.
        tolerances: the spread of real robots around the nominal model (default :class:`Tolerances`).
        seed: seed of the configurations the absorption B is solved on.
        n_fit: their number.

    Returns:
        (m,) m; zeros at the fitted reflector, or when the model does not list its identified parameters.
    """
    G, u, model_c = unobservable_map(cm, station, tcp_m, Q, seed, n_fit)
    if not u:
        return np.zeros(len(np.atleast_2d(Q)))
    s_u = (tolerances or Tolerances()).sigma_vector(model_c)[u]
    return np.sqrt(np.sum((G * s_u) ** 2, axis=(1, 2)))


def unobservable_map(cm: Any, station: str | None, tcp_m: np.ndarray, Q: np.ndarray, seed: int = 0,
                     n_fit: int = 60) -> tuple[np.ndarray, list[int], TrackerModel]:
    """(G (m, 3, k) in m per parameter unit, the k raw-parameter columns u the fit held at zero, the TCP's model):
    the displacement of the compensated point per unit of each undetermined joint-placement error (module
    docstring). ``u`` is empty at the fitted reflector or when the model does not list its identified parameters."""
    Q = np.atleast_2d(np.asarray(Q, float))
    names = (cm.parameters or {}).get("names")
    model_r, p = cm.station_model(station)
    c = np.asarray(tcp_m, float).reshape(3)
    L = model_r.layout
    model_c = TrackerModel(cm.robot, tracker_T_base=model_r.tracker_T_base, reflector_m=c, noise=cm.noise, layout=L)
    n_geo = 6 * cm.robot.nq
    known = set(map(str, names or ()))
    u = [i for i in range(n_geo) if L.names[i] not in known]
    if not names or not u or np.allclose(c, model_r.reflector_m, rtol=0.0, atol=1e-12):
        return np.zeros((len(Q), 3, 0)), [], model_c
    b = [i for i in range(n_geo) if L.names[i] in known] + list(range(n_geo, L.n))
    Qfit = cm.robot.random_q(np.random.default_rng(seed), n_fit)
    Jr = model_r.jacobian(p, Qfit)[:, :3, :].reshape(-1, L.n)
    B = np.linalg.lstsq(Jr[:, b], Jr[:, u], rcond=None)[0]
    Jc = model_c.jacobian(p, Q)[:, :3, :]
    Jc[:, :, L.reflector] = 0.0  # the compensated point does not follow the fitted reflector offset
    return Jc[:, :, u] - np.einsum("mak,ku->mau", Jc[:, :, b], B), u, model_c
