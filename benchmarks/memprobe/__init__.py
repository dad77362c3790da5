"""The memory probe's other side: the environment that puts it in a child process and the readings it writes
(the probe itself is this folder's ``sitecustomize.py``, which a child imports at start-up)."""

from __future__ import annotations

import json
import os
import signal
from pathlib import Path

HERE = Path(__file__).resolve().parent


def probe_env(env: dict, out_dir: Path) -> dict:
    """``env`` with the probe on: this folder first on PYTHONPATH and the readings going to ``out_dir``."""
    path = os.pathsep.join(x for x in (str(HERE), env.get("PYTHONPATH", "")) if x)
    return env | {"SIMREAL_MEMPROBE": str(out_dir), "PYTHONPATH": path}


def ready(pid: int, out_dir: Path) -> bool:
    """Whether process ``pid``'s probe said it is in place (only then may it be sent SIGUSR1, which otherwise ends
    it)."""
    return (out_dir / f"{pid}.jsonl").is_file()


def ask(pid: int) -> None:
    """Ask process ``pid`` for a reading (its probe writes it when its main thread next runs Python)."""
    os.kill(pid, signal.SIGUSR1)


def latest(pid: int, out_dir: Path) -> dict:
    """Process ``pid``'s newest line ({} where there is none)."""
    lines = (out_dir / f"{pid}.jsonl").read_text().splitlines()
    out: dict = json.loads(lines[-1]) if lines else {}
    return out
