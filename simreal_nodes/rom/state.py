"""The model state: everything that shapes one reduced model in one frame, in one place.

A model state is the model's parameters ``mu`` (one per axis, in axis order) plus the rigid extras the
estimators and the contact add on top of the separated field:

- ``alpha_z``: a rotation of the deformation about the object's z axis (thesis §4.5.4, a rigid parameter the
  model declares in ``rigid_parameters``);
- ``load_scale``: for a *linear* model loaded by contact, the pseudo-time scales the precomputed load, hence
  the displacement (Alg. 5.1 on a PGD beam without a pseudo-time axis);
- ``shift``: a translation of the whole object in the map frame, metres (the tracker's nuisance parameter that
  absorbs camera-pose drift; never sent in messages).

The deformation of a state, in the object frame, is ``load_scale * R_z(alpha_z) u(x, mu)`` (evaluated by
:meth:`ReducedModel.deformation` and :class:`~simreal_nodes.rom.model.DeformationView`); the shift moves the
object, not its shape. A :class:`StateLayout` says which of these a flat vector carries and in which order
(mu, alpha_z, load_scale, shift): the LM's unknowns, a message's (names, values), an estimate's values.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any, Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from simreal_nodes import geometry as G
from simreal_nodes.rom.separated import Axis


class ModelDescription(Protocol):
    """What a model state needs to know of its reduced model (:class:`~simreal_nodes.rom.model.ReducedModel` has
    it): its parameter axes, declared rigid parameters and, for contacts, its load points. A protocol rather than
    the model class keeps this module below ``rom.model``, which evaluates states (no import cycle)."""

    @property
    def name(self) -> str: ...
    @property
    def axes(self) -> Sequence[Axis]: ...
    @property
    def rigid_parameters(self) -> Sequence[dict[str, Any]]: ...
    @property
    def points(self) -> NDArray[Any]: ...
    @property
    def load_points(self) -> NDArray[Any] | None: ...
    @property
    def material(self) -> dict[str, Any]: ...

Vector = NDArray[np.float64]

ALPHA_Z = "alpha_z"
LOAD_SCALE = "load_scale"
SHIFT = ("shift_x", "shift_y", "shift_z")
PSEUDO_TIME = "pseudo_time"
LOAD_POINT = "load_point"  # a probe model's axis: the index of its discrete contact point
# a message with several contacts names the k-th one's parameters "<name>@k" (k >= 2; ModelParameters.msg)
CONTACT_SEP = "@"
# Axes of linear contact models that are the position of their load: which coordinate of a load point they take.
LOAD_POSITION_AXES: dict[str, int] = {"s": 0, "s_x": 0, "s_y": 1}
# load_scale is a pseudo-time: 0 undeformed, 1 the largest precomputed deformation (ContactState.msg).
LOAD_SCALE_RANGE = (0.0, 1.0)

_NO_SHIFT = np.zeros(3)
_NO_SHIFT.flags.writeable = False


def _no_shift() -> Vector:
    return _NO_SHIFT


@dataclass(eq=False)
class ModelState:
    """One model state; see the module docstring. ``mu`` is a float64 vector in axis order."""

    mu: Vector
    alpha_z: float = 0.0
    load_scale: float = 1.0
    shift: Vector = field(default_factory=_no_shift)

    def rotation(self) -> Vector:
        """R_z(alpha_z): object frame -> the rotated object frame the deformation is drawn in."""
        return G.rot_axis("z", self.alpha_z)

    def rigid(self, u: Vector) -> Vector:
        """The rigid extras applied to a displacement u(x, mu) (n, 3): scaled by ``load_scale``, then rotated by
        alpha_z. Skipped when they are the identity (the hot paths: no copy, the same numbers)."""
        if self.load_scale != 1.0:
            u = self.load_scale * u
        if self.alpha_z:
            u = u @ self.rotation().T
        return u

    @classmethod
    def from_named(cls, axes: Sequence[Axis], names: Sequence[str], values: Sequence[float]) -> ModelState:
        """The state a message's (names, values) describes, made drawable: the one place where what a producer
        may send is interpreted.

        A model parameter that is missing or not finite takes its lower bound (nothing is known: draw the rest
        shape's end of the range), one out of range is clipped to it; alpha_z missing or not finite is 0;
        load_scale missing is 1 (a model without contact scaling), not finite 0 (a contact of unknown depth:
        draw no load). A name the model state does not have is an error: a producer and a model that
        disagree must not be drawn silently wrong."""
        if len(names) != len(values):
            raise ValueError(f"{len(names)} parameter names for {len(values)} values")
        known = [a.name for a in axes] + [ALPHA_Z, LOAD_SCALE]
        given: dict[str, float] = {}
        for name, value in zip(names, values):
            if name not in known:
                raise ValueError(f"unknown parameter '{name}' (this model's state has: {', '.join(known)})")
            given[name] = float(value)
        mu = []
        for a in axes:
            lo, hi = a.range
            v = given.get(a.name, lo)
            mu.append(min(max(v if np.isfinite(v) else lo, lo), hi))
        alpha = given.get(ALPHA_Z, 0.0)
        scale = given.get(LOAD_SCALE, 1.0)
        return cls(np.asarray(mu, dtype=np.float64), alpha if np.isfinite(alpha) else 0.0,
                   scale if np.isfinite(scale) else 0.0)


    @classmethod
    def from_named_contacts(cls, axes: Sequence[Axis], names: Sequence[str],
                            values: Sequence[float]) -> list[ModelState]:
        """The states of a message that carries several contacts (a collision with ``max_contacts`` > 1): the
        first contact's parameters under their names, the k-th one's as ``name@k`` (k = 2, 3, ...); each contact
        is read as :meth:`from_named` reads one. Their deformations add (linear models only send several)."""
        if len(names) != len(values):
            raise ValueError(f"{len(names)} parameter names for {len(values)} values")
        groups: dict[int, tuple[list[str], list[float]]] = {1: ([], [])}
        for name, value in zip(names, values):
            base, sep, k = str(name).partition(CONTACT_SEP)
            if sep and not (k.isdigit() and int(k) >= 2 and k == str(int(k))):
                raise ValueError(f"parameter '{name}': a further contact's name ends in {CONTACT_SEP}2, "
                                 f"{CONTACT_SEP}3, ...")
            n_, v_ = groups.setdefault(int(k) if sep else 1, ([], []))
            n_.append(base)
            v_.append(value)
        if sorted(groups) != list(range(1, len(groups) + 1)) or (len(groups) > 1 and not groups[1][0]):
            raise ValueError(f"contacts {sorted(groups)} in a message: the first one's parameters under their names, "
                             f"the next as {CONTACT_SEP}2, {CONTACT_SEP}3, ... without gaps")
        return [cls.from_named(axes, *groups[k]) for k in sorted(groups)]


@dataclass(frozen=True)
class StateLayout:
    """Which parts of a model state a flat vector carries, in this order: mu (one per axis), alpha_z (when
    ``alpha_z`` holds its range), load_scale, shift (3, map frame)."""

    axes: tuple[Axis, ...]
    alpha_z: tuple[float, float] | None = None
    load_scale: bool = False
    shift: bool = False

    @classmethod
    def of(cls, model: ModelDescription, alpha_z: bool = False, load_scale: bool = False,
           shift: bool = False) -> StateLayout:
        """The layout of ``model`` with the extras asked for; alpha_z's range is the one the model declares."""
        rng = None
        if alpha_z:
            rigid = {r["name"]: r for r in model.rigid_parameters}
            if ALPHA_Z not in rigid:
                raise ValueError(f"model '{model.name}' declares no rigid parameter '{ALPHA_Z}'")
            lo, hi = rigid[ALPHA_Z]["range"]
            rng = (float(lo), float(hi))
        return cls(tuple(model.axes), rng, load_scale, shift)

    def with_shift(self) -> StateLayout:
        return replace(self, shift=True)

    @property
    def n_mu(self) -> int:
        return len(self.axes)

    @property
    def alpha_index(self) -> int:
        """Where alpha_z sits in the vector (right after mu)."""
        if self.alpha_z is None:
            raise ValueError("this layout carries no alpha_z")
        return self.n_mu

    @property
    def size(self) -> int:
        return self.n_mu + (self.alpha_z is not None) + int(self.load_scale) + (3 if self.shift else 0)

    @property
    def names(self) -> list[str]:
        return ([a.name for a in self.axes] + ([ALPHA_Z] if self.alpha_z is not None else [])
                + ([LOAD_SCALE] if self.load_scale else []) + (list(SHIFT) if self.shift else []))

    @property
    def units(self) -> list[str]:
        return ([a.unit for a in self.axes] + (["rad"] if self.alpha_z is not None else [])
                + ([""] if self.load_scale else []) + (["m"] * 3 if self.shift else []))

    def bounds(self, shift_m: float = 0.0) -> tuple[Vector, Vector]:
        """(lo, hi): the axes' ranges, alpha_z's declared range, load_scale's [0, 1] and +-``shift_m``."""
        lo = [a.range[0] for a in self.axes]
        hi = [a.range[1] for a in self.axes]
        if self.alpha_z is not None:
            lo.append(self.alpha_z[0])
            hi.append(self.alpha_z[1])
        if self.load_scale:
            lo.append(LOAD_SCALE_RANGE[0])
            hi.append(LOAD_SCALE_RANGE[1])
        if self.shift:
            lo += [-shift_m] * 3
            hi += [shift_m] * 3
        return np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)

    def state(self, x: ArrayLike) -> ModelState:
        """Decode a flat vector (its mu and shift are views of ``x``, not copies)."""
        v = np.asarray(x, dtype=np.float64)
        if v.shape != (self.size,):
            raise ValueError(f"expected {self.size} values ({', '.join(self.names)}), got shape {v.shape}")
        i = self.n_mu
        alpha, scale = 0.0, 1.0
        if self.alpha_z is not None:
            alpha = float(v[i])
            i += 1
        if self.load_scale:
            scale = float(v[i])
            i += 1
        return ModelState(v[: self.n_mu], alpha, scale, v[i:] if self.shift else _NO_SHIFT)

    def vector(self, state: ModelState) -> Vector:
        """The flat vector of ``state`` in this layout (what :meth:`state` decodes)."""
        parts = [np.asarray(state.mu, dtype=np.float64).ravel()]
        if self.alpha_z is not None:
            parts.append(np.array([state.alpha_z]))
        if self.load_scale:
            parts.append(np.array([state.load_scale]))
        if self.shift:
            parts.append(np.asarray(state.shift, dtype=np.float64).ravel())
        v = np.concatenate(parts)
        if v.shape != (self.size,):
            raise ValueError(f"state with {len(parts[0])} parameters for a layout of {self.n_mu}")
        return v

    def named(self, state: ModelState) -> tuple[list[str], list[float]]:
        """(names, values) as messages carry them."""
        return self.names, [float(v) for v in self.vector(state)]


