r"""The discrepancy kernel: a covariance over joint values that knows angles wrap and a track does not.

A calibrated robot model still misses what no parameter of it describes (gear and encoder
errors between the harmonics a model carries, deflections, cable forces). That model
discrepancy δ(q) is a smooth function of the joint angles q, periodic in each revolute angle.
:class:`JointKernel` is the covariance of δ used everywhere — identification, prediction and
design use this one formula:

.. math::

    k(q, q') = c^2 \prod_j \exp\!\Big(-\frac{2\sin^2(\Delta_j/2)}{L_j^2}\Big)
             + \sum_j a_j^2 \exp\!\Big(-\frac{2\sin^2(\Delta_j/2)}{\ell_j^2}\Big),
    \qquad \Delta_j = q_j - q'_j .

``4 sin²(Δ/2) = |(cos q, sin q) − (cos q', sin q')|²``: each factor of a revolute joint is a
squared-exponential kernel on the point (cos q_j, sin q_j) of the unit circle, so q and q + 2π
are the same configuration and no seam appears at ±π. A **linear** joint (prismatic, a track in
m: ``linear``) enters with its squared distance on the line instead, 4 sin²(Δ_j/2) → Δ_j²: a
squared-exponential in metres whose length scales are in m (two track positions 2π m apart are
not the same). Without linear joints every figure is the all-revolute kernel's, bit for bit.

* the **product** part (amplitude c, one length scale L_j per joint, ARD) is a smooth
  function of the whole configuration: deflections and couplings between joints;
* the **additive** part (an amplitude a_j and a length scale ℓ_j per joint) is a sum of
  one-joint functions: transmission / encoder errors, periodic in one joint with many cycles
  per revolution, which a product kernel would need far more data to learn (a short ℓ_j
  behaves like a Fourier basis of that joint up to order ≈ 1/ℓ_j).

The kernel is unit-free (amplitudes in units of the normalised residual); the per-axis scale in
metres is held by :class:`~pin_kpi_oed.discrepancy.gp.Discrepancy`. It implements
scikit-learn's kernel protocol (value and gradient in the log hyper-parameters,
:class:`~pin_kpi_oed.discrepancy.hyperparameters.HyperKernel`, without importing scikit-learn) so that
:class:`~sklearn.gaussian_process.GaussianProcessRegressor` fits it by maximum marginal likelihood as the
package's own :mod:`~pin_kpi_oed.discrepancy.marginal` does, and adds :meth:`JointKernel.grad_x`, the exact
derivative in the joint angles a design needs (checked against finite differences).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from pin_kpi_oed.discrepancy.hyperparameters import HyperKernel, Hyperparameter

__all__ = ["JointKernel"]

_BOUNDS_AMP = (1e-4, 1e2)
_BOUNDS_LEN = (1e-2, 1e2)
#: what a model file's kernel may hold: ten times beyond the fit's bounds (amplitudes normalised, length scales rad);
#: further out the kernel overflows or is constant to machine precision
FILE_RANGE_AMP, FILE_RANGE_LEN = (1e-5, 1e3), (1e-3, 1e3)
#: the same for a linear joint's length scales (m): its fit bounds follow the joint's travel (:func:`length_units`)
FILE_RANGE_LEN_M = (1e-6, 1e4)
#: the model file's kernel forms: all joints on the circle (older files), or each joint's unit stated
FORM_CIRCLE, FORM_UNITS = "joint_wrapped_se/1", "joint_se/2"


def linear_mask(linear: Any, d: int) -> np.ndarray | None:
    """``linear`` as a (d,) bool mask, or None when no joint is linear (the all-revolute kernel).

    Raises:
        ValueError: a mask of another length.
    """
    if linear is None:
        return None
    m = np.asarray(linear, bool).reshape(-1)
    if m.size != d:
        raise ValueError(f"linear-joint mask of {m.size} joints for configurations of {d}")
    return m if m.any() else None


def length_units(linear: Any, span: Any, d: int) -> np.ndarray:
    """What 1 rad of length scale is per joint: 1 for a revolute joint, travel / 2π (m) for a linear one — its whole
    travel counts as one turn, so starts and bounds stated in rad (1 rad, 0.5 rad, 0.01 .. 100 rad) carry over.

    Args:
        linear: (d,) bool, the linear joints (None: none). span: (d,) the joints' travel (upper − lower limit; m for
            a linear joint; None: 2π, i.e. 1 m per rad). d: number of joints.
    """
    u = np.ones(d)
    m = linear_mask(linear, d)
    if m is not None:
        sp = np.full(d, 2.0 * np.pi) if span is None else np.asarray(span, float).reshape(-1)
        u[m] = np.maximum(sp[m], 1e-6) / (2.0 * np.pi)
    return u


def chord_squared(X: np.ndarray, Y: np.ndarray, lin: np.ndarray | None = None) -> np.ndarray:
    """4 sin²((x_j − y_j)/2) = 2 − 2 cos(x_j − y_j) per joint, (x_j − y_j)² for a linear joint: (n, m, d)."""
    D = 2.0 - 2.0 * np.cos(X[:, None, :] - Y[None, :, :])
    if lin is not None:
        Dl = X[:, None, lin] - Y[None, :, lin]
        D[..., lin] = Dl * Dl
    return D


def _value_blocks(X: np.ndarray, cY: np.ndarray, sY: np.ndarray, Y: np.ndarray | None, c: float, L: np.ndarray,
                  a: np.ndarray, ell: np.ndarray, lin: np.ndarray | None, block: int = 128,
                  lower: bool = False) -> np.ndarray:
    """:meth:`JointKernel._value` on Y given by its circle points ``cY``, ``sY`` (and, with linear joints ``lin``, its
    coordinates ``Y``): a revolute joint's 4 sin²(Δ/2)/L² = 2/L² − 2 (cx cy + sx sy)/L² and a linear joint's
    Δ²/L² = (x/L)² + (y/L)² − 2 (x/L)(y/L) (centred on X's mean first, against cancellation) join one matrix
    product; the one-joint parts are exp((cos Δ − 1)/ℓ²) and exp(−Δ²/2ℓ²), summed ``block`` rows at a time while in
    the processor's cache. ``lower`` (Y is X): each block of rows up to its diagonal block only, the columns beyond
    left 0 (every entry formed is the one of the whole matrix, to the last bit: a lower Cholesky factor reads
    nothing else)."""
    lin = np.zeros(X.shape[1], bool) if lin is None else lin
    ang, on_line = ~lin, bool(lin.any())
    cX, sX = np.cos(X), np.sin(X)
    U = np.hstack([cX[:, ang] / L[ang], sX[:, ang] / L[ang]])
    V = np.hstack([cY[:, ang] / L[ang], sY[:, ang] / L[ang]])
    s0 = float(np.sum(1.0 / L[ang] ** 2))
    if on_line:
        if Y is None:
            raise ValueError("a kernel with linear joints needs the configurations: pass features(Y)")
        mid = X[:, lin].mean(axis=0)
        xl, yl = (X[:, lin] - mid) / L[lin], (Y[:, lin] - mid) / L[lin]
        U, V = np.hstack([U, xl]), np.hstack([V, yl])
        rx, ry = 0.5 * np.sum(xl ** 2, axis=1), 0.5 * np.sum(yl ** 2, axis=1)
    V = V.T
    inv = 1.0 / ell ** 2
    K = (np.zeros if lower else np.empty)((X.shape[0], cY.shape[0]))
    T = np.empty((min(block, X.shape[0]), cY.shape[0]))
    T2 = np.empty_like(T)                     # the sine products, summed into T
    cXi, sXi = cX * inv, sX * inv             # each entry the product the block loop formed (the same bits)
    for b in range(0, X.shape[0], block):
        end = b + block if lower else cY.shape[0]  # the columns formed
        Kb = K[b:b + block, :end]
        Tb = T[:Kb.shape[0], :Kb.shape[1]]
        np.matmul(U[b:b + block], V[:, :end], out=Kb)
        Kb -= s0
        if on_line:
            Kb -= rx[b:b + block, None]
            Kb -= ry[None, :end]
        np.minimum(Kb, 0.0, out=Kb)
        np.exp(Kb, out=Kb)
        Kb *= c ** 2
        for j in range(X.shape[1]):
            if lin[j]:                        # a_j² exp(−Δ_j²/(2ℓ_j²))
                np.subtract.outer(X[b:b + block, j], Y[:end, j], out=Tb)
                Tb *= Tb
                Tb *= -0.5 * inv[j]
            else:                             # a_j² exp((cos Δ_j − 1)/ℓ_j²), cos Δ = cos x cos y + sin x sin y
                np.multiply.outer(cXi[b:b + block, j], cY[:end, j], out=Tb)
                T2b = T2[:Kb.shape[0], :Kb.shape[1]]
                np.multiply.outer(sXi[b:b + block, j], sY[:end, j], out=T2b)
                Tb += T2b
                Tb -= inv[j]
                np.minimum(Tb, 0.0, out=Tb)
            np.exp(Tb, out=Tb)
            Tb *= a[j] ** 2
            Kb += Tb
    return K


class _ChordCache:
    """The last training set's chords: they do not depend on the hyper-parameters, and the marginal-likelihood
    optimiser evaluates the kernel on the same X a few hundred times (keyed by the array's bytes)."""

    def __init__(self) -> None:
        self.entry: tuple[bytes, np.ndarray] | None = None

    def __call__(self, X: np.ndarray, lin: np.ndarray | None = None) -> np.ndarray:
        key = X.shape[0].to_bytes(8, "little") + np.ascontiguousarray(X).tobytes() + \
            (b"" if lin is None else b"L" + lin.tobytes())
        entry = self.entry                       # one read: safe when two threads fit at once
        if entry is None or entry[0] != key:
            D = chord_squared(X, X, lin)
            D.flags.writeable = False
            entry = (key, D)
            self.entry = entry
        return entry[1]


#: One shared entry: scikit-learn evaluates a fresh clone of the kernel at every step of the optimiser.
_CHORDS = _ChordCache()


class JointKernel(HyperKernel):
    """k(q, q') = c² Π_j SE_j(L_j) + Σ_j a_j² SE_j(ℓ_j) on the unit circle of each revolute joint and on the line
    of each linear one (see the module).

    Attributes:
        amplitude: c (unit-free, normalised residual units).
        length_scale: L_j, (d,) (rad; m for a linear joint; the product part).
        joint_amplitude: a_j, (d,) (unit-free; the additive part).
        joint_length_scale: ℓ_j, (d,) (rad; m for a linear joint; the additive part).
        linear: (d,) bool, the linear (prismatic) joints, compared on the line in m; None: every joint an angle.
        *_bounds: the fit's bounds, (2,) or one row per joint (d, 2) (:meth:`for_joints`: a linear joint's follow its
            travel).
    """

    def __init__(self, amplitude: float = 1.0, length_scale: Any = 1.0, joint_amplitude: Any = 0.3,
                 joint_length_scale: Any = 0.3, amplitude_bounds: Any = _BOUNDS_AMP,
                 length_scale_bounds: Any = _BOUNDS_LEN, joint_amplitude_bounds: Any = _BOUNDS_AMP,
                 joint_length_scale_bounds: Any = _BOUNDS_LEN, linear: Any = None) -> None:
        self.amplitude = amplitude
        self.length_scale = length_scale
        self.joint_amplitude = joint_amplitude
        self.joint_length_scale = joint_length_scale
        self.amplitude_bounds = amplitude_bounds
        self.length_scale_bounds = length_scale_bounds
        self.joint_amplitude_bounds = joint_amplitude_bounds
        self.joint_length_scale_bounds = joint_length_scale_bounds
        self.linear = linear

    @classmethod
    def for_joints(cls, amplitude: float, length_scale_rad: Any, joint_amplitude: Any, joint_length_scale_rad: Any,
                   linear: Any = None, span: Any = None) -> JointKernel:
        """A kernel whose length scales (and the fit's bounds on them) are given in rad and taken, for a linear joint,
        in units of its travel / 2π m (:func:`length_units`): a track of several metres starts at a length scale
        relative to its travel, not at 1 m. Without linear joints exactly ``JointKernel(amplitude, ...)``.

        Args:
            amplitude, joint_amplitude: c, a_j (unit-free). length_scale_rad, joint_length_scale_rad: L_j, ℓ_j (rad).
            linear: (d,) bool, the linear joints (None: none). span: (d,) the joints' travel (m for a linear joint).
        """
        d = int(max(np.size(length_scale_rad), np.size(joint_amplitude), np.size(joint_length_scale_rad),
                    np.size(linear) if linear is not None else 1))
        lin = linear_mask(linear, d)
        if lin is None:
            return cls(amplitude, length_scale_rad, joint_amplitude, joint_length_scale_rad)
        u = length_units(lin, span, d)
        bounds = np.outer(u, _BOUNDS_LEN)
        return cls(amplitude, np.broadcast_to(np.asarray(length_scale_rad, float), (d,)) * u, joint_amplitude,
                   np.broadcast_to(np.asarray(joint_length_scale_rad, float), (d,)) * u, _BOUNDS_AMP, bounds,
                   _BOUNDS_AMP, bounds, lin.copy())

    def linear_joints(self, d: int) -> np.ndarray | None:
        """The (d,) mask of the linear joints, or None when there are none (every joint on the circle)."""
        return linear_mask(self.linear, d)

    def check_units(self, joint_units: Any, joint_names: Any, where: str = "discrepancy.kernel") -> None:
        """The kernel's linear joints must be the robot's prismatic ones (``joint_units``: ``rad`` / ``m`` per joint).
        A kernel without linear joints read from a file of the older form (every joint on the circle) is kept as
        written; one that states units must state the robot's.

        Raises:
            ValueError: a joint whose unit is not the robot's, named.
        """
        lin = self.linear_joints(len(joint_units))
        if lin is None:
            return
        for name, is_lin, want in zip(joint_names, lin, joint_units):
            if ("m" if is_lin else "rad") != want:
                raise ValueError(f"{where}.joint_units: joint {name} is in {'m' if is_lin else 'rad'}, but the "
                                 f"robot's joint is in {want}; was the file written for another robot?")

    def features(self, Y: np.ndarray) -> tuple[np.ndarray, ...]:
        """(cos Y, sin Y, Y): what :meth:`against` needs of configurations Y (m, d), computed once."""
        Y = np.atleast_2d(np.asarray(Y, float))
        return np.cos(Y), np.sin(Y), Y

    # ------------------------------------------------------------------ scikit-learn hyper-parameters
    @property
    def hyperparameter_amplitude(self) -> Hyperparameter:
        return Hyperparameter.of("amplitude", "numeric", self.amplitude_bounds)

    @property
    def hyperparameter_length_scale(self) -> Hyperparameter:
        return Hyperparameter.of("length_scale", "numeric", self.length_scale_bounds, np.size(self.length_scale))

    @property
    def hyperparameter_joint_amplitude(self) -> Hyperparameter:
        return Hyperparameter.of("joint_amplitude", "numeric", self.joint_amplitude_bounds,
                                 np.size(self.joint_amplitude))

    @property
    def hyperparameter_joint_length_scale(self) -> Hyperparameter:
        return Hyperparameter.of("joint_length_scale", "numeric", self.joint_length_scale_bounds,
                                 np.size(self.joint_length_scale))

    def parts(self, d: int) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
        """(amplitude, length scales (d,), joint amplitudes (d,), joint length scales (d,)), scalars broadcast to d."""
        def vec(v: Any) -> np.ndarray:
            v = np.atleast_1d(np.asarray(v, float))
            return np.full(d, float(v[0])) if v.size == 1 else v
        return float(np.asarray(self.amplitude, float).reshape(-1)[0]), vec(self.length_scale), \
            vec(self.joint_amplitude), vec(self.joint_length_scale)

    def __call__(self, X: np.ndarray, Y: np.ndarray | None = None, eval_gradient: bool = False) -> Any:
        """K (n, m); with ``eval_gradient`` also dK/dlog θ (n, n, n_θ) in the order of ``self.hyperparameters``."""
        X = np.atleast_2d(np.asarray(X, float))
        if eval_gradient and Y is not None:
            raise ValueError("gradient can only be evaluated when Y is None")
        Yv = X if Y is None else np.atleast_2d(np.asarray(Y, float))
        c, L, a, ell = self.parts(X.shape[1])
        lin = self.linear_joints(X.shape[1])
        if not eval_gradient:
            return self._value(X, Yv, c, L, a, ell, lin=lin)
        D = _CHORDS(X, lin)
        Dp = D / L ** 2
        P = c ** 2 * np.exp(-0.5 * Dp.sum(-1))
        Da = D / ell ** 2
        A = a ** 2 * np.exp(-0.5 * Da)
        K = P + A.sum(-1)
        # scikit-learn orders the hyper-parameters by name: amplitude, joint_amplitude, joint_length_scale,
        # length_scale (``dir`` order of the ``hyperparameter_*`` properties)
        grads = [2.0 * P[..., None],
                 2.0 * A if np.size(self.joint_amplitude) > 1 else 2.0 * A.sum(-1, keepdims=True),
                 A * Da if np.size(self.joint_length_scale) > 1 else (A * Da).sum(-1, keepdims=True),
                 P[..., None] * Dp if np.size(self.length_scale) > 1 else (P * Dp.sum(-1))[..., None]]
        return K, np.concatenate(grads, axis=-1)

    def lower(self, X: np.ndarray) -> np.ndarray:
        """K(X, X)'s lower triangle (n, n), every entry to the last bit that of ``self(X)``, for a lower Cholesky
        factor (which reads nothing else): about half the work.

        Args:
            X: configurations (n, d) rad (m for a linear joint).

        Returns:
            K with its entries above the diagonal blocks of 128 rows left 0 (those inside the blocks are formed).
        """
        X = np.atleast_2d(np.asarray(X, float))
        c, L, a, ell = self.parts(X.shape[1])
        return _value_blocks(X, np.cos(X), np.sin(X), X, c, L, a, ell, self.linear_joints(X.shape[1]), lower=True)

    def against(self, X: np.ndarray, trig_Y: tuple[np.ndarray, ...]) -> np.ndarray:
        """K(X, Y) (n, m) for configurations Y given by ``trig_Y`` = :meth:`features` of Y ((cos Y, sin Y, Y), each
        (m, d); (cos Y, sin Y) alone without linear joints), computed once for many X (a pool's candidates, one
        column at a time); equal to ``self(X, Y)``."""
        X = np.atleast_2d(np.asarray(X, float))
        return self._value(X, None, *self.parts(X.shape[1]), trig_Y=trig_Y, lin=self.linear_joints(X.shape[1]))

    @staticmethod
    def _value(X: np.ndarray, Y: np.ndarray | None, c: float, L: np.ndarray, a: np.ndarray, ell: np.ndarray,
               block: int = 128, trig_Y: tuple[np.ndarray, ...] | None = None,
               lin: np.ndarray | None = None) -> np.ndarray:
        """K without the gradient, without a trigonometric function per pair: cos(x − y) = cos x cos y + sin x sin y,
        so the product part is one matrix product of the scaled circle points and each one-joint part an outer
        product; ``block`` rows at a time, so that the one-joint parts are summed while in the processor's cache."""
        if trig_Y is None:
            Y = np.atleast_2d(Y)
            return _value_blocks(X, np.cos(Y), np.sin(Y), Y, c, L, a, ell, lin, block)
        Yv = trig_Y[2] if len(trig_Y) > 2 else None
        return _value_blocks(X, trig_Y[0], trig_Y[1], None if Yv is None else np.atleast_2d(Yv), c, L, a, ell, lin,
                             block)

    def diag(self, X: np.ndarray) -> np.ndarray:
        """k(q, q) for each row: c² + Σ a_j²."""
        c, _, a, _ = self.parts(np.atleast_2d(X).shape[1])
        return np.full(np.atleast_2d(X).shape[0], c ** 2 + float((a ** 2).sum()))

    def is_stationary(self) -> bool:
        return True

    # ------------------------------------------------------------------ derivative in the joint angles
    def grad_x(self, X: np.ndarray, Y: np.ndarray) -> np.ndarray:
        """∂k(x_i, y_k)/∂x_ij: (n, m, d) (per rad; per m for a linear joint).

        ∂/∂x_j of exp(−2 sin²(Δ_j/2)/L_j²) is −sin(Δ_j)/L_j² times the factor (4 sin²(Δ/2) =
        2 − 2 cos Δ, so its derivative is 2 sin Δ); of a linear joint's exp(−Δ_j²/(2L_j²)) it is −Δ_j/L_j² times it.
        """
        X = np.atleast_2d(np.asarray(X, float))
        Y = np.atleast_2d(np.asarray(Y, float))
        c, L, a, ell = self.parts(X.shape[1])
        Dq = X[:, None, :] - Y[None, :, :]
        D = 2.0 - 2.0 * np.cos(Dq)
        S = np.sin(Dq)
        lin = self.linear_joints(X.shape[1])
        if lin is not None:
            D[..., lin] = Dq[..., lin] ** 2
            S[..., lin] = Dq[..., lin]
        P = c ** 2 * np.exp(-0.5 * (D / L ** 2).sum(-1))
        A = a ** 2 * np.exp(-0.5 * D / ell ** 2)
        return -(P[..., None] * S / L ** 2) - A * S / ell ** 2

    # ------------------------------------------------------------------ plain data
    def to_dict(self) -> dict:
        """Hyper-parameters as plain numbers (the model file's ``discrepancy.kernel``): form ``joint_wrapped_se/1``
        (length scales in rad) without linear joints, else ``joint_se/2`` with each joint's unit (``joint_units``:
        ``rad`` on the circle, ``m`` on the line) and the length scales in it."""
        d = int(max(np.size(self.length_scale), np.size(self.joint_amplitude), np.size(self.joint_length_scale)))
        c, L, a, ell = self.parts(d)
        lin = self.linear_joints(d)
        if lin is None:
            return {"form": FORM_CIRCLE, "amplitude": c, "length_scale_rad": L.tolist(),
                    "joint_amplitude": a.tolist(), "joint_length_scale_rad": ell.tolist()}
        return {"form": FORM_UNITS, "joint_units": ["m" if v else "rad" for v in lin], "amplitude": c,
                "length_scale": L.tolist(), "joint_amplitude": a.tolist(), "joint_length_scale": ell.tolist()}

    @classmethod
    def from_dict(cls, d: Any, n_joints: int, where: str = "discrepancy.kernel") -> JointKernel:
        """Inverse of :meth:`to_dict`, every field checked (a file of form ``joint_wrapped_se/1``, written before
        linear joints were told apart: every joint on the circle, as written).

        Raises:
            ValueError: another form, a missing field, a wrong length, a non-positive or non-finite value
                (the message names the field; callers turn it into an input error naming the file).
        """
        if not isinstance(d, dict):
            raise ValueError(f"{where}: must be an object with the kernel's hyper-parameters")
        if d.get("form") not in (FORM_CIRCLE, FORM_UNITS):
            raise ValueError(f"{where}.form: {d.get('form')!r} is not a known kernel (expected "
                             f"'{FORM_CIRCLE}' or '{FORM_UNITS}')")
        lin = np.zeros(n_joints, bool)
        if d["form"] == FORM_UNITS:
            units = d.get("joint_units")
            if not isinstance(units, list) or len(units) != n_joints or any(u not in ("rad", "m") for u in units):
                raise ValueError(f"{where}.joint_units: must be {n_joints} units 'rad' or 'm' (one per joint), "
                                 f"got {units!r}")
            lin = np.array([u == "m" for u in units])
        suffix = "_rad" if d["form"] == FORM_CIRCLE else ""

        def num(key: str, n: int | None, length: bool = False) -> Any:
            if key not in d:
                raise ValueError(f"{where}.{key}: missing")
            try:
                v = np.asarray(d[key], dtype=float)
            except (TypeError, ValueError):
                raise ValueError(f"{where}.{key}: must be numbers, got {d[key]!r}") from None
            if (n is None and v.shape != ()) or (n is not None and v.shape != (n,)):
                want = "one number" if n is None else f"{n} numbers (one per joint)"
                raise ValueError(f"{where}.{key}: must be {want}, got shape {v.shape}")
            if not np.all(np.isfinite(v)) or np.any(v <= 0):
                raise ValueError(f"{where}.{key}: must be positive and finite, got {d[key]!r}")
            va = np.atleast_1d(v)
            rng = np.where(lin[:, None], FILE_RANGE_LEN_M, FILE_RANGE_LEN) if length else \
                np.tile(FILE_RANGE_AMP, (va.size, 1))
            lo, hi = rng[:, 0], rng[:, 1]
            bad = np.flatnonzero((va < lo) | (va > hi))
            if bad.size:
                k = int(bad[0])
                unit = ("m" if lin[k] else "rad") if length else "normalised"
                raise ValueError(f"{where}.{key}: {va[k]:g} ({unit}) is outside [{lo[k]:g}, {hi[k]:g}] (the fit "
                                 f"keeps it within {(_BOUNDS_LEN if length else _BOUNDS_AMP)}"
                                 f"{' x travel/2pi' if length and lin[k] else ''}); was the file edited?")
            return float(v) if n is None else v
        return cls(num("amplitude", None), num("length_scale" + suffix, n_joints, True),
                   num("joint_amplitude", n_joints), num("joint_length_scale" + suffix, n_joints, True),
                   linear=lin if lin.any() else None)
