"""benchmarks/memprobe: the memory probe `benchmarks/fuzz_graph.py --memory-detail` puts in every node."""

import json
import os
import subprocess
import sys
from pathlib import Path

PROBE = Path(__file__).resolve().parents[1] / "benchmarks" / "memprobe"
CHILD = """
import os, signal, time
import numpy as np
a = np.ones(50 * 2 ** 20 // 8)  # 50 MB, from the C allocator, seen by tracemalloc
os.kill(os.getpid(), signal.SIGUSR1)
time.sleep(0.05)
"""


def _run(env_extra: dict) -> None:
    env = {k: v for k, v in os.environ.items() if k != "SIMREAL_MEMPROBE"}
    env["PYTHONPATH"] = os.pathsep.join([str(PROBE), *([env["PYTHONPATH"]] if env.get("PYTHONPATH") else [])])
    subprocess.run([sys.executable, "-c", CHILD], env=env | env_extra, check=True, timeout=60)


def test_the_probe_reports_python_and_the_allocator_on_sigusr1(tmp_path):
    _run({"SIMREAL_MEMPROBE": str(tmp_path)})
    files = list(tmp_path.glob("*.jsonl"))
    assert len(files) == 1
    ready, probe = (json.loads(x) for x in files[0].read_text().splitlines())
    assert ready["event"] == "ready" and probe["event"] == "probe"
    assert probe["python_mb"] - ready["python_mb"] >= 49  # the array, as Python allocated it
    assert probe["malloc_in_use_mb"] - ready["malloc_in_use_mb"] >= 49  # and as glibc holds it
    assert probe["rss_mb"] >= probe["python_mb"]


def test_without_the_variable_the_probe_does_nothing(tmp_path):
    """Not asked for: no tracemalloc and no handler, so SIGUSR1 keeps its default action (the process ends)."""
    env = {k: v for k, v in os.environ.items() if k != "SIMREAL_MEMPROBE"}
    env["PYTHONPATH"] = str(PROBE)
    r = subprocess.run([sys.executable, "-c", CHILD], env=env, timeout=60, cwd=tmp_path)
    assert r.returncode == -10  # killed by SIGUSR1
    assert not list(tmp_path.glob("*.jsonl"))
