"""Outputs of `rscalib selfcalib`: result.json (through rscalib.io.results), camera.yaml (the OpenCV
pinhole-radtan camera closest to the civera-radial estimate) and history.png (the estimates with
their 99 % bounds and the number of Gaussians per frame)."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Optional

from ..io.cameras import write_opencv_yaml
from ..io.results import write_result_json
from .calibrate import PARAM_NAMES, SelfCalibResult, civera_to_opencv

CAMERA_FILE = "camera.yaml"
HISTORY_PLOT = "history.png"


@dataclass
class SelfCalibOutputs:
    """What :func:`write_selfcalib_outputs` wrote, and how far the OpenCV camera is from the estimate."""

    result_json: Path
    camera_yaml: Path
    history_png: Path
    opencv_max_difference_px: float


def write_selfcalib_outputs(result: SelfCalibResult, out_dir, *, extra: Optional[dict] = None,
                            inputs: Optional[dict] = None) -> SelfCalibOutputs:
    """Write out_dir/result.json (the result's summary, then ``extra`` entries, then the OpenCV
    camera's description; ``inputs`` go to its provenance), out_dir/camera.yaml and
    out_dir/history.png."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    summary = {**result.summary_dict(), **(extra or {})}
    opencv, max_error = civera_to_opencv(result.camera())
    write_opencv_yaml(opencv, out / CAMERA_FILE)
    summary["opencv_camera"] = {"file": CAMERA_FILE, "model": "pinhole-radtan (k1, k2, k3 fitted; p1 = p2 = 0)",
                                "max_difference_px": max_error}
    plot_history(result, out / HISTORY_PLOT)
    path = write_result_json(out, summary, command="selfcalib", inputs=inputs)
    return SelfCalibOutputs(result_json=path, camera_yaml=out / CAMERA_FILE, history_png=out / HISTORY_PLOT,
                            opencv_max_difference_px=max_error)


def plot_history(result: SelfCalibResult, path: Path) -> None:
    """The five estimates with their 99 % bounds, and the number of Gaussians, per frame."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    units = {"f": "px", "cx": "px", "cy": "px", "k1": "mm⁻²", "k2": "mm⁻⁴"}
    history = result.history
    fig, axes = plt.subplots(6, 1, figsize=(8, 12), sharex=True)
    for i, name in enumerate(PARAM_NAMES):
        ax = axes[i]
        ax.fill_between(history.frame, history.bounds_99[:, i, 0], history.bounds_99[:, i, 1], alpha=0.3,
                        label="99 % bounds")
        ax.plot(history.frame, history.mean[:, i], lw=1.2, label="estimate")
        ax.set_ylabel(f"{name} ({units[name]})")
    axes[0].legend(fontsize=8)
    axes[5].semilogy(history.frame, history.gaussians, lw=1.2, color="C3")
    axes[5].set_ylabel("Gaussians")
    axes[5].set_xlabel("frame")
    axes[0].set_title("Self-calibration: estimates with 99 % bounds, and the number of Gaussians")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
