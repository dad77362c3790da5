"""Rate, latency and drop counters (ROS-free; the nodes publish them on /diagnostics)."""

from __future__ import annotations

import time
from collections import deque

import numpy as np


class WindowStats:
    """Rolling window of samples with percentiles."""

    def __init__(self, size: int = 300):
        self._buf: deque[float] = deque(maxlen=size)

    def add(self, x: float) -> None:
        if np.isfinite(x):
            self._buf.append(float(x))

    def __len__(self) -> int:
        return len(self._buf)

    def percentile(self, q: float) -> float:
        return float(np.percentile(self._buf, q)) if self._buf else float("nan")

    def mean(self) -> float:
        return float(np.mean(self._buf)) if self._buf else float("nan")

    def values(self) -> np.ndarray:
        return np.asarray(self._buf)


# an input older than this (or stamped more than a second ahead) is not on this clock: a replayed recording keeps
# its stamps from the day it was recorded, and "now minus stamp" is then the recording's age, not a latency
AGE_LIMIT_MS = (-1e3, 6e4)


STAGES = ("decode", "work", "encode")  # a frame's processing in a node: message to arrays, the core, arrays out


class StageMetrics:
    """Per-node statistics: input rate, processing latency, end-to-end age, drops, errors; the processing split
    into :data:`STAGES` where the node marks them (:meth:`lap`): ``decode`` (messages to arrays), ``work`` (the
    ROS-free core), ``encode`` (arrays to messages, published).

    ``age_ms``: now minus the input's stamp, kept only while the stamps are on this clock (``AGE_LIMIT_MS``); a
    replayed recording's frames are counted in ``off_clock`` instead and the age reads "n/a"."""

    def __init__(self, window: int = 300, clock=time.monotonic):
        self.clock = clock
        self._window = window
        self._arrivals: deque[float] = deque(maxlen=window)
        self.processing_ms = WindowStats(window)
        self.age_ms = WindowStats(window)
        self.off_clock = 0
        self.processed = 0
        self._last_done = clock()
        self.dropped = 0
        self.skipped = 0
        self.errors = 0
        self.last_error = ""
        self.last_drop_reason = ""
        self.last_skip_reason = ""
        self.extra: dict[str, str] = {}
        self.stages: dict[str, WindowStats] = {}
        self._lap_t = clock()

    def arrived(self) -> float:
        t = self.clock()
        self._arrivals.append(t)
        self._lap_t = t
        return t

    def lap(self, stage: str) -> None:
        """The frame's time since its arrival or the previous lap is ``stage``'s (one of :data:`STAGES`)."""
        t = self.clock()
        self.stages.setdefault(stage, WindowStats(self._window)).add((t - self._lap_t) * 1e3)
        self._lap_t = t

    def done(self, t_start: float, age_ms: float | None = None) -> float:
        ms = (self.clock() - t_start) * 1e3
        self.processing_ms.add(ms)
        if age_ms is not None:
            if AGE_LIMIT_MS[0] <= age_ms <= AGE_LIMIT_MS[1]:
                self.age_ms.add(age_ms)
            else:
                self.off_clock += 1
        self.processed += 1
        self._last_done = self.clock()
        return ms

    def seconds_since_done(self) -> float:
        """Seconds since the last finished frame (since the start if none was)."""
        return self.clock() - self._last_done

    def drop(self, reason: str) -> None:
        self.dropped += 1
        self.last_drop_reason = reason

    def skip(self, reason: str) -> None:
        """A frame left out on purpose (live load shedding), not a fault."""
        self.skipped += 1
        self.last_skip_reason = reason

    def error(self, what: str) -> None:
        self.errors += 1
        self.last_error = what

    def rate_hz(self) -> float:
        a = self._arrivals
        if len(a) < 2:
            return 0.0
        span = a[-1] - a[0]
        if self.clock() - a[-1] > max(2.0, 5 * span / max(len(a) - 1, 1)):
            return 0.0  # input stopped
        return (len(a) - 1) / span if span > 0 else 0.0

    def as_dict(self) -> dict[str, str]:
        d = {
            "rate_hz": f"{self.rate_hz():.2f}",
            "processing_ms_p50": f"{self.processing_ms.percentile(50):.2f}",
            "processing_ms_p95": f"{self.processing_ms.percentile(95):.2f}",
            "age_ms_p50": (f"{self.age_ms.percentile(50):.2f}" if len(self.age_ms)
                           else "n/a (input stamps not on this clock: a replayed recording?)" if self.off_clock
                           else "nan"),
            **{f"{k}_ms_p50": f"{self.stages[k].percentile(50):.2f}" for k in STAGES if k in self.stages},
            "processed": str(self.processed),
            "dropped": str(self.dropped),
            "skipped": str(self.skipped),
            "errors": str(self.errors),
        }
        if self.last_skip_reason:
            d["last_skip_reason"] = self.last_skip_reason
        if self.last_drop_reason:
            d["last_drop_reason"] = self.last_drop_reason
        if self.last_error:
            d["last_error"] = self.last_error
        d.update(self.extra)
        return d
