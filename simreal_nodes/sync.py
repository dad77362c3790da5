"""Exact-stamp synchronization of several streams (ROS-free): all derived messages carry the stamp of
the image they come from, so inputs of one frame are matched by equal stamps, not by time windows."""

from __future__ import annotations

from collections import OrderedDict

#: a message this much older than the newest released frame means the stamps restarted (a looping bag,
#: a reset clock), not a late message: the synchronizer starts afresh
TIME_JUMP_NS = 5_000_000_000


class StampSync:
    """Collect messages by stamp; a frame is complete when every required key has arrived.

    ``optional`` keys are attached when present; a frame whose required keys are complete but optional
    ones are missing is released after ``wait`` newer frames have completed (or at once if wait=0), or
    when :meth:`give_up` says an optional key will not come for it.

    Frames are released in stamp order and never twice: once a frame is out, frames older than it can no
    longer complete and are dropped, and a message for a stamp at or before the newest released one
    (an optional input that came after its frame was drawn without it) is ignored and counted in
    :attr:`late` — it does not open a new frame that would later be reported as dropped.
    The oldest incomplete frames beyond ``max_pending`` are dropped too. Dropped frames are reported by
    :meth:`pop_dropped` with the keys they missed.
    """

    def __init__(self, required: tuple[str, ...], optional: tuple[str, ...] = (), wait: int = 2, max_pending: int = 30):
        self.required, self.optional = tuple(required), tuple(optional)
        self.wait, self.max_pending = wait, max_pending
        self._frames: OrderedDict[int, dict] = OrderedDict()
        self._dropped: list[tuple[int, str]] = []
        self._released: int | None = None
        self.late = 0

    @property
    def floor(self) -> int | None:
        """Newest stamp that has left (released or dropped); messages at or before it are late."""
        return self._released

    def add(self, key: str, stamp_ns: int, msg) -> list[tuple[int, dict]]:
        """Add one message; returns the frames that became ready, oldest first."""
        if self._released is not None and stamp_ns <= self._released:
            if self._released - stamp_ns < TIME_JUMP_NS:
                self.late += 1
                return []
            self._drop_all("the stamps jumped back (source restarted)")
            self._released = None
        f = self._frames.get(stamp_ns)
        if f is None:
            f = self._frames[stamp_ns] = {}
            self._frames = OrderedDict(sorted(self._frames.items()))
        f[key] = msg
        return self._release()

    def give_up(self, key: str, stamp_ns: int) -> list[tuple[int, dict]]:
        """An optional ``key`` will not come for this stamp (its producer dropped the frame): a frame
        waiting only for it is released without it. Returns the frames that became ready."""
        if key not in self.optional:
            raise KeyError(f"'{key}' is not an optional key of this synchronizer")
        if self._released is not None and 0 <= self._released - stamp_ns < TIME_JUMP_NS:
            return []  # that frame has left already
        f = self._frames.get(stamp_ns)
        if f is None:  # the producer's word can come before the frame's other inputs
            f = self._frames[stamp_ns] = {}
            self._frames = OrderedDict(sorted(self._frames.items()))
        f.setdefault("_gave_up", set()).add(key)
        return self._release()

    def _complete(self, fr: dict) -> bool:
        return all(k in fr for k in self.required)

    def _release(self) -> list[tuple[int, dict]]:
        complete = [s for s, fr in self._frames.items() if self._complete(fr)]
        newest = None
        for i, s in enumerate(complete):
            fr = self._frames[s]
            gave_up = fr.get("_gave_up", ())
            if all(k in fr or k in gave_up for k in self.optional) or len(complete) - 1 - i >= self.wait:
                newest = s
        ready = []
        if newest is not None:
            # everything up to the newest ready frame leaves now, in order: frames with their required
            # inputs go out (their optional ones will not come before a newer frame is out), the rest
            # can never complete in order and are dropped
            for s in [s for s in self._frames if s <= newest]:
                fr = self._frames.pop(s)
                if self._complete(fr):
                    fr.pop("_gave_up", None)
                    ready.append((s, fr))
                else:
                    self._report(s, fr, "incomplete frame")
            self._released = newest if self._released is None else max(self._released, newest)
        while len(self._frames) > self.max_pending:
            s, fr = self._frames.popitem(last=False)
            self._report(s, fr, "incomplete frame")
            self._released = s if self._released is None else max(self._released, s)
        return ready

    def _report(self, s: int, fr: dict, why: str) -> None:
        missing = [k for k in self.required if k not in fr]
        if missing:
            self._dropped.append((s, f"{why} (missing {', '.join(missing)})"))
        else:  # complete, still waiting for optional inputs when over max_pending newer frames came
            waiting = [k for k in self.optional if k not in fr and k not in fr.get("_gave_up", ())]
            self._dropped.append((s, f"frame held for {', '.join(waiting) or 'newer frames'} and over "
                                     f"{self.max_pending} frames pending"))

    def _drop_all(self, why: str) -> None:
        for s in list(self._frames):
            self._dropped.append((s, why))
        self._frames.clear()

    def pop_dropped(self) -> list[tuple[int, str]]:
        d, self._dropped = self._dropped, []
        return d


def live_skip_reason(why: str) -> str:
    """A dropped frame's reason as a live node reports it. Live, an input that never completes its frame was most
    often replaced in the subscription's keep-last queue while the node was busy (load shedding, as meant), not
    lost; the reason says both, so that a skipped frame does not read like a fault."""
    if why.startswith("incomplete frame (missing "):
        return why[:-1] + ": replaced in the live queue while the node was busy, or never received)"
    return why
