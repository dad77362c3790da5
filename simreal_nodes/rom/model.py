"""A reduced-order model of one object: mesh, surface, parameter axes and separated fields, and the one
evaluation of a model state's deformation (:meth:`ReducedModel.deformation`, :class:`DeformationView`)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from simreal_nodes.rom.separated import Axis, FieldView, SeparatedField
from simreal_nodes.rom.state import ModelState

Vector = NDArray[np.float64]
Nodes = NDArray[np.integer[Any]] | Sequence[int] | None  # model node indices (None: all)


@dataclass
class ReducedModel:
    name: str
    points: NDArray[Any]  # (n_nodes, 3) reference coordinates in the object frame, metres
    cells: NDArray[Any]  # (n_cells, k) vertex indices
    cell_type: str  # tet4 | hex8 | tri3 | quad4
    axes: list[Axis]
    fields: dict[str, SeparatedField]
    surface: NDArray[Any] = field(default_factory=lambda: np.zeros((0, 3), np.int64))  # outward triangles
    description: str = ""
    material: dict[str, Any] = field(default_factory=dict)
    boundary_conditions: list[Any] = field(default_factory=list)
    loads: dict[str, Any] = field(default_factory=dict)
    load_points: NDArray[Any] | None = None  # node index per load point (discrete load axes, contact)
    load_directions: NDArray[Any] | None = None  # (n_lp, 3) unit force directions
    rigid_parameters: list[dict[str, Any]] = field(default_factory=list)  # e.g. [{"name": "alpha_z", "axis": "z", ...}]
    provenance: dict[str, Any] = field(default_factory=dict)
    model_id: str = ""  # name@content-hash once saved / loaded
    path: str = ""
    # the full-order tensors a snapshot builder reduced, by field name (only when rom.build.KEEP_SNAPSHOTS: the
    # benchmarks compare NI-PGD with HOSVD on them); never saved to the model file
    snapshots: dict[str, NDArray[np.float64]] | None = field(default=None, repr=False, compare=False)

    @property
    def n_nodes(self) -> int:
        return int(self.points.shape[0])

    def axis(self, name: str) -> Axis:
        for a in self.axes:
            if a.name == name:
                return a
        raise KeyError(f"model '{self.name}' has no parameter '{name}' "
                       f"(it has: {', '.join(a.name for a in self.axes)})")

    def axis_index(self, name: str) -> int:
        return [a.name for a in self.axes].index(self.axis(name).name)

    def field(self, name: str) -> SeparatedField:
        try:
            return self.fields[name]
        except KeyError:
            raise KeyError(f"model '{self.name}' has no field '{name}' "
                           f"(loaded: {', '.join(self.fields) or 'none'})") from None

    def displacement(self, mu: ArrayLike, nodes: Nodes = None, n_modes: int | None = None) -> Vector:
        """u(x, mu) of the displacement field alone (no rigid extras): (n_nodes or len(nodes), 3)."""
        return self.field("displacement").evaluate(mu, nodes, n_modes)

    def deformed_points(self, mu: ArrayLike, nodes: Nodes = None, n_modes: int | None = None,
                        magnify: float = 1.0) -> Vector:
        P = self.points if nodes is None else self.points[nodes]
        return P + magnify * self.displacement(mu, nodes, n_modes)

    def deformation(self, state: ModelState, nodes: Nodes = None, n_modes: int | None = None) -> Vector:
        """The displacement a model state gives, object frame: load_scale * R_z(alpha_z) u(x, mu)."""
        return state.rigid(self.displacement(state.mu, nodes, n_modes))

    def deformation_view(self, nodes: Nodes = None, n_modes: int | None = None,
                         weights: ArrayLike | None = None) -> DeformationView:
        """:meth:`deformation` at fixed points laid out for hot loops: ``nodes`` (None: all), or N points each
        interpolated from k nodes with ``weights`` (N, k) (the tracker's links)."""
        return DeformationView(self.field("displacement").view(nodes, n_modes, weights))

    def summary(self) -> str:
        lines = [f"model '{self.name}' {self.model_id}: {self.n_nodes} nodes, {len(self.cells)} {self.cell_type} "
                 f"cells, {len(self.surface)} surface triangles"]
        for a in self.axes:
            lines.append(f"  parameter {a.name} [{a.unit}] {a.kind}: {a.range[0]:g} .. {a.range[1]:g} "
                         f"({len(a.values)} grid values)")
        for f in self.fields.values():
            err = "" if f.error_vs_modes is None or not len(f.error_vs_modes) else \
                f", error {f.error_vs_modes[0]:.2e} (1 mode) .. {f.error_vs_modes[-1]:.2e} ({f.n_modes} modes)"
            lines.append(f"  field {f.name} [{f.unit}] {f.n_comp} components, {f.n_modes} modes{err}")
        for r in self.rigid_parameters:
            lines.append(f"  rigid parameter {r['name']} [{r.get('unit', '')}]: {r.get('description', '')}")
        return "\n".join(lines)


class DeformationView:
    """A model's deformation at fixed points, one small matrix product per evaluation (the field's
    :class:`FieldView`): what the tracker (with Jacobians), the overlay (with a live mode count) and the
    contact (at the load points) evaluate every frame."""

    def __init__(self, field_view: FieldView):
        self.field = field_view

    @property
    def n_modes(self) -> int:
        return self.field.n_modes

    @property
    def modes(self) -> Vector:
        """The space modes at the view's points, (n_modes, N, 3)."""
        return self.field.modes

    def coefficients(self, mu: Vector) -> Vector:
        """c_i(mu) of all the view's modes: with :attr:`modes`, what a truncation-error estimate needs."""
        c: Vector = self.field.field.coefficients(mu, self.n_modes)
        return c

    def __call__(self, state: ModelState, n_modes: int | None = None) -> Vector:
        """load_scale * R_z(alpha_z) u(x, mu) at the view's points, with its modes or the first ``n_modes``."""
        return state.rigid(self.field.evaluate(state.mu, n_modes))

    def with_jacobian(self, mu: Vector) -> tuple[Vector, Vector]:
        """(u (N, 3), du/dmu (N, 3, n_mu)) of the field alone: the LM folds the rigid extras into its camera
        projection. ``mu`` must be inside the model's range (the LM keeps it there: no check per call)."""
        return self.field.evaluate_with_jacobian(mu, checked=True)
