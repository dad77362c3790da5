"""`simreal demo`: the end-to-end job on an embedded default scene, no camera needed.

1. the scene's model is built from its spec once (cached in ``cache/models``);
2. its sample bag is taken from ``bags/`` (generated with ``make-bag`` if absent: a synthetic recording
   with exact ground truth that the estimators never read);
3. the bag is replayed losslessly through the real multi-process graph (ingest -> localization ->
   tracking and / or collision -> overlay) over DDS, recording every output topic;
4. the run is evaluated against the truth: overlay MP4, a PNG plot of estimated versus true parameters
   over time, and ``metrics.json`` / ``summary.md`` (parameter error, per-node rate and latency).
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

import numpy as np

from simreal_nodes.errors import SimrealError
from simreal_nodes.rom.build import REPO

DEFAULT_SCENE = "aluminium_beam"
BAGS = REPO / "bags"


def sample_bag(scene: str, regenerate: bool = False, echo=print, duration: float | None = None,
               resolution: str = "640x480") -> tuple[Path, Path]:
    """(bag folder, scene YAML) of a sample scene, generating them when absent."""
    tag = "" if resolution == "640x480" else f"_{resolution}"
    bag, yaml_path = BAGS / f"{scene}{tag}", BAGS / f"{scene}{tag}.yaml"
    if regenerate or not (bag.is_dir() and yaml_path.is_file()):
        import shutil

        from simreal_nodes.synth.makebag import make_bag

        if bag.exists():
            shutil.rmtree(bag)
        w, h = (int(x) for x in resolution.lower().split("x"))
        echo(f"[demo] rendering the sample bag {bag} (synthetic scene '{scene}', {resolution}) ...")
        info = make_bag(scene, bag, width=w, height=h, duration=duration, image_format="jpeg", jpeg_quality=95,
                        scene_out=yaml_path)
        echo(f"[demo] {info}")
    return bag, yaml_path


def node_metrics(run_bag: Path) -> dict:
    """Last diagnostics of every simreal node in a recorded run: rate, processing time, drops."""
    from simreal_nodes.io import bags

    last = {}
    for m in bags.read_bag(run_bag, topics=["/diagnostics"]):
        for st in bags.decode(m).status:
            if st.name.startswith("simreal/"):
                last[st.name[8:]] = ({kv.key: kv.value for kv in st.values}
                                     | {"message": st.message, "level": int(st.level)})
    return last


def plot_parameters(series: dict, path: Path) -> None:
    """series: label -> (t, est, std, truth, unit)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = max(1, len(series))
    fig, axs = plt.subplots(n, 1, figsize=(8, 2.8 * n), squeeze=False)
    for ax, (label, (t, e, sd, tr, unit)) in zip(axs[:, 0], series.items()):
        sc, u = (1e3, "mm") if unit == "m" else ((180 / np.pi, "deg") if unit == "rad" else (1.0, unit))
        ax.plot(t, tr * sc, "k-", lw=2, label="truth")
        ax.plot(t, e * sc, "C0.-", ms=3, lw=0.8, label="estimate")
        if sd is not None and np.any(np.isfinite(sd)):
            ax.fill_between(t, (e - 2 * sd) * sc, (e + 2 * sd) * sc, color="C0", alpha=0.2, label="±2σ")
        ax.set_ylabel(f"{label} [{u}]")
        ax.grid(alpha=0.3)
        ax.legend(loc="best", fontsize=8)
    axs[-1, 0].set_xlabel("time [s]")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def model_ranges(model_path: str) -> dict:
    """Parameter name -> (lo, hi) of the model's axes (errors are reported as % of these ranges)."""
    from simreal_nodes.rom.model_file import load_model

    m = load_model(model_path, fields=[], mesh=False)
    out = {a.name: a.range for a in m.axes}
    for r in m.rigid_parameters:
        if "range" in r:
            out[r["name"]] = tuple(r["range"])
    return out


def evaluate_run(run_bag: Path, truth_bag: Path, scene: dict, out: Path) -> dict:
    from simreal_nodes.assimilation.evaluate import compare, read_parameters
    from simreal_nodes.scene.graph import params_topic

    results: dict[str, dict[str, Any]] = {}  # per object (or "object/parameter"): its comparison
    series: dict[str, tuple[Any, ...]] = {}
    for o in scene["objects"]:
        if not (o["tracking"]["enabled"] or o["collision"]["enabled"]):
            continue
        oid = o["id"]
        try:
            est = read_parameters(run_bag, params_topic(oid))
            tru = read_parameters(truth_bag, f"{scene['ground_truth']['topic_prefix']}/objects/{oid}/parameters")
        except SimrealError as e:
            results[oid] = {"error": str(e)}
            continue
        common, ie, it = np.intersect1d(est.stamps, tru.stamps, return_indices=True)
        t = (common - common[0]) * 1e-9 if len(common) else common
        for r in compare(est, tru, model_ranges(o["model"])):
            j, k = est.names.index(r.name), tru.names.index(r.name)
            series[f"{oid}/{r.name}"] = (t, est.values[ie, j], est.std[ie, j] if est.std is not None else None,
                                         tru.values[it, k], r.unit)
            results[f"{oid}/{r.name}"] = {"unit": r.unit, "frames": r.n, "median_abs": r.median_abs,
                                          "mean_abs": r.mean_abs, "max_abs": r.max_abs, "range": r.span,
                                          "median_pct_of_range": 100 * r.median_abs / r.span if r.span else None,
                                          "outside_range": r.outside_range, "states": r.states, "table41": r.table}
    if series:
        plot_parameters(series, out / "parameters.png")
    return results


