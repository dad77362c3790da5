"""The full-order truths kept on disk (`synth.scenes._cached_truth`): solved once and loaded after, one solve when
several processes (here threads, each with its own lock handle) ask for a missing truth at once, a damaged file
solved again, an older truth of the same set-up removed."""

import threading
import time
from types import SimpleNamespace

import numpy as np

from simreal_nodes.synth.scenes import _cached_truth


def _truth(calls: list, delay: float = 0.0):
    def solve():
        calls.append(threading.get_ident())
        time.sleep(delay)
        return SimpleNamespace(U=np.arange(6.0).reshape(2, 3), info={"n": 2})

    def make(arrays, info):
        return SimpleNamespace(U=arrays["U"], info=info)

    return solve, make


def test_a_truth_is_solved_once_and_loaded_after(tmp_path, monkeypatch):
    monkeypatch.setenv("SIMREAL_CACHE", str(tmp_path / "cache"))
    calls: list = []
    solve, make = _truth(calls)
    a = _cached_truth("probe", ["set-up", 1], ("U",), solve, make, lambda o: o.U.shape == (2, 3))
    b = _cached_truth("probe", ["set-up", 1], ("U",), solve, make, lambda o: o.U.shape == (2, 3))
    assert len(calls) == 1 and np.array_equal(a.U, b.U) and b.info == {"n": 2}
    files = sorted(p.name for p in (tmp_path / "cache" / "truth").glob("probe-*.npz"))
    assert len(files) == 1 and not any(".tmp" in p.name for p in (tmp_path / "cache" / "truth").iterdir())
    # a damaged file is solved again; another key (newer code or model) replaces the older file
    f = tmp_path / "cache" / "truth" / files[0]
    f.write_bytes(b"not a zip")
    _cached_truth("probe", ["set-up", 1], ("U",), solve, make, lambda o: True)
    assert len(calls) == 2
    _cached_truth("probe", ["set-up", 2], ("U",), solve, make, lambda o: True)
    assert len(calls) == 3 and len(list((tmp_path / "cache" / "truth").glob("probe-*.npz"))) == 1


def test_parallel_askers_of_a_missing_truth_share_one_solve(tmp_path, monkeypatch):
    monkeypatch.setenv("SIMREAL_CACHE", str(tmp_path / "cache"))
    calls: list = []
    solve, make = _truth(calls, delay=0.5)
    got: list = []
    errors: list = []

    def ask():
        try:
            got.append(_cached_truth("probe", ["shared"], ("U",), solve, make, lambda o: True))
        except Exception as e:  # noqa: BLE001 - collected for the assertion below
            errors.append(e)

    threads = [threading.Thread(target=ask) for _ in range(3)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert errors == [] and len(got) == 3
    assert len(calls) == 1  # the others waited for the first one's file and loaded it
    assert all(np.array_equal(g.U, got[0].U) for g in got)
