"""The small sample bags committed in ``bags/samples/`` (issue 4): what each one is and the exact call that renders
it, so a test can re-render one and compare pixels, and a user can regenerate them all
(``python -m simreal_nodes.synth.samples``)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from simreal_nodes.rom.build import REPO

SAMPLES_DIR = REPO / "bags" / "samples"

SAMPLES: dict[str, dict[str, Any]] = {
    # markers + glued dots on the aluminium beam (thesis §4.5.1): the demo's scene, short and small
    "aluminium_beam_320x240": dict(scene="aluminium_beam", width=320, height=240, duration=2.0, image_format="jpeg",
                                   jpeg_quality=90),
    # a real probe pushing the virtual crossed beams, RGB-D (§5.4.1): what tests/ros/test_graph.py replays
    "crossed_beams_probe_320x240": dict(scene="crossed_beams_probe", width=320, height=240, duration=3.2,
                                        image_format="jpeg", jpeg_quality=90),
}


def sample(name: str) -> tuple[Path, Path]:
    """(bag folder, scene YAML) of a committed sample."""
    if name not in SAMPLES:
        raise KeyError(f"no sample bag '{name}' (known: {', '.join(SAMPLES)})")
    return SAMPLES_DIR / name, SAMPLES_DIR / f"{name}.yaml"


def render_sample(name: str, out_dir: str | Path = SAMPLES_DIR) -> dict:
    """Render sample ``name`` into ``out_dir`` (bag folder + scene YAML) with its recorded settings."""
    from simreal_nodes.synth.makebag import make_bag

    s = dict(SAMPLES[name])
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    return make_bag(s.pop("scene"), out_dir / name, scene_out=out_dir / f"{name}.yaml", **s)


if __name__ == "__main__":
    import shutil

    for n in SAMPLES:
        bag, _ = sample(n)
        if bag.exists():
            shutil.rmtree(bag)
        print(n, render_sample(n))
