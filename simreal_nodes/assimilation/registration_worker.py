"""Registration in a worker process, for live use: the tracker keeps taking frames while an object is placed.

:func:`~simreal_nodes.assimilation.registration.register_rgbd` (and ``register_loaded``) runs Open3D's RANSAC plane
and ICP on the fused depth views: seconds on two busy cores, with the GIL held all the while (Open3D does not release
it), so in a thread it would stall the node just the same. Here the same function runs in a spawned process (started
with the tracker, so its imports are done before the views are); the node submits the views and polls for the
result each frame. The computation is the one the synchronous call does, on the same inputs, so the registration is
the same; only the frame it arrives at differs. Lossless replay and the offline pipeline register synchronously
(every frame in order: repeatable).

The inputs and the result cross the process boundary as pickles over a pipe between this process and the child it
spawned (as :class:`~simreal_nodes.vision.slam.optimize.AsyncBundleAdjuster` does); nothing is read from a file. A
job (several MB: the fused cloud, the model) is handed to the pipe by a feeder thread, so a submit never waits for the
worker to read it (a worker busy with another object, or still importing after a restart). The worker ends when the
process that started it does, even by ``kill -9`` (Linux ``PR_SET_PDEATHSIG``), or at the end of its pipe.
"""

from __future__ import annotations

import contextlib
import os
import queue
import signal
import threading
from collections.abc import Callable
from multiprocessing.connection import Connection
from multiprocessing.process import BaseProcess
from typing import Any

from simreal_nodes.lifetime import end_with_parent

# ("ok", Registration) | ("refused", why) | ("slide", why: refused for its slide along the object's axis alone,
# :class:`~simreal_nodes.assimilation.registration.SlideRefused`) | ("failed", why)
Result = tuple[str, Any]


def _serve(conn: Connection, parent: int) -> None:
    """The worker's loop: (object id, kind, args, kwargs) in, (object id, status, value) out; None ends it."""
    if not end_with_parent(parent, signal.SIGKILL):  # the node died before the request: no signal will come
        os._exit(0)
    from simreal_nodes.assimilation.registration import (
        RegistrationError,
        SlideRefused,
        register_loaded,
        register_rgbd,
    )

    run: dict[str, Callable[..., Any]] = {"rgbd": register_rgbd, "loaded": register_loaded}
    while True:
        try:
            job = conn.recv()
        except (EOFError, OSError):
            return
        if job is None:
            return
        oid, kind, args, kwargs = job
        try:
            conn.send((oid, "ok", run[kind](*args, **kwargs)))
        except SlideRefused as e:
            conn.send((oid, "slide", e.args[0]))
        except RegistrationError as e:
            conn.send((oid, "refused", e.args[0]))
        except Exception as e:  # noqa: BLE001 - any failure is the registration's, reported, not the worker's end
            conn.send((oid, "failed", f"{type(e).__name__}: {e}"))


class BackgroundRegistration:
    """One worker process that registers objects one after the other; :meth:`submit` a job, :meth:`poll` for its
    result. A worker that died (killed, out of memory) is reported as a failed registration and started again at
    once, ready for the next submit. Nothing here waits on the worker but :meth:`close` with ``wait``."""

    def __init__(self) -> None:
        self._proc: BaseProcess | None = None
        self._conn: Connection | None = None
        self._jobs: queue.SimpleQueue[Any] | None = None
        self._pending: set[str] = set()
        self._done: dict[str, Result] = {}
        self.start()

    def start(self) -> None:
        """Start the worker (its imports take a few seconds, in its own process) and its feeder thread."""
        import multiprocessing as mp

        if self._proc is not None and self._proc.is_alive():
            return
        self._drop_pipe()
        ctx = mp.get_context("spawn")
        conn, child = ctx.Pipe()
        proc = ctx.Process(target=_serve, args=(child, os.getpid()), daemon=True, name="simreal-registration")
        proc.start()
        child.close()
        jobs: queue.SimpleQueue[Any] = queue.SimpleQueue()
        threading.Thread(target=_feed, args=(jobs, conn), daemon=True, name="simreal-registration-feeder").start()
        self._proc, self._conn, self._jobs = proc, conn, jobs

    def submit(self, oid: str, kind: str, *args: Any, **kwargs: Any) -> None:
        """Register object ``oid`` with ``register_rgbd`` (kind ``rgbd``) or ``register_loaded`` (``loaded``); returns
        at once (the feeder thread pickles the job and writes it to the worker)."""
        if kind not in ("rgbd", "loaded"):
            raise ValueError(f"registration kind: expected 'rgbd' or 'loaded'; found {kind!r}")
        self.start()
        assert self._jobs is not None  # start() made it
        self._jobs.put((oid, kind, args, kwargs))
        self._pending.add(oid)

    def pending(self, oid: str) -> bool:
        return oid in self._pending

    def poll(self, oid: str) -> Result | None:
        """The result for ``oid`` once it has come (and then forgotten), else None."""
        self._collect()
        return self._done.pop(oid, None)

    def _collect(self) -> None:
        if not self._pending or self._conn is None:
            return
        try:
            while self._conn.poll():
                got, status, value = self._conn.recv()
                self._pending.discard(got)
                self._done[got] = (status, value)
        except (EOFError, OSError):
            pass
        if self._pending and (self._proc is None or not self._proc.is_alive()):
            code = self._proc.exitcode if self._proc is not None else None
            for oid in self._pending:
                self._done[oid] = ("failed", f"the registration worker exited (code {code})")
            self._pending.clear()
            self._proc = None
            self.start()  # a new worker, importing while the views are collected again

    def _drop_pipe(self) -> None:
        """Let go of a dead worker's pipe. The feeder closes it, once its write has ended: closed from here while the
        feeder was still writing a large job, the descriptor could be reused by the next worker's pipe and the
        rest of the old job written into it (the new worker then read garbage)."""
        if self._jobs is not None:
            self._jobs.put(None)  # the feeder ends (after the job it may be writing) and closes the connection
        self._conn = self._jobs = None

    def close(self, wait: bool = True) -> None:
        """End the worker (a later submit starts another): told to end after its job, then, with ``wait``, waited
        for up to 2 s and terminated. Without ``wait`` (from a frame callback) nothing blocks: it ends on its own."""
        if self._jobs is not None:
            self._jobs.put(None)  # after any job still queued: the worker reads None and returns
        proc, self._proc = self._proc, None
        self._jobs = None  # the feeder owns the connection now: it closes it after writing the end
        self._conn = None
        self._pending.clear()
        if proc is not None and wait:
            proc.join(timeout=2)
            if proc.is_alive():
                proc.terminate()


def _feed(jobs: queue.SimpleQueue[Any], conn: Connection) -> None:
    """Write the queued jobs to the worker, in order; None (from close) is written on as the worker's end, then the
    thread closes the connection and ends."""
    try:
        while True:
            job = jobs.get()
            try:
                conn.send(job)
            except (OSError, ValueError):  # the worker is gone (its death is found by poll) or the pipe was closed
                return
            if job is None:
                return
    finally:
        with contextlib.suppress(OSError):
            conn.close()
