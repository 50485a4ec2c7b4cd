"""Hyper-parameters of a kernel as scikit-learn's Gaussian-process kernels declare them, without scikit-learn.

:class:`HyperKernel` gives a kernel scikit-learn's protocol — ``theta`` (the logarithms of the free
hyper-parameters in the ``dir`` order of its ``hyperparameter_*`` properties), ``bounds``, ``hyperparameters``,
``get_params`` / ``set_params``, ``clone_with_theta``, ``n_dims``, equality — so that the package fits and stores
its kernel without importing scikit-learn (a second of CPU time at every command that fits a discrepancy). Sums and
products with scikit-learn's kernels (``kernel + WhiteKernel(...)``) import scikit-learn when they are formed, and
scikit-learn's ``GaussianProcessRegressor`` takes such a sum as it takes its own kernels (the tests compare with it).
"""

from __future__ import annotations

import copy
import inspect
from typing import Any, NamedTuple

import numpy as np

__all__ = ["Hyperparameter", "HyperKernel"]


class Hyperparameter(NamedTuple):
    """One hyper-parameter: its name, kind, bounds ((2,) or one row per element, (n_elements, 2)), number of
    elements and whether it is held fixed (scikit-learn's ``Hyperparameter``: the same fields, the same bounds'
    shape)."""

    name: str
    value_type: str
    bounds: Any
    n_elements: int = 1
    fixed: bool = False

    @classmethod
    def of(cls, name: str, value_type: str, bounds: Any, n_elements: int = 1) -> Hyperparameter:
        """The hyper-parameter with its bounds as scikit-learn stores them: (n_elements, 2), or ``"fixed"``.

        Raises:
            ValueError: bounds of another number of rows than elements.
        """
        if isinstance(bounds, str) and bounds == "fixed":
            return cls(name, value_type, bounds, int(n_elements), True)
        b = np.atleast_2d(bounds)
        if n_elements > 1 and b.shape[0] == 1:
            b = np.repeat(b, n_elements, 0)
        elif n_elements > 1 and b.shape[0] != n_elements:
            raise ValueError(f"bounds of {name}: {b.shape[0]} rows for {n_elements} elements")
        return cls(name, value_type, b, int(n_elements), False)


class HyperKernel:
    """The part of scikit-learn's ``Kernel`` base class the package's kernel needs (see the module); a subclass
    declares its hyper-parameters as ``hyperparameter_<name>`` properties returning :class:`Hyperparameter` and takes
    every parameter as a keyword of its ``__init__``, stored unchanged."""

    requires_vector_input = True

    def get_params(self, deep: bool = True) -> dict:
        """The ``__init__`` parameters by name (``deep`` is scikit-learn's flag: no nested kernels here)."""
        names = [p.name for p in inspect.signature(type(self).__init__).parameters.values()
                 if p.name != "self" and p.kind not in (p.VAR_KEYWORD, p.VAR_POSITIONAL)]
        return {name: getattr(self, name) for name in names}

    def set_params(self, **params: Any) -> HyperKernel:
        """Set parameters by name.

        Raises:
            ValueError: a name that is not a parameter.
        """
        valid = self.get_params()
        for key, value in params.items():
            if key not in valid:
                raise ValueError(f"invalid parameter {key} for kernel {type(self).__name__}")
            setattr(self, key, value)
        return self

    @property
    def hyperparameters(self) -> list[Hyperparameter]:
        """The hyper-parameters in the ``dir`` order of their properties (scikit-learn's order of ``theta``)."""
        return [getattr(self, attr) for attr in dir(self) if attr.startswith("hyperparameter_")]

    @property
    def theta(self) -> np.ndarray:
        """The logarithms of the free hyper-parameters, flattened."""
        params = self.get_params()
        values = [params[h.name] for h in self.hyperparameters if not h.fixed]
        return np.log(np.hstack(values)) if values else np.array([])

    @theta.setter
    def theta(self, theta: np.ndarray) -> None:
        params = self.get_params()
        i = 0
        for h in self.hyperparameters:
            if h.fixed:
                continue
            if h.n_elements > 1:
                params[h.name] = np.exp(theta[i:i + h.n_elements])
            else:
                params[h.name] = np.exp(theta[i])
            i += h.n_elements
        if i != len(theta):
            raise ValueError(f"theta has not the correct number of entries: should be {i}, got {len(theta)}")
        self.set_params(**params)

    @property
    def n_dims(self) -> int:
        """Number of free hyper-parameters (elements)."""
        return int(self.theta.shape[0])

    @property
    def bounds(self) -> np.ndarray:
        """The log bounds of ``theta``: (n_dims, 2)."""
        rows = [h.bounds for h in self.hyperparameters if not h.fixed]
        return np.log(np.vstack(rows)) if rows else np.array([])

    def clone_with_theta(self, theta: np.ndarray) -> HyperKernel:
        """A copy with the hyper-parameters ``theta`` (logarithms)."""
        cloned = copy.deepcopy(self)
        cloned.theta = theta
        return cloned

    def is_stationary(self) -> bool:
        """Whether the kernel depends on the differences of its arguments only."""
        return True

    def __eq__(self, other: object) -> bool:
        if type(self) is not type(other):
            return False
        a, b = self.get_params(), other.get_params()
        return all(not np.any(a.get(k) != b.get(k)) for k in set(a) | set(b))

    def __repr__(self) -> str:
        return f"{type(self).__name__}({', '.join(map('{0:.3g}'.format, self.theta))})"

    # sums and products with scikit-learn's kernels: scikit-learn's own operators, imported when formed
    def __add__(self, other: Any) -> Any:
        from sklearn.gaussian_process.kernels import ConstantKernel, Kernel, Sum

        return Sum(self, other if isinstance(other, (Kernel, HyperKernel)) else ConstantKernel(other))

    def __radd__(self, other: Any) -> Any:
        from sklearn.gaussian_process.kernels import ConstantKernel, Kernel, Sum

        return Sum(other if isinstance(other, (Kernel, HyperKernel)) else ConstantKernel(other), self)

    def __mul__(self, other: Any) -> Any:
        from sklearn.gaussian_process.kernels import ConstantKernel, Kernel, Product

        return Product(self, other if isinstance(other, (Kernel, HyperKernel)) else ConstantKernel(other))

    def __rmul__(self, other: Any) -> Any:
        from sklearn.gaussian_process.kernels import ConstantKernel, Kernel, Product

        return Product(other if isinstance(other, (Kernel, HyperKernel)) else ConstantKernel(other), self)
