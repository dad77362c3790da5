"""One frame of collision for all the colliding objects of a scene (thesis Alg. 5.1, §5.4.1).

Real points come from the depth image, decimated per object and back-projected into the map frame; an object
listed in another object's ``collision.pushes`` also receives that object's deformed surface (virtual-virtual
contact: an exact surface, touching at a gap of zero along the push direction, not within the depth's delta), so the
pushing object is updated first. The collision node converts messages and
publishes; everything between the depth image and the contact states is here, testable without ROS.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from simreal_nodes import geometry as G
from simreal_nodes.camera import CameraModel
from simreal_nodes.collision.contact import ContactState, ContactTracker, PusherSurface, outward_triangles
from simreal_nodes.rom.model import ReducedModel
from simreal_nodes.vision.depth import depth_points


def pusher_order(objects: list[dict]) -> list[dict]:
    """Objects ordered so that an object that pushes another is updated before it (cycles keep file order)."""
    ids = [o["id"] for o in objects]
    pushed_by = {i: [o["id"] for o in objects if i in o["collision"]["pushes"]] for i in ids}
    out: list[str] = []
    seen: set[str] = set()

    def visit(i: str, stack: tuple[str, ...] = ()) -> None:
        if i in seen or i in stack:
            return
        for p in pushed_by[i]:
            visit(p, stack + (i,))
        seen.add(i)
        out.append(i)

    for i in ids:
        visit(i)
    by_id = {o["id"]: o for o in objects}
    return [by_id[i] for i in out]


@dataclass
class ObjectContact:
    """One object's contact state after a frame, and what it was measured against (``depth``, or
    ``depth+<pushers>`` when other objects' surfaces were added)."""

    object_id: str
    state: ContactState
    source: str


class ContactScene:
    """The :class:`ContactTracker` of every colliding object (``objects``: validated scene objects whose collision
    is enabled; ``models``: their reduced models by id), in pusher order.

    ``decimation``: overrides every object's depth decimation step (0 = each object's own)."""

    def __init__(self, objects: list[dict], models: dict[str, ReducedModel], decimation: int = 0):
        self.objects = pusher_order(objects)
        self.models = models
        self.decimation = decimation
        self.trackers: dict[str, ContactTracker] = {}
        self.outward = {oid: outward_triangles(m.points, m.surface) for oid, m in models.items()}
        self._stepped_back: dict[str, float] = {}  # a held contact's step back this frame: how far its node moved
        for o in self.objects:
            c = o["collision"]
            self.trackers[o["id"]] = ContactTracker(models[o["id"]], G.pose7_to_matrix(o["anchor"]["pose"]),
                                                    threshold=c["threshold_m"], step=c["step"],
                                                    anywhere=bool(c.get("anywhere", False)),
                                                    max_contacts=int(c.get("max_contacts", 1)),
                                                    separation=float(c.get("separation_m", 0.0)))

    def step(self, depth: np.ndarray, cam: CameraModel, T_wc: np.ndarray | None) -> list[ObjectContact]:
        """Advance every object by one frame: ``depth`` in metres (registered to ``cam``), ``T_wc`` the camera pose
        in the map frame (None: no pose this frame, only virtual pushers can touch)."""
        pts_by_step: dict[int, np.ndarray] = {}
        out = []
        for o in self.objects:
            c = o["collision"]
            step = int(self.decimation or c["decimation"])
            if T_wc is None:
                pts, why = None, "no camera pose this frame"
            else:
                if step not in pts_by_step:
                    pts_by_step[step] = depth_points(depth, cam, step, T_wc, max_depth=c["max_depth_m"]).points
                pts = pts_by_step[step]
                why = "" if len(pts) else "no valid depth"
            pushers = [p for p in self.objects if o["id"] in p["collision"]["pushes"]]
            surfaces = [(p["id"], self._surface_world(p["id"])) for p in pushers]
            pressing = [(i, s) for i, s in surfaces if s is not None]
            before = replace(self.trackers[o["id"]].state)
            st = self.trackers[o["id"]].update(pts, [s for _, s in pressing])
            self._stepped_back[o["id"]] = (self.trackers[o["id"]].node_motion(before, st)
                                           if st.in_contact and st.pseudo_time < before.pseudo_time else 0.0)
            if why and not st.reason:
                st.reason = why
            source = "depth" if not pressing else "depth+" + ",".join(i for i, _ in pressing)
            out.append(ObjectContact(o["id"], st, source))
        return out

    def _surface_world(self, oid: str) -> PusherSurface | None:
        """The pushing object's deformed surface in the map frame (virtual-virtual contact, §5.4.1); None while it
        is undeformed (its rest shape does not overlap the objects it may push)."""
        tr = self.trackers[oid]
        if tr.state.pseudo_time <= 0:
            return None
        m = self.models[oid]
        return PusherSurface(G.transform(tr.T, m.points + tr.displacement()), self.outward[oid],
                             self._stepped_back.get(oid, 0.0))
