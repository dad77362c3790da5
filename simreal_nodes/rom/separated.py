"""Evaluation of a separated field u(x, mu) = sum_i F_i(x) prod_k G_i^k(mu_k) and of its sensitivities.

Thesis Eq. 2.9 (evaluation) and Eq. 4.9 / the sensitivity formula of §4.4:

    du/dmu_k = sum_i F_i(x) dG_i^k/dmu_k(mu_k) prod_{l != k} G_i^l(mu_l)

The parameter modes G_i^k are nodal values on the axis grid; between nodes they are interpolated
(``cubic``: C2 spline, smooth sensitivities; ``linear``: the finite-element interpolation of the
axis, exact for loads between two load points of a linear model). A ``discrete`` axis (e.g. the
index of a precomputed contact point) takes integer values and has no sensitivity.
"""

from __future__ import annotations

import bisect
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, Literal, overload

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.interpolate import CubicSpline

AXIS_KINDS = ("continuous", "discrete")
INTERPOLATIONS = ("cubic", "linear")

# Node selections: indices into the space modes' node axis (an (N, k) array for interpolated views).
Nodes = NDArray[np.integer] | Sequence[int]
# An axis's interpolant: ("linear", x, y, slope) or ("cubic", breakpoints, coefficients (n-1, 4, m)).
_Linear = tuple[Literal["linear"], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]
_Cubic = tuple[Literal["cubic"], NDArray[np.float64], NDArray[np.float64]]


@dataclass
class Axis:
    name: str
    values: NDArray[np.float64]
    unit: str = ""
    kind: str = "continuous"
    interpolation: str = "cubic"
    description: str = ""

    def __post_init__(self) -> None:
        self.values = np.asarray(self.values, dtype=np.float64)
        if self.values.ndim != 1 or len(self.values) < 1:
            raise ValueError(f"axis '{self.name}' needs a 1-D grid of values")
        if len(self.values) > 1 and np.any(np.diff(self.values) <= 0):
            raise ValueError(f"axis '{self.name}' values must increase strictly")
        if self.kind not in AXIS_KINDS:
            raise ValueError(f"axis kind must be one of {AXIS_KINDS}, got '{self.kind}'")
        if self.interpolation not in INTERPOLATIONS:
            raise ValueError(f"axis interpolation must be one of {INTERPOLATIONS}, got '{self.interpolation}'")

    @property
    def range(self) -> tuple[float, float]:
        return float(self.values[0]), float(self.values[-1])

    def contains(self, x: float, tol: float = 1e-9) -> bool:
        lo, hi = self.range
        span = max(hi - lo, 1e-300)
        return lo - tol * span <= x <= hi + tol * span

    def as_dict(self) -> dict[str, Any]:
        return {"name": self.name, "unit": self.unit, "kind": self.kind, "interpolation": self.interpolation,
                "range": list(self.range), "n": len(self.values), "description": self.description}


