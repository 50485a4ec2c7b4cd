r"""Drift over time within a measurement session: a slowly moving offset between tracker and robot.

A laser tracker on its stand settles, the floor and the robot's base warm up, the air
changes: within one session the whole measured point cloud moves slowly. To first order
that is a position offset in the tracker frame, linear (optionally quadratic) in time, one
per station (tracker placement)::

    ΔY_i = Σ_{d=1..D} (t_i − t_ref,s)^d · v_{s,d}           (m, tracker frame), s = station of row i

with θ = (v_{s,1}, …) in m/s (d = 1) and m/s² (d = 2), t the ``time`` column (s). The constant
term (d = 0) is the tracker's translation, which the set-up already holds; ``t_ref`` (default
the mean time of each station's rows in the data the effect was built from,
:meth:`Drift.from_data`) only moves that constant.

**Set-up specific** (``setup_specific = True``): it describes one session, not the robot. It
is fitted together with the tracker pose, re-fitted at every registration on another set-up
and never transferred — a calibrated model that carried Series B's drift to Series C would
move C's points by B's minutes. A rotation drift of the tracker is not modelled (it scales
with the distance and looks different).

Without a ``time`` column the effect is skipped with a note (:meth:`Effect.check`); the IPA
series B, C, D have none (their time stamps were lost), so the examples use the row number
as a stand-in and say so.
"""

from __future__ import annotations

from typing import Any
from collections.abc import Sequence

import numpy as np

from pin_kpi_oed.effects.base import Effect, check_aux_len
from pin_kpi_oed.errors import InputError
from pin_kpi_oed.model.robot import Robot

__all__ = ["Drift", "station_labels"]

_AXES = ("x", "y", "z")
_UNITS = {1: "m_per_s", 2: "m_per_s2"}


def station_labels(aux: Any, m: int) -> np.ndarray | None:
    """Station label of every row as text (m,), or None when the data carry no ``station`` column."""
    st = None if aux is None else getattr(aux, "station", None)
    if st is None:
        return None
    st = np.asarray(st).astype(str)
    if st.shape != (m,):
        raise InputError(f"drift: the station column has {st.size} entries for {m} rows")
    return st


