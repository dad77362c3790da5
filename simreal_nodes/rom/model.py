"""A reduced-order model of one object: mesh, surface, parameter axes and separated fields."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from simreal_nodes.rom.separated import Axis, SeparatedField


@dataclass
class ReducedModel:
    name: str
    points: np.ndarray  # (n_nodes, 3) reference coordinates in the object frame, metres
    cells: np.ndarray  # (n_cells, k) vertex indices
    cell_type: str  # tet4 | hex8 | tri3 | quad4
    axes: list[Axis]
    fields: dict[str, SeparatedField]
    surface: np.ndarray = field(default_factory=lambda: np.zeros((0, 3), np.int64))  # outward triangles
    description: str = ""
    material: dict = field(default_factory=dict)
    boundary_conditions: list = field(default_factory=list)
    loads: dict = field(default_factory=dict)
    load_points: np.ndarray | None = None  # node index per load point (discrete load axes, contact)
    load_directions: np.ndarray | None = None  # (n_lp, 3) unit force directions
    rigid_parameters: list = field(default_factory=list)  # e.g. [{"name": "alpha_z", "axis": "z", ...}]
    provenance: dict = field(default_factory=dict)
    model_id: str = ""  # name@content-hash once saved / loaded
    path: str = ""

    @property
    def n_nodes(self) -> int:
        return self.points.shape[0]

    def axis(self, name: str) -> Axis:
        for a in self.axes:
            if a.name == name:
                return a
        raise KeyError(f"model '{self.name}' has no parameter '{name}' (it has: {', '.join(a.name for a in self.axes)})")

    def axis_index(self, name: str) -> int:
        return [a.name for a in self.axes].index(self.axis(name).name)

    def field(self, name: str) -> SeparatedField:
        try:
            return self.fields[name]
        except KeyError:
            raise KeyError(f"model '{self.name}' has no field '{name}' (loaded: {', '.join(self.fields) or 'none'})") from None

    def displacement(self, mu, nodes=None, n_modes=None) -> np.ndarray:
        return self.field("displacement").evaluate(mu, nodes, n_modes)

    def deformed_points(self, mu, nodes=None, n_modes=None, magnify: float = 1.0) -> np.ndarray:
        P = self.points if nodes is None else self.points[nodes]
        return P + magnify * self.displacement(mu, nodes, n_modes)

    def summary(self) -> str:
        lines = [f"model '{self.name}' {self.model_id}: {self.n_nodes} nodes, {len(self.cells)} {self.cell_type} cells, "
                 f"{len(self.surface)} surface triangles"]
        for a in self.axes:
            lines.append(f"  parameter {a.name} [{a.unit}] {a.kind}: {a.range[0]:g} .. {a.range[1]:g} ({len(a.values)} grid values)")
        for f in self.fields.values():
            err = "" if f.error_vs_modes is None or not len(f.error_vs_modes) else \
                f", error {f.error_vs_modes[0]:.2e} (1 mode) .. {f.error_vs_modes[-1]:.2e} ({f.n_modes} modes)"
            lines.append(f"  field {f.name} [{f.unit}] {f.n_comp} components, {f.n_modes} modes{err}")
        for r in self.rigid_parameters:
            lines.append(f"  rigid parameter {r['name']} [{r.get('unit', '')}]: {r.get('description', '')}")
        return "\n".join(lines)
