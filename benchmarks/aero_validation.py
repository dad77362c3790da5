"""The CFD behind the car database, checked before it is trusted (issue 19, item 2): drag of a sphere and a cube
against published values, and the car database's own mesh error.

    ./run bench aero_validation             # about 8 CPU-minutes

* **Sphere, Re = 100** (laminar, steady axisymmetric wake: a steady solver is the right model): Cd against 1.087
  (Johnson & Patel 1999, DNS) / 1.09 (Clift, Grace & Weber's standard drag curve), at three surface refinements.
* **Cube face-on, Re = 9000** (the database's Reynolds number; sharp edges fix the separation): Cd against 1.05
  (Hoerner, Fluid-Dynamic Drag, free-stream cube), with the database's model (steady k-omega SST) and laminar.
* **Sphere, Re = 9000**: Cd against about 0.40 (standard drag curve). A smooth body whose separation point moves with
  the boundary layer: steady models are not expected to get it; reported to say so.
* **The inflow's turbulence**: the same car with an inflow eddy viscosity ten times smaller than the database's.
* **Mesh error of the database**: one car (``large_00`` of ``aero_cars.yaml``) at the database's surface level 3 and
  one finer (4): Cd, and the relative L2 difference of the velocity on the thesis's grid (over |v| and over the
  disturbance |v - U_inf|). This is the CFD's own discretisation error, the floor under any comparison of fields.

Half domains with a symmetry plane at y = 0, as for the cars (the reference area is half the frontal area).
"""

from __future__ import annotations

import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from benchmarks.common import save
from simreal_nodes.aero.bodies import cube_surface, sphere_surface


def free_body(work: Path, name: str, body: tuple[np.ndarray, np.ndarray], re: float, level: int, turbulence: str,
              ref_area: float) -> dict:
    from simreal_nodes.aero.openfoam import CfdSettings, run_case, write_case

    s = CfdSettings(speed=1.0, nu=1.0 / re, domain_min=(-6.0, 0.0, -6.0), domain_max=(14.0, 6.0, 6.0),
                    background=0.5, box_level=1, near_level=2, surface_level=level, iterations=2000, residual=1e-5,
                    ground="slip", turbulence=turbulence, length=1.0)
    pts = np.array([[-5.0, 3.0, 0.0]])
    case = write_case(work / f"{name}_{level}_{int(re)}_{turbulence}", *body, pts, s,
                      (np.array([-1.5, 0.0, -1.5]), np.array([4.0, 1.5, 1.5])),
                      (np.array([-3.0, 0.0, -3.0]), np.array([8.0, 3.0, 3.0])), ref_area=ref_area, ref_length=1.0)
    r = run_case(case, pts, s)
    return {"case": name, "Re": re, "model": turbulence, "level": level, "cells": r.n_cells, "cd": r.cd,
            "iterations": r.iterations, "converged": r.converged, "seconds": r.seconds}


