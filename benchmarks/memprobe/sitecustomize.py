"""Memory probe for `benchmarks/fuzz_graph.py --memory-detail`: imported at start-up by every Python process whose
PYTHONPATH holds this folder and whose environment names an output folder in ``SIMREAL_MEMPROBE``; a no-op
otherwise.

It starts :mod:`tracemalloc` (every allocation Python makes, numpy's buffers included) and, on SIGUSR1, appends one
JSON line to ``$SIMREAL_MEMPROBE/<pid>.jsonl``: the resident size, what Python has allocated and not freed, and
glibc's own account (``mallinfo2``: bytes in use, in its arenas and in blocks mapped of their own, bytes free inside
its arenas, and the mapped blocks alone). Malloc's bytes in use less Python's are at least what native code holds (the
DDS, rclpy's C layer, OpenCV; Python's small objects live in its own arenas, outside malloc's count); malloc's free
bytes are the allocator's slack. A first line, written at start-up, says the handler is in place (the benchmark
signals only such processes: SIGUSR1's default action ends a process)."""

import os

_OUT = os.environ.get("SIMREAL_MEMPROBE")
if _OUT:
    import ctypes
    import json
    import signal
    import time
    import tracemalloc

    class _MallInfo2(ctypes.Structure):
        _fields_ = [(n, ctypes.c_size_t) for n in ("arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks",
                                                   "fsmblks", "uordblks", "fordblks", "keepcost")]

    def _line(event: str) -> None:
        mb = 2.0 ** 20
        rec: dict = {"event": event, "t": time.monotonic(), "python_mb": tracemalloc.get_traced_memory()[0] / mb}
        try:
            with open(f"/proc/{os.getpid()}/statm") as f:
                rec["rss_mb"] = int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / mb
            libc = ctypes.CDLL("libc.so.6")
            libc.mallinfo2.restype = _MallInfo2
            mi = libc.mallinfo2()
            rec.update(malloc_in_use_mb=(mi.uordblks + mi.hblkhd) / mb, malloc_free_mb=mi.fordblks / mb,
                       malloc_mmap_mb=mi.hblkhd / mb)
        except (OSError, AttributeError, ValueError):  # not Linux / not glibc: Python's figure alone
            pass
        with open(os.path.join(_OUT, f"{os.getpid()}.jsonl"), "a") as f:
            f.write(json.dumps(rec) + "\n")

    tracemalloc.start(1)
    signal.signal(signal.SIGUSR1, lambda sig, frame: _line("probe"))
    try:
        _line("ready")
    except OSError:  # the folder is gone: no probe
        signal.signal(signal.SIGUSR1, signal.SIG_DFL)