class LoadPointStates:
    """The model state of a contact at one of the model's load points pushed to a pseudo-time (Alg. 5.1).

    Three kinds of contact model:

    - a probe model (NI-PGD over contact point x pseudo-time, a scanned body): mu = (load point index,
      pseudo-time); its load points are discrete (``probe``);
    - a non-linear model over load positions and pseudo-time (the SVK crossed beams: u(x, s_x, s_y, tau)):
      mu = (the load point's position on the axes ``s``, ``s_x``, ``s_y`` (LOAD_POSITION_AXES), pseudo-time);
    - a linear model without a pseudo-time axis: mu = the load point's position and the pseudo-time scales the
      precomputed load: load_scale = pseudo-time.

    ``pseudo_time``: the model has a pseudo-time axis (a non-linear law: contacts do not superpose).
    """

    def __init__(self, model: ModelDescription):
        if model.load_points is None or len(model.load_points) == 0:
            raise ValueError(f"model '{model.name}' has no load points: it cannot take contacts")
        names = [a.name for a in model.axes]
        self.pseudo_time = PSEUDO_TIME in names
        self.probe = self.pseudo_time and LOAD_POINT in names
        if not self.pseudo_time and model.material.get("law") != "linear_elastic":
            raise ValueError(f"model '{model.name}' has no {PSEUDO_TIME} axis and is not linear: cannot scale its load")
        self.layout = StateLayout(tuple(model.axes), load_scale=not self.pseudo_time)
        self._tau = names.index(PSEUDO_TIME) if self.pseudo_time else -1
        n_lp = len(model.load_points)
        if self.probe:
            self._mu = np.arange(n_lp, dtype=np.float64)[:, None]
            self._slots = [names.index(LOAD_POINT)]
        else:
            position = [n for n in names if n != PSEUDO_TIME]
            unknown = [n for n in position if n not in LOAD_POSITION_AXES]
            if unknown:
                raise ValueError(f"model '{model.name}': axes {unknown} are not load positions "
                                 f"({', '.join(LOAD_POSITION_AXES)}): a contact cannot set them")
            P = model.points[np.asarray(model.load_points, dtype=np.int64)]
            self._mu = np.stack([P[:, LOAD_POSITION_AXES[n]] for n in position], axis=1)
            self._slots = [names.index(n) for n in position]
        self._n = len(names)

    def __len__(self) -> int:
        return len(self._mu)

    def at(self, position: ArrayLike, pseudo_time: float) -> ModelState:
        """The state of a load at ``position`` (its values on the load-position axes, or a probe model's load point
        index) pushed to ``pseudo_time``."""
        if not self.pseudo_time:
            return ModelState(np.asarray(position, dtype=np.float64).ravel(), load_scale=pseudo_time)
        mu = np.empty(self._n)
        mu[self._slots] = np.asarray(position, dtype=np.float64).ravel()
        mu[self._tau] = pseudo_time
        return ModelState(mu)

    def state(self, load_point: int, pseudo_time: float) -> ModelState:
        return self.at(self._mu[load_point], pseudo_time)
