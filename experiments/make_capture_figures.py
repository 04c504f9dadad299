"""Figures of docs/capture.md for the flicker and self-calibration sections, made by the renderers.

    .venv/bin/python experiments/make_capture_figures.py      # writes docs/capture/{flicker,selfcalib}.png
"""
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from rscalib.sim.flicker_light import FlickerLight, FlickerScene, render_flicker_frames  # noqa: E402
from rscalib.sim.scene_video import render_scene_frames  # noqa: E402

OUT = Path(__file__).resolve().parent.parent / "docs" / "capture"


def flicker_figure() -> Path:
    """Good: a diffuser filling the frame, short exposure (crisp bands); bad: long exposure (bands
    washed out) and a small lamp with a text overlay (few rows carry bands)."""
    size, d = (480, 270), 30e-6
    cases = [("plain surface, short exposure: crisp bands", FlickerScene(coverage=1.0, vignetting=0.3), 1 / 8000),
             ("exposure close to 1/f: bands wash out", FlickerScene(coverage=1.0, vignetting=0.3), 0.9e-3),
             ("small lamp and an overlay: few rows carry bands",
              FlickerScene(lamp="disk", lamp_radius=0.18, overlay_text="12:00 ISO 100", texture=0.3), 1 / 8000)]
    fig, axes = plt.subplots(1, 3, figsize=(12, 2.8), constrained_layout=True)
    for ax, (title, scene, exposure) in zip(axes, cases):
        frames, _ = render_flicker_frames(FlickerLight(1000.0, duty=0.5), scene, size, d, [0.0], exposure_s=exposure,
                                          noise=1.0, seed=1)
        ax.imshow(frames[0], cmap="gray", vmin=0, vmax=255)
        ax.set_title(title, fontsize=9)
        ax.axis("off")
    path = OUT / "flicker.png"
    fig.savefig(path, dpi=80)
    plt.close(fig)
    return path


def selfcalib_figure() -> Path:
    """Frames of the rendered room walk `rscalib simulate --scene` makes: rotation and translation
    through a textured room, the kind of sequence that determines f."""
    frames = render_scene_frames(num_frames=241, seed=0, supersampling=1)
    picks = [0, 80, 160, 240]
    fig, axes = plt.subplots(1, len(picks), figsize=(12, 2.4), constrained_layout=True)
    for ax, k in zip(axes, picks):
        ax.imshow(np.asarray(frames.images[k]), cmap="gray", vmin=0, vmax=255)
        ax.set_title(f"t = {k / 30:.1f} s", fontsize=9)
        ax.axis("off")
    path = OUT / "selfcalib.png"
    fig.savefig(path, dpi=80)
    plt.close(fig)
    return path


if __name__ == "__main__":
    OUT.mkdir(parents=True, exist_ok=True)
    for make in (flicker_figure, selfcalib_figure):
        path = make()
        print(f"wrote {path} ({path.stat().st_size // 1024} kB)")
