"""A node killed mid-replay (issue 20): `kill -9` of one node while a live replay runs, the launcher's respawn,
and how long until that node's output is back -- and back to a trustworthy state.

    ./run bench respawn

Scene: the aluminium beam demo (ingest -> markers -> tracker -> overlay), rendered 12 s at 320 x 240 (JPEG q90)
by `simreal make-bag` into `cache/bags/`, replayed live (rate 1: frames are dropped while a node is down, as from a
camera). Per node killed (tracker, localization, overlay), three runs: SIGKILL 4 s into the replay; the launcher
restarts it (respawn, default 2 restarts). Measured from the recording (receive wall time of each output message):

- **gap**: the time from the kill to the node's first output from its new process (the issue's target: 1 s);
- **back to OK** (tracker): to its first estimate in state OK after the kill;
- **restart**: from the kill to the launcher's "started <node>" line of the new process.

The one-process launch (`--one-process`, all nodes in one process) is killed whole (row "nodes": every node
goes; the tracker's output is measured).

Each with the node's standby process (the default for live use: imports done and DDS participant up, promoted
when the node exits) and without (`--no-standby`: a cold restart). With a standby the kill waits until the
standby has said it is ready.

Each run is a child process of its own, run again if it fails, or if it has not finished after `RUN_TIMEOUT_S`
(it is then killed with its nodes; at most `TRIES` tries): a run that hangs (the harness's player and recorder once
deadlocked inside Fast DDS as a killed node's participant left, eProsima/Fast-DDS#6502) then costs that run, not
the table, and the table counts such tries.

The nodes use the project's Fast DDS profile (`ros/fastdds_shm.xml`) unless FASTRTPS_DEFAULT_PROFILES_FILE names
another: `FASTRTPS_DEFAULT_PROFILES_FILE=old.xml python -m benchmarks.respawn` compares profiles.
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import psutil

from benchmarks.common import save, saved_machine
from simreal_nodes.io import bags
from simreal_nodes.launch import ONE_PROCESS
from simreal_nodes.rom.build import REPO
from simreal_nodes.ros import bagplay
from simreal_nodes.ros.commands import replay

BAG_DIR = REPO / "cache" / "bags"
NAME = "aluminium_beam_320x240_12s"
KILL_AFTER_S = 4.0
VICTIMS = ("tracker", "localization", "overlay", ONE_PROCESS)
OUTPUTS = {"tracker": "/simreal/objects/beam/parameters", "localization": "/simreal/localization/pose",
           "overlay": "/simreal/overlay/image_raw", ONE_PROCESS: "/simreal/objects/beam/parameters"}
TRACKED = ("tracker", ONE_PROCESS)  # victims whose kill stops the tracker's estimates (back to OK is measured)
RUN_TIMEOUT_S = 150.0  # a run takes 20-40 s on 2 cores (start-up, 12 s of replay, shut-down)
TRIES = 3


def sample() -> tuple[Path, Path]:
    bag, scene = BAG_DIR / NAME, BAG_DIR / f"{NAME}.yaml"
    if not bag.is_dir():
        from simreal_nodes.synth.makebag import make_bag

        make_bag("aluminium_beam", bag, 320, 240, duration=12.0, image_format="jpeg", jpeg_quality=90,
                 scene_out=scene)
    return bag, scene


STARTED = re.compile(r"\[launch\] started (\w+) \(pid (\d+)\)")
STANDBY = re.compile(r"\[launch\] standby for (\w+) started \(pid (\d+)\)")


def run_once(bag: Path, scene: Path, victim: str, out: Path, standby: bool = True) -> dict:
    pids: dict[str, list[tuple[float, int]]] = {}
    lines: list[str] = []
    playing = threading.Event()
    standby_ready = threading.Event()
    killed: dict[str, float] = {}
    standbys: dict[str, int] = {}

    def echo(line: str) -> None:
        lines.append(line)
        m = STARTED.match(line)
        if m:
            pids.setdefault(m.group(1), []).append((time.time(), int(m.group(2))))
        if line.startswith(f"[{victim}] standby ready"):
            standby_ready.set()
        m = STANDBY.match(line)
        if m:
            standbys[m.group(1)] = int(m.group(2))

    def killer() -> None:
        if not playing.wait(120):
            return
        time.sleep(KILL_AFTER_S)
        if standby and not standby_ready.wait(30):
            return
        pid = pids[victim][-1][1]
        if standby:  # what a standby costs: its memory while it waits
            with contextlib.suppress(psutil.Error, KeyError):
                killed["standby_rss_mb"] = psutil.Process(standbys[victim]).memory_info().rss / 2 ** 20
        killed["t"] = time.time()
        os.kill(pid, signal.SIGKILL)

    original = bagplay.Player.play

    def play(self, *a, **kw):
        playing.set()
        return original(self, *a, **kw)

    bagplay.Player.play = play  # the killer starts counting when frames start to flow
    th = threading.Thread(target=killer, daemon=True)
    th.start()
    try:
        replay(str(bag), str(scene), rate=1.0, lossless=False, record=str(out), echo=echo, standby=standby,
               one_process=victim == ONE_PROCESS)
    finally:
        bagplay.Player.play = original
    th.join(5)
    if "t" not in killed:
        raise RuntimeError(f"{victim} was never killed (replay ended first?)")
    t_kill = killed["t"]
    t_restart = pids[victim][-1][0] if len(pids.get(victim, [])) > 1 else float("inf")
    msgs = [(m.log_time_ns * 1e-9, m) for m in bags.read_bag(out, topics=[OUTPUTS[victim]])]
    # output after the kill counts once the new process exists: a message the killed one sent just before
    # can still arrive after the kill
    after = [(t, m) for t, m in msgs if t > t_restart]
    before = [t for t, _ in msgs if t <= t_kill]
    row = {"node": victim, "standby": standby, "messages_before": len(before), "messages_after": len(after),
           "from_standby": any(line.startswith(f"[launch] started {victim} ") and line.endswith("from its standby")
                               for line in lines),
           "restarts": len(pids.get(victim, [])) - 1,
           "restart_s": (pids[victim][-1][0] - t_kill) if len(pids.get(victim, [])) > 1 else float("nan"),
           "gap_s": (after[0][0] - t_kill) if after else float("nan"),
           "standby_rss_mb": killed.get("standby_rss_mb", float("nan"))}
    if victim in TRACKED:
        ok = [t for t, m in after if int(bags.decode(m).state) == 0]
        row["back_to_ok_s"] = (ok[0] - t_kill) if ok else float("nan")
        # for scale: the longest stretch without an OK estimate before the kill (the demo at 320x240 has some)
        ok_before = [t for t, m in msgs if t <= t_kill and int(bags.decode(m).state) == 0]
        row["ok_gap_before_s"] = float(np.max(np.diff(ok_before))) if len(ok_before) > 1 else float("nan")
    return row


def kill_tree(pid: int) -> None:
    """SIGKILL a process and every process below it (the launcher starts nodes in sessions of their own). The tree is
    read first and the root killed first, so that a launcher cannot start a node meanwhile in place of one killed."""
    with contextlib.suppress(psutil.Error):
        root = psutil.Process(pid)
        for p in [root, *root.children(recursive=True)]:
            with contextlib.suppress(psutil.Error):
                p.send_signal(signal.SIGKILL)


def _run_command(victim: str, standby: bool, row: Path) -> list[str]:
    return [sys.executable, "-m", "benchmarks.respawn", "--one", victim, "--row", str(row)] + (
        [] if standby else ["--no-standby"])


def run_isolated(victim: str, standby: bool, timeout: float = RUN_TIMEOUT_S,
                 command: Callable[[str, bool, Path], list[str]] = _run_command) -> tuple[dict | None, str]:
    """:func:`run_once` in a child process (``command``: its command line, given the victim, the standby setting and
    the file for its row): (its row, "") or (None, why the try failed: timed out, or the child's exit status). The
    child writes its row as JSON; one that outlives ``timeout`` is killed with its nodes, as is the child of a
    benchmark interrupted meanwhile."""
    with tempfile.TemporaryDirectory() as d:
        out = Path(d) / "row.json"
        child = subprocess.Popen(command(victim, standby, out), cwd=REPO)
        try:
            rc = child.wait(timeout)
        except subprocess.TimeoutExpired:
            kill_tree(child.pid)
            child.wait()
            return None, f"timed out after {timeout:.0f} s"
        except BaseException:
            kill_tree(child.pid)
            raise
        if rc != 0 or not out.is_file():
            return None, f"exit status {rc}"
        return json.loads(out.read_text()), ""


def main():
    import argparse

    from benchmarks.common import RESULTS

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--report", action="store_true", help="rewrite table and plot from the results JSON")
    ap.add_argument("--runs", type=int, default=3, help="runs per node and standby setting")
    ap.add_argument("--victims", nargs="+", choices=VICTIMS, default=list(VICTIMS),
                    help="run only these (the other victims' runs are kept from the results JSON)")
    ap.add_argument("--one", choices=VICTIMS, help=argparse.SUPPRESS)  # a child's run (run_isolated)
    ap.add_argument("--row", help=argparse.SUPPRESS)
    ap.add_argument("--no-standby", action="store_true", help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.one:
        bag, scene = sample()
        with tempfile.TemporaryDirectory() as d:
            row = run_once(bag, scene, a.one, Path(d) / "rec", standby=not a.no_standby)
        Path(a.row).write_text(json.dumps(row))
        return
    rows = []
    if a.report or set(a.victims) != set(VICTIMS):
        kept = RESULTS / "respawn.json"
        if not kept.is_file():
            ap.error(f"--report and --victims keep runs from {kept}, which does not exist: run all victims first")
        rows = [r for r in json.loads(kept.read_text())["runs"] if a.report or r["node"] not in a.victims]
    if not a.report:
        sample()  # the bag, made once before the runs' children read it
        for standby in (True, False):
            for victim in a.victims:
                for k in range(a.runs):
                    failed: list[str] = []
                    while (r := run_isolated(victim, standby))[0] is None:
                        failed.append(r[1])
                        print(f"[respawn] {victim} (standby {standby}) run {k}: try failed, {r[1]}", flush=True)
                        if len(failed) == TRIES:
                            raise RuntimeError(f"{victim} (standby {standby}) run {k}: {TRIES} tries failed: "
                                               f"{failed}")
                    row = r[0] | {"run": k, "failed_tries": failed}
                    rows.append(row)
                    print(row, flush=True)
    summary = []
    for standby in (True, False):
        for victim in VICTIMS:
            rr = [r for r in rows if r["node"] == victim and r.get("standby", False) == standby]
            if not rr:
                continue
            def med(key: str, rr: list[dict] = rr) -> float:
                return float(np.nanmedian([r.get(key, np.nan) for r in rr]))

            summary.append({"node": victim, "standby": "yes" if standby else "no (cold)", "runs": len(rr),
                            "promoted": sum(bool(r.get("from_standby")) for r in rr),
                            "failed_tries": sum(len(r.get("failed_tries", [])) for r in rr),
                            "restart_s": med("restart_s"), "gap_s": med("gap_s"),
                            "standby_rss_mb": med("standby_rss_mb"),
                            "gap_max_s": float(np.nanmax([r["gap_s"] for r in rr])),
                            "back_to_ok_s": med("back_to_ok_s") if victim in TRACKED else float("nan"),
                            "ok_gap_before_s": med("ok_gap_before_s") if victim in TRACKED else float("nan")})
    cols = [("node", "node killed", "{}"), ("standby", "standby", "{}"), ("runs", "runs", "{}"),
            ("promoted", "standby promoted", "{}"), ("restart_s", "respawned after (s)", "{:.2f}"),
            ("gap_s", "output back after (s, median)", "{:.2f}"), ("gap_max_s", "max", "{:.2f}"),
            ("back_to_ok_s", "tracker OK again after (s)", "{:.2f}"),
            ("ok_gap_before_s", "tracker: longest gap between OK estimates before the kill (s)", "{:.2f}"),
            ("standby_rss_mb", "standby's memory (RSS MB)", "{:.0f}"),
            ("failed_tries", "tries timed out or failed (rerun)", "{}")]

    def plot(plt):
        fig, axes = plt.subplots(1, 2, figsize=(10, 3.5), sharey=True)
        for ax, standby in zip(axes, (True, False), strict=True):
            for j, (key, lab) in enumerate((("restart_s", "respawned"), ("gap_s", "output back"),
                                            ("back_to_ok_s", "tracker OK again"))):
                for i, victim in enumerate(VICTIMS):
                    v = [r.get(key, np.nan) for r in rows if r["node"] == victim and r.get("standby") == standby]
                    ax.scatter(np.full(len(v), i + (j - 1) * 0.2), v, color=f"C{j}",
                               label=lab if i == 0 else None)
            ax.axhline(1.0, color="gray", ls=":", lw=0.8, label="target (1 s)")
            ax.set_xticks(range(len(VICTIMS)), VICTIMS)
            ax.set_title("with a standby process" if standby else "cold restart (--no-standby)", fontsize=9)
        axes[0].set_ylabel("seconds after kill -9")
        axes[0].legend(fontsize=7)
        fig.tight_layout()
        return fig

    save("respawn", summary, cols, "kill -9 of one node mid-replay: respawn and recovery",
         f"`kill -9` {KILL_AFTER_S:.0f} s into a live replay (rate 1) of the aluminium beam demo (320x240, 12 s); "
         "times from the kill, measured on the recording's receive times; median of the runs per node and setting "
         "(all runs in the JSON). A run that fails, or hangs (killed with its nodes after "
         f"{RUN_TIMEOUT_S:.0f} s), is run again (up to {TRIES} tries; counted in the last column). Standby: the "
         "launcher's standby process for the node (imports done, DDS participant up) is promoted; cold: a new "
         "process (`--no-standby`). 'nodes': the one-process launch (`--one-process`) killed whole, the tracker's "
         "output measured. The issue's target: tracking back "
         "within 1 s. `--victims` reruns some rows and keeps the others' runs from the JSON"
         + (f" (kept here: every victim's but {', '.join(a.victims)})" if set(a.victims) != set(VICTIMS) else "")
         + ".", plot,
         extra={"runs": rows, **(saved_machine("respawn") if a.report else {})})


if __name__ == "__main__":
    main()
