"""Registration in a worker process, for live use: the tracker keeps taking frames while an object is placed.

:func:`~simreal_nodes.assimilation.registration.register_rgbd` (and ``register_loaded``) runs Open3D's RANSAC plane
and ICP on the fused depth views: seconds on two busy cores, with the GIL held all the while (Open3D does not release
it), so in a thread it would stall the node just the same. Here the same function runs in a spawned process (started
with the tracker, so its imports are done before the views are); the node submits the views and polls for the
result each frame. The computation is the one the synchronous call does, on the same inputs, so the registration is
the same; only the frame it arrives at differs. Lossless replay and the offline pipeline register synchronously
(every frame in order: repeatable).

The inputs and the result cross the process boundary as pickles over a pipe between this process and the child it
spawned (as :class:`~simreal_nodes.vision.slam.optimize.AsyncBundleAdjuster` does); nothing is read from a file.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable
from multiprocessing.connection import Connection
from multiprocessing.process import BaseProcess
from typing import Any

Result = tuple[str, Any]  # ("ok", Registration) | ("refused", why) | ("failed", why)


def _serve(conn: Connection) -> None:
    """The worker's loop: (object id, kind, args) in, (object id, status, value) out; None ends it."""
    from simreal_nodes.assimilation.registration import RegistrationError, register_loaded, register_rgbd

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
        except RegistrationError as e:
            conn.send((oid, "refused", e.args[0]))
        except Exception as e:  # noqa: BLE001 - any failure is the registration's, reported, not the worker's end
            conn.send((oid, "failed", f"{type(e).__name__}: {e}"))


class BackgroundRegistration:
    """One worker process that registers objects one after the other; :meth:`submit` a job, :meth:`poll` for its
    result. A worker that died (killed, out of memory) is reported as a failed registration and started again at the
    next submit."""

    def __init__(self) -> None:
        self._proc: BaseProcess | None = None
        self._conn: Connection | None = None
        self._pending: set[str] = set()
        self._done: dict[str, Result] = {}
        self.start()

    def start(self) -> None:
        import multiprocessing as mp

        if self._proc is not None and self._proc.is_alive():
            return
        ctx = mp.get_context("spawn")
        self._conn, child = ctx.Pipe()
        proc = ctx.Process(target=_serve, args=(child,), daemon=True, name="simreal-registration")
        proc.start()
        self._proc = proc
        child.close()

    def submit(self, oid: str, kind: str, *args: Any, **kwargs: Any) -> None:
        """Register object ``oid`` with ``register_rgbd`` (kind ``rgbd``) or ``register_loaded`` (``loaded``)."""
        if kind not in ("rgbd", "loaded"):
            raise ValueError(f"registration kind: expected 'rgbd' or 'loaded'; found {kind!r}")
        self.start()
        assert self._conn is not None  # start() made it
        self._conn.send((oid, kind, args, kwargs))
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

    def close(self) -> None:
        """End the worker (it is started again by a later submit)."""
        if self._conn is not None:
            with contextlib.suppress(BrokenPipeError, OSError):
                self._conn.send(None)
        if self._proc is not None:
            self._proc.join(timeout=2)
            if self._proc.is_alive():
                self._proc.terminate()
        self._proc = self._conn = None
        self._pending.clear()