def main(argv: list[str] | None = None) -> None:
    from simreal_nodes.aero.cars import car_family
    from simreal_nodes.aero.database import load_aero_spec
    from simreal_nodes.aero.grid import THESIS_GRID
    from simreal_nodes.aero.openfoam import run_case, write_case

    rows = []
    with tempfile.TemporaryDirectory(prefix="aero_validation_") as tmp:
        work = Path(tmp)
        sph, cube = sphere_surface(), cube_surface()
        for level in (3, 4, 5):
            rows.append({**free_body(work, "sphere", sph, 100.0, level, "laminar", np.pi / 8), "reference": 1.087})
        for model in ("kOmegaSST", "laminar"):
            rows.append({**free_body(work, "cube", cube, 9000.0, 4, model, 0.5), "reference": 1.05})
        for model in ("kOmegaSST", "laminar"):
            rows.append({**free_body(work, "sphere", sph, 9000.0, 4, model, np.pi / 8), "reference": 0.40})
        for r in rows:
            r["error_pct"] = 100.0 * (r["cd"] / r["reference"] - 1.0)
            print(r, flush=True)

        # the database's mesh error, on its first car
        spec = load_aero_spec("aero_cars.yaml")
        car = car_family(spec.per_group, spec.seed)[0]
        pts = THESIS_GRID.points()
        fields = {}
        for level in (3, 4, "nut"):
            # level 3 is the database's; 4 one finer; "nut": the database's mesh with an inflow eddy viscosity ten
            # times smaller (turbulence length 1 % of the car's instead of 10 %: nu_t / nu about 0.6 against 6)
            s = (replace(spec.cfd, surface_level=level) if level != "nut"
                 else replace(spec.cfd, turbulence_length=0.1 * spec.cfd.turbulence_length))
            v, f = car.surface()
            near = (np.array([-1.0, 0.0, 0.0]), np.array([car.length + 3.0, 0.5 * car.width + 1.0, car.height + 1.0]))
            t0 = time.perf_counter()
            case = write_case(work / f"car_{level}", v, f, pts, s, near,
                              (np.asarray(THESIS_GRID.lo), np.asarray(THESIS_GRID.hi)),
                              ref_area=0.5 * car.frontal_area(), ref_length=car.length)
            fields[level] = run_case(case, pts, s)
            print(f"car {level}: Cd {fields[level].cd:.4f}, {time.perf_counter() - t0:.0f} s", flush=True)
    a, b, c = fields[3], fields[4], fields["nut"]
    m = a.in_fluid & b.in_fluid & (THESIS_GRID.presence(car) == 0)
    uinf = np.array([spec.cfd.speed, 0.0, 0.0])
    d = (a.velocity - b.velocity)[m]
    mesh_error = {"car": car.name, "cd_level3": a.cd, "cd_level4": b.cd, "cells_level3": a.n_cells,
                  "cells_level4": b.n_cells,
                  "velocity_rel_l2_pct": 100 * float(np.linalg.norm(d) / np.linalg.norm(b.velocity[m])),
                  "disturbance_rel_l2_pct": 100 * float(np.linalg.norm(d) / np.linalg.norm((b.velocity - uinf)[m]))}
    m2 = a.in_fluid & c.in_fluid & (THESIS_GRID.presence(car) == 0)
    d2 = (a.velocity - c.velocity)[m2]
    inflow = {"cd_nut_ratio_6": a.cd, "cd_nut_ratio_0_6": c.cd,
              "velocity_rel_l2_pct": 100 * float(np.linalg.norm(d2) / np.linalg.norm(c.velocity[m2])),
              "disturbance_rel_l2_pct": 100 * float(np.linalg.norm(d2) / np.linalg.norm((c.velocity - uinf)[m2]))}

    def plot(plt):
        fig, ax = plt.subplots(1, 2, figsize=(11, 3.8))
        sp = [r for r in rows if r["case"] == "sphere" and r["Re"] == 100.0]
        ax[0].plot([r["cells"] for r in sp], [r["cd"] for r in sp], "o-", label="simpleFoam, laminar")
        ax[0].axhline(1.087, color="k", ls="--", label="Johnson & Patel 1999 (DNS)")
        ax[0].set_xlabel("cells (half domain)")
        ax[0].set_ylabel("Cd")
        ax[0].set_title("sphere, Re = 100: surface levels 3, 4, 5")
        ax[0].legend()
        hi = [r for r in rows if r["Re"] == 9000.0]
        x = np.arange(len(hi))
        ax[1].bar(x - 0.2, [r["cd"] for r in hi], 0.4, label="OpenFOAM")
        ax[1].bar(x + 0.2, [r["reference"] for r in hi], 0.4, label="published")
        ax[1].set_xticks(x, [f"{r['case']}\n{r['model']}" for r in hi], fontsize=8)
        ax[1].set_title("Re = 9000")
        ax[1].legend()
        fig.tight_layout()
        return fig

    notes = (f"Mesh error of the car database ({mesh_error['car']}, surface level 3 as in the database against 4): "
             f"Cd {mesh_error['cd_level3']:.4f} against {mesh_error['cd_level4']:.4f}; velocity on the thesis's grid "
             f"{mesh_error['velocity_rel_l2_pct']:.2f} % of |v| ({mesh_error['disturbance_rel_l2_pct']:.1f} % of the "
             "disturbance |v - U_inf|). The inflow's eddy viscosity (the database: nu_t / nu about 6 at the inlet) "
             f"against ten times less on the same car: Cd {inflow['cd_nut_ratio_6']:.4f} against "
             f"{inflow['cd_nut_ratio_0_6']:.4f}, velocity {inflow['velocity_rel_l2_pct']:.2f} % of |v| "
             f"({inflow['disturbance_rel_l2_pct']:.1f} % of the disturbance). Reference values: sphere Re 100 1.087 "
             "(Johnson & Patel 1999); cube Re ~1e4 1.05 (Hoerner); sphere Re 9000 about 0.40 (standard drag "
             "curve). A laminar run that did not converge "
             "reports the drag of its last iteration.")
    cols = [("case", "body", "{}"), ("Re", "Re", "{:.0f}"), ("model", "model", "{}"), ("level", "surface level", "{}"),
            ("cells", "cells", "{}"), ("iterations", "iterations", "{}"), ("converged", "converged", "{}"),
            ("cd", "Cd", "{:.4f}"), ("reference", "published", "{:.3f}"), ("error_pct", "error (%)", "{:+.1f}"),
            ("seconds", "time (s)", "{:.0f}")]
    save("aero_validation", rows, cols, "OpenFOAM (simpleFoam) against published drag, and the car database's mesh "
         "error", notes=notes, plot=plot, extra={"mesh_error": mesh_error, "inflow_turbulence": inflow})


if __name__ == "__main__":
    main()
