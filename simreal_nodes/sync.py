"""Exact-stamp synchronization of several streams (ROS-free): all derived messages carry the stamp of
the image they come from, so inputs of one frame are matched by equal stamps, not by time windows."""

from __future__ import annotations

from collections import OrderedDict


class StampSync:
    """Collect messages by stamp; a frame is complete when every required key has arrived.

    ``optional`` keys are attached when present; a frame whose required keys are complete but optional
    ones are missing is released after ``wait`` newer frames have completed (or at once if wait=0).
    Incomplete frames older than ``max_pending`` stamps are dropped (reported by :meth:`pop_dropped`).
    """

    def __init__(self, required: tuple[str, ...], optional: tuple[str, ...] = (), wait: int = 2, max_pending: int = 30):
        self.required, self.optional = tuple(required), tuple(optional)
        self.wait, self.max_pending = wait, max_pending
        self._frames: OrderedDict[int, dict] = OrderedDict()
        self._dropped: list[tuple[int, str]] = []

    def add(self, key: str, stamp_ns: int, msg) -> list[tuple[int, dict]]:
        """Add one message; returns the frames that became ready, oldest first."""
        f = self._frames.get(stamp_ns)
        if f is None:
            f = self._frames[stamp_ns] = {}
            self._frames = OrderedDict(sorted(self._frames.items()))
        f[key] = msg
        ready = []
        stamps = list(self._frames)
        for i, s in enumerate(stamps):
            fr = self._frames[s]
            if not all(k in fr for k in self.required):
                continue
            newer_complete = sum(1 for t in stamps[i + 1:] if all(k in self._frames[t] for k in self.required))
            if all(k in fr for k in self.optional) or newer_complete >= self.wait:
                ready.append((s, self._frames.pop(s)))
        while len(self._frames) > self.max_pending:
            s, fr = self._frames.popitem(last=False)
            missing = [k for k in self.required if k not in fr]
            self._dropped.append((s, f"incomplete frame (missing {', '.join(missing)})"))
        # frames older than a released one can never complete in order: drop them
        if ready:
            newest = ready[-1][0]
            for s in [s for s in self._frames if s < newest]:
                fr = self._frames.pop(s)
                missing = [k for k in self.required if k not in fr]
                if missing:
                    self._dropped.append((s, f"incomplete frame (missing {', '.join(missing)})"))
        return ready

    def pop_dropped(self) -> list[tuple[int, str]]:
        d, self._dropped = self._dropped, []
        return d