class Drift(Effect):
    """Position offset in the tracker frame, linear (or quadratic) in time, per station (m/s, m/s²).

    Args:
        robot: the arm (only for the interface).
        degree: 1 (linear) or 2 (linear + quadratic).
        stations: station labels (text), one drift each; None = one drift for every row.
        t_ref_s: reference time per station (s), default 0.

    Raises:
        InputError: degree not 1 or 2, ``t_ref_s`` of the wrong length or not finite.
    """

    name = "drift"
    unit = "m/s"
    plausible_max = 1e-6  # 3.6 mm per hour
    setup_specific = True
    requires = ("time_s",)
    description = ("position offset of the measured points (tracker frame) drifting linearly (or quadratically) "
                   "in time within a session, per station; set-up specific, re-fitted at registration")

    def __init__(self, robot: Robot, degree: int = 1, stations: Sequence[str] | None = None,
                 t_ref_s: Sequence[float] | np.ndarray | float | None = None):
        super().__init__(robot)
        if degree not in (1, 2):
            raise InputError(f"{self.name}: degree must be 1 (linear) or 2 (quadratic), got {degree}")
        self.degree = int(degree)
        self.stations = None if stations is None else [str(s) for s in stations]
        ns = 1 if self.stations is None else len(self.stations)
        if self.stations is not None and (ns == 0 or len(set(self.stations)) != ns):
            raise InputError(f"{self.name}: station labels must be given once each, got {self.stations}")
        tr = np.zeros(ns) if t_ref_s is None else np.broadcast_to(np.asarray(t_ref_s, float), (ns,)).copy()
        if not np.all(np.isfinite(tr)):
            raise InputError(f"{self.name}: t_ref_s must be finite, got {t_ref_s}")
        self.t_ref_s = tr

    @classmethod
    def from_data(cls, robot: Robot, data: Any, degree: int = 1) -> Drift:
        """One drift per station of ``data`` (its ``station`` column, else one), t_ref = each station's mean time.

        Raises:
            InputError: the data have no ``time`` column.
        """
        t = getattr(data, "time_s", None)
        if t is None:
            raise InputError(f"{cls.name}: {getattr(data, 'source', '') or 'the measurements'} have no 'time' column")
        t = np.asarray(t, float)
        st = station_labels(data, t.size)
        if st is None:
            return cls(robot, degree, None, [float(t.mean())])
        labels = list(dict.fromkeys(st.tolist()))
        return cls(robot, degree, labels, [float(t[st == s].mean()) for s in labels])

    @classmethod
    def from_spec(cls, robot: Robot, text: str) -> Drift:
        """From ``"degree=2"``.

        Raises:
            InputError: anything else.
        """
        key, sep, val = str(text).replace(" ", "").partition("=")
        if key != "degree" or not sep or val not in ("1", "2"):
            raise InputError(f"{cls.name}[{text}]: the only option is degree=1 or degree=2")
        return cls(robot, degree=int(val))

    def _station_names(self) -> list[str]:
        return ["all"] if self.stations is None else self.stations

    def options(self) -> dict:
        """Constructor keyword arguments that rebuild this effect (JSON-able; stored in the model file)."""
        return {"degree": int(self.degree), "stations": self.stations,
                "t_ref_s": [float(t) for t in np.atleast_1d(self.t_ref_s)]}

    def param_names(self, robot: Robot | None = None) -> list[str]:
        return [f"{self.name}.{s}.{a}_{_UNITS[d]}" for s in self._station_names() for d in range(1, self.degree + 1)
                for a in _AXES]

    def groups(self) -> list[tuple[str, list[int]]]:
        k = 3 * self.degree
        return [(f"station {s}", list(range(i * k, (i + 1) * k))) for i, s in enumerate(self._station_names())]

    def restrict(self, groups: Sequence[int]) -> Drift:
        names = self._station_names()
        if self.stations is None:
            return self
        return Drift(self.robot, self.degree, [names[g] for g in groups], self.t_ref_s[list(groups)])

    def _rows(self, aux: Any, m: int) -> np.ndarray:
        """Station index of every row (m,)."""
        if self.stations is None:
            return np.zeros(m, int)
        st = station_labels(aux, m)
        if st is None:
            if len(self.stations) == 1:
                return np.zeros(m, int)
            raise InputError(f"{self.name}: {len(self.stations)} stations but the measurements have no station column")
        unknown = sorted(set(st.tolist()) - set(self.stations))
        if unknown:
            raise InputError(f"{self.name}: station(s) {unknown} have no drift parameters (stations: "
                             f"{', '.join(self.stations)}); re-build the drift for these data (Drift.from_data)")
        lut = {s: i for i, s in enumerate(self.stations)}
        return np.array([lut[s] for s in st], int)

    def tool_offset(self, theta: np.ndarray, Q: np.ndarray, aux: Any = None, model: Any = None,
                    p: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        th = self._theta(theta)
        Q = np.atleast_2d(np.asarray(Q, float))
        m = Q.shape[0]
        note = self.check(aux)
        if note:
            raise InputError(note)
        check_aux_len(aux, m, self.name)
        t = np.asarray(aux.time_s, float)
        s = self._rows(aux, m)
        tau = t - self.t_ref_s[s]
        D = np.zeros((m, 3, th.size))
        k = 3 * self.degree
        for d in range(1, self.degree + 1):
            for a in range(3):
                D[np.arange(m), a, s * k + (d - 1) * 3 + a] = tau ** d
        return D @ th, D

    def describe(self, theta: np.ndarray) -> list[str]:
        """Per station: ``"station B: drift 0.35 mm per hour (x +0.02, y -0.05, z +0.35 mm/h)"``."""
        th = self._theta(theta).reshape(-1, self.degree, 3)
        out = []
        for s, v in zip(self._station_names(), th):
            r = v[0] * 3600e3  # mm per hour
            line = (f"station {s}: drift {np.linalg.norm(r):.3g} mm per hour (x {r[0]:+.3g}, y {r[1]:+.3g}, "
                    f"z {r[2]:+.3g} mm/h)")
            if self.degree == 2:
                line += f", curvature {np.linalg.norm(v[1]) * 3600.0 ** 2 * 1e3:.3g} mm/h²"
            out.append(line)
        return out

    def to_dict(self) -> dict:
        d = super().to_dict()
        d.update(degree=self.degree, stations=self.stations, t_ref_s=self.t_ref_s.tolist())
        return d