class AxisModes:
    """All parameter modes of one axis, interpolated together: values and derivatives, shape (m,)."""

    def __init__(self, axis: Axis, modes: NDArray[np.float64]) -> None:
        self.axis = axis
        self.modes = np.asarray(modes, dtype=np.float64)  # (m, n)
        x = axis.values
        self._xl = [float(v) for v in x]
        self._pp: _Linear | _Cubic | None
        if axis.kind == "discrete" or len(x) == 1:
            self._pp = None
        elif axis.interpolation == "linear" or len(x) < 4:
            slope = np.diff(self.modes, axis=1) / np.diff(x)  # (m, n-1)
            self._pp = ("linear", x, self.modes, slope)
        else:
            cs = CubicSpline(x, self.modes.T, axis=0, bc_type="not-a-knot")
            # per interval, the 4 polynomial coefficients of every mode, contiguous (Horner in one pass)
            self._pp = ("cubic", cs.x, np.ascontiguousarray(cs.c.transpose(1, 0, 2)))  # (n-1, 4, m)

    def _interval(self, t: float) -> int:
        i = bisect.bisect_right(self._xl, t) - 1
        return 0 if i < 0 else (len(self._xl) - 2 if i > len(self._xl) - 2 else i)

    def value_and_derivative(self, t: float, m: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Both at once (the tracker's hot path)."""
        if self._pp is None or self._pp[0] != "cubic":
            return self.value(t, m), self.derivative(t, m)
        _, _x, c = self._pp
        i = self._interval(t)
        d = t - self._xl[i]
        ci = c[i, :, :m]
        v = ((ci[0] * d + ci[1]) * d + ci[2]) * d + ci[3]
        dv = (3 * ci[0] * d + 2 * ci[1]) * d + ci[2]
        return v, dv

    def value(self, t: float, m: int) -> NDArray[np.float64]:
        if self._pp is None:
            at_index: NDArray[np.float64] = self.modes[:m, self._index(t)]
            return at_index
        if self._pp[0] == "linear":
            _, x, y, slope = self._pp
            i = self._interval(t)
            v: NDArray[np.float64] = y[:m, i] + slope[:m, i] * (t - x[i])
            return v
        _, x, c = self._pp
        i = self._interval(t)
        d = t - self._xl[i]
        ci = c[i, :, :m]
        val: NDArray[np.float64] = ((ci[0] * d + ci[1]) * d + ci[2]) * d + ci[3]
        return val

    def derivative(self, t: float, m: int) -> NDArray[np.float64]:
        if self._pp is None:
            raise ValueError(f"axis '{self.axis.name}' is discrete: it has no sensitivity")
        if self._pp[0] == "linear":
            _, _x, _y, slope = self._pp
            return slope[:m, self._interval(t)].copy()
        _, _x, c = self._pp
        i = self._interval(t)
        d = t - self._xl[i]
        ci = c[i, :, :m]
        der: NDArray[np.float64] = (3 * ci[0] * d + 2 * ci[1]) * d + ci[2]
        return der

    def _index(self, t: float) -> int:
        i = round(t)
        if abs(t - i) > 1e-9 or not 0 <= i < self.modes.shape[1]:
            if len(self.axis.values) == 1:
                return 0
            raise ValueError(f"axis '{self.axis.name}' is discrete: value {t} is not an index "
                             f"0..{self.modes.shape[1] - 1}")
        return i


@dataclass
class SeparatedField:
    """One field (displacement, stress, ...) of a reduced model."""

    name: str
    space: NDArray[np.float64]  # (n_modes, n_nodes, n_comp)
    params: list[NDArray[np.float64]]  # per axis: (n_modes, n_axis)
    axes: list[Axis]
    unit: str = ""
    components: list[str] = field(default_factory=list)
    error_vs_modes: NDArray[np.float64] | None = None  # relative error after 1..n modes (against the full-order truth)

    def __post_init__(self) -> None:
        self.space = np.asarray(self.space)
        if self.space.ndim == 2:
            self.space = self.space[:, :, None]
        m = self.space.shape[0]
        if len(self.params) != len(self.axes):
            raise ValueError(f"field '{self.name}': {len(self.params)} parameter-mode sets for {len(self.axes)} axes")
        for p, ax in zip(self.params, self.axes):
            if p.shape != (m, len(ax.values)):
                raise ValueError(f"field '{self.name}': modes of axis '{ax.name}' have shape {p.shape}, "
                                 f"expected ({m}, {len(ax.values)})")
        self._axis_modes = [AxisModes(ax, p) for ax, p in zip(self.axes, self.params)]

    @property
    def n_modes(self) -> int:
        return int(self.space.shape[0])

    @property
    def n_nodes(self) -> int:
        return int(self.space.shape[1])

    @property
    def n_comp(self) -> int:
        return int(self.space.shape[2])

    def _m(self, n_modes: int | None) -> int:
        if n_modes is None or n_modes == 0:
            return self.n_modes
        if n_modes < 0 or n_modes > self.n_modes:
            raise ValueError(f"field '{self.name}' has {self.n_modes} modes; {n_modes} were requested")
        return int(n_modes)

    def check_mu(self, mu: ArrayLike) -> NDArray[np.float64]:
        mu = np.asarray(mu, dtype=np.float64).ravel()
        if mu.size != len(self.axes):
            raise ValueError(f"expected {len(self.axes)} parameters ({', '.join(a.name for a in self.axes)}), "
                             f"got {mu.size}")
        for v, ax in zip(mu, self.axes):
            if not np.isfinite(v):
                raise ValueError(f"parameter '{ax.name}' is not finite: {v}")
            if not ax.contains(v):
                raise ValueError(f"parameter '{ax.name}' = {v:g} is outside the model's range "
                                 f"[{ax.range[0]:g}, {ax.range[1]:g}]")
        return mu

    @overload
    def coefficients(self, mu: ArrayLike, n_modes: int | None = None, with_derivatives: Literal[False] = False,
                     checked: bool = False) -> NDArray[np.float64]: ...

    @overload
    def coefficients(self, mu: ArrayLike, n_modes: int | None, with_derivatives: Literal[True],
                     checked: bool = False) -> tuple[NDArray[np.float64], NDArray[np.float64]]: ...

    @overload
    def coefficients(self, mu: ArrayLike, n_modes: int | None = None, *, with_derivatives: Literal[True],
                     checked: bool = False) -> tuple[NDArray[np.float64], NDArray[np.float64]]: ...

    def coefficients(self, mu: ArrayLike, n_modes: int | None = None, with_derivatives: bool = False,
                     checked: bool = False) -> NDArray[np.float64] | tuple[NDArray[np.float64], NDArray[np.float64]]:
        """c_i = prod_k G_i^k(mu_k) and, optionally, dc_i/dmu_k (m, n_params; NaN columns for discrete axes).
        ``checked``: mu was validated by the caller (hot loops)."""
        m = self._m(n_modes)
        mu = np.asarray(mu, dtype=np.float64).ravel() if checked else self.check_mu(mu)
        if len(self._axis_modes) == 1:  # the common single-parameter case, without list building
            am = self._axis_modes[0]
            if not with_derivatives:
                return am.value(float(mu[0]), m)
            if am._pp is None:
                return am.value(float(mu[0]), m), np.full((m, 1), np.nan)
            c, d = am.value_and_derivative(float(mu[0]), m)
            return c, d[:, None]
        vals = [am.value(t, m) for am, t in zip(self._axis_modes, mu)]
        c = np.prod(vals, axis=0) if vals else np.ones(m)
        if not with_derivatives:
            return c
        dc = np.full((m, len(mu)), np.nan)
        for k, (am, t) in enumerate(zip(self._axis_modes, mu)):
            if am._pp is None:
                continue
            others = np.prod([v for l, v in enumerate(vals) if l != k], axis=0) if len(vals) > 1 else np.ones(m)
            dc[:, k] = am.derivative(t, m) * others
        return c, dc

    def evaluate(self, mu: ArrayLike, nodes: Nodes | None = None, n_modes: int | None = None) -> NDArray[np.float64]:
        """u(x, mu): (n_nodes or len(nodes), n_comp)."""
        c = self.coefficients(mu, n_modes)
        S = self.space[: len(c)] if nodes is None else self.space[: len(c), nodes]
        return np.tensordot(c, S, axes=(0, 0))

    def sensitivity(self, mu: ArrayLike, k: int, nodes: Nodes | None = None,
                    n_modes: int | None = None) -> NDArray[np.float64]:
        """du/dmu_k: (n_sel, n_comp)."""
        c, dc = self.coefficients(mu, n_modes, with_derivatives=True)
        if np.isnan(dc[0, k]):
            raise ValueError(f"parameter '{self.axes[k].name}' is discrete: it has no sensitivity")
        S = self.space[: len(c)] if nodes is None else self.space[: len(c), nodes]
        return np.tensordot(dc[:, k], S, axes=(0, 0))

    def view(self, nodes: Nodes | None = None, n_modes: int | None = None,
             weights: ArrayLike | None = None) -> FieldView:
        """The field at ``nodes`` (None: all), or, with ``weights`` (N, k) and ``nodes`` (N, k), at N points
        each interpolated from k nodes (Eq. 4.10's links, folded into the modes once)."""
        return FieldView(self, nodes, self._m(n_modes), weights)

    def truncated(self, n_modes: int) -> SeparatedField:
        m = self._m(n_modes)
        return SeparatedField(self.name, self.space[:m], [p[:m] for p in self.params], self.axes, self.unit,
                              self.components, None if self.error_vs_modes is None else self.error_vs_modes[:m])


class FieldView:
    """A field restricted to some nodes and modes, laid out for fast repeated evaluation
    (one small matrix product per call: what the tracker and the overlay call every frame)."""

    def __init__(self, f: SeparatedField, nodes: Nodes | None, n_modes: int, weights: ArrayLike | None = None) -> None:
        self.field = f
        self.n_modes = n_modes
        if weights is not None:
            nodes, weights = np.asarray(nodes), np.asarray(weights, dtype=np.float64)
            if nodes.shape != weights.shape or nodes.ndim != 2:
                raise ValueError(f"interpolated view: nodes {nodes.shape} and weights {weights.shape} "
                                 "must both be (N, k)")
            sel = np.einsum("mnkc,nk->mnc", f.space[:n_modes][:, nodes], weights)
        else:
            sel = f.space[:n_modes] if nodes is None else f.space[:n_modes, nodes]
        self.n_sel, self.n_comp = sel.shape[1], sel.shape[2]
        # modes as rows (m, n_sel * n_comp): one streaming pass over memory per evaluation
        self.S = np.ascontiguousarray(sel.reshape(n_modes, -1), dtype=np.float64)

    @property
    def modes(self) -> NDArray[np.float64]:
        """The selected space modes, (n_modes, n_sel, n_comp) (a view of the evaluation layout)."""
        return self.S.reshape(self.n_modes, self.n_sel, self.n_comp)

    def evaluate(self, mu: ArrayLike, n_modes: int | None = None) -> NDArray[np.float64]:
        """u at the view's points with its modes, or with the first ``n_modes`` of them (a live truncation:
        the overlay's per-view mode count)."""
        m = self.n_modes if n_modes is None else n_modes
        if not 0 < m <= self.n_modes:
            raise ValueError(f"view of field '{self.field.name}' has {self.n_modes} modes; {m} were requested")
        c = self.field.coefficients(mu, m)
        return (c @ self.S[:m]).reshape(self.n_sel, self.n_comp)

    def evaluate_many(self, mus: ArrayLike) -> NDArray[np.float64]:
        """u at the view's points for each row of ``mus`` (K, n_params): (K, n_sel, n_comp), one product for all
        (a search over candidate parameters)."""
        mus = np.atleast_2d(np.asarray(mus, np.float64))
        C = np.array([self.field.coefficients(mu, self.n_modes) for mu in mus]).reshape(len(mus), self.n_modes)
        return (C @ self.S).reshape(len(mus), self.n_sel, self.n_comp)

    def evaluate_with_jacobian(self, mu: ArrayLike, checked: bool = False
                               ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """u (n_sel, n_comp) and du/dmu (n_sel, n_comp, n_params) in one product."""
        c, dc = self.field.coefficients(mu, self.n_modes, with_derivatives=True, checked=checked)
        C = np.empty((1 + dc.shape[1], len(c)))
        C[0] = c
        C[1:] = dc.T
        C[~np.isfinite(C)] = 0.0
        out = C @ self.S  # (1 + n_params, n_sel * n_comp)
        u = out[0].reshape(self.n_sel, self.n_comp)
        J = out[1:].reshape(-1, self.n_sel, self.n_comp).transpose(1, 2, 0)
        return u, J