def run_demo(scene: str = DEFAULT_SCENE, out: str | Path = "out/demo", regenerate: bool = False,
             resolution: str = "640x480", duration: float | None = None, echo=print,
             one_process: bool = True, executor: str | None = None, threads: int | None = None) -> dict:
    from simreal_nodes.ros.commands import replay
    from simreal_nodes.scene.schema import build_spec_models, load_scene

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.monotonic()
    bag, scene_yaml = sample_bag(scene, regenerate, echo, duration, resolution)
    echo(f"[demo] scene {scene_yaml}; loading / building its model(s) ...")
    sc = build_spec_models(load_scene(scene_yaml))  # spec:NAME models built once into cache/models
    run_bag = out / "run"
    if run_bag.exists():
        import shutil

        shutil.rmtree(run_bag)
    video = out / "overlay.mp4"
    echo("[demo] replaying through the graph" + (" (one process)" if one_process else " (a process per node)") + ": "
         + " -> ".join(n.name for n in __import__("simreal_nodes.scene.graph",
                                                   fromlist=["required_nodes"]).required_nodes(sc)))
    stats, _report, counts = replay(str(bag), str(scene_yaml), lossless=True, record=str(run_bag),
                                   extra_params={"overlay": {"video": str(video.resolve())}}, echo=echo,
                                   one_process=one_process, executor=executor, threads=threads)
    if stats is None:
        raise SimrealError("the replay did not run")
    params = evaluate_run(run_bag, bag, sc, out)
    metrics = {"scene": scene, "bag": str(bag), "frames": stats.as_dict(), "parameters": params,
               "nodes": node_metrics(run_bag), "recorded": counts, "wall_s": time.monotonic() - t0,
               "outputs": {"video": str(video), "plot": str(out / "parameters.png"), "run_bag": str(run_bag)}}
    (out / "metrics.json").write_text(json.dumps(metrics, indent=2, default=float))
    (out / "summary.md").write_text(summary_markdown(metrics))
    echo(summary_markdown(metrics))
    return metrics


def summary_markdown(m: dict) -> str:
    f = m["frames"]
    lines = [f"# simreal demo: {m['scene']}", "",
             f"{f['frames_published']} frames replayed in {f['play_s']:.1f} s ({f['fps']:.1f} fps, lossless); "
             f"{f['frames_completed']} completed, {f['frames_dropped']} dropped, "
             f"{f['frames_timed_out']} timed out.", "",
             "| parameter | frames | median abs error | % of range | max abs error | outside range |",
             "|---|---|---|---|---|---|"]
    for k, p in m["parameters"].items():
        if "error" in p:
            lines.append(f"| {k} | - | {p['error']} | | | |")
            continue
        sc, u = (1e3, "mm") if p["unit"] == "m" else ((180 / np.pi, "deg") if p["unit"] == "rad" else (1.0, p["unit"]))
        pct = p["median_pct_of_range"]
        lines.append(f"| {k} | {p['frames']} | {p['median_abs'] * sc:.3f} {u} | {pct:.2f} | "
                     f"{p['max_abs'] * sc:.3f} {u} | {p['outside_range']} |" if pct is not None
                     else f"| {k} | {p['frames']} | {p['median_abs'] * sc:.3f} {u} | - | - | - |")
    lines += ["", "| node | processing p50 ms | p95 ms | processed | dropped | errors "
                  "| latency from publish p50 / p95 ms |",
              "|---|---|---|---|---|---|---|"]
    lat = f.get("latency_ms", {})
    for n, d in sorted(m["nodes"].items()):
        l = lat.get(n, {})
        lines.append(f"| {n} | {d.get('processing_ms_p50', '-')} | {d.get('processing_ms_p95', '-')} | "
                     f"{d.get('processed', '-')} | "
                     f"{d.get('dropped', '-')} | {d.get('errors', '-')} | "
                     f"{l.get('p50', float('nan')):.1f} / {l.get('p95', float('nan')):.1f} |")
    o = m["outputs"]
    lines += ["", f"Overlay video: `{o['video']}`; parameters plot: `{o['plot']}`; recorded outputs: `{o['run_bag']}`."]
    return "\n".join(lines) + "\n"
