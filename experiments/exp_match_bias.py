"""Where the image-level self-calibration bias came from (issue 5/6; not in Civera et al.).

On rendered textured-room sequences the renderer knows, for every feature the front end
initialises, the 3-D point under its pixel; so every later match can be compared with the exact
projection of that point. Three front ends feed the same 108-Gaussian bank:

- `parabola`: NCC of the stored (never re-cut, never warped) patch, parabola through the peak;
- `affine`:   the same, then ECC affine alignment of the patch (rscalib's default);
- `exact`:    the matches `affine` found, replaced by the exact projection + 0.3 px Gaussian noise
              (same features, same frames: only the measurement error differs).

Reports the match error against feature age and the final calibration per front end.

Usage: .venv/bin/python benchmarks/exp_match_bias.py [--sequences 4] [--frames 300]
Writes benchmarks/results/exp_match_bias.json and docs/figures/exp_match_bias.png.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from _common import machine_info, write_results
from exp_sog_vs_single import frames_for

from rscalib.selfcalib.calibrate import self_calibrate
from rscalib.selfcalib.front_end import FrontEndOptions, ImageFrontEnd
from rscalib.sim.scene_video import render_scene_frames
from rscalib.sim.trajectories import RoomWalkTrajectory

ROOT = Path(__file__).resolve().parents[1]
AGE_BINS = [(1, 5), (5, 15), (15, 40), (40, 100), (100, 10 ** 6)]


class _Recorder(ImageFrontEnd):
    """The image front end, recording each match's error against the exact projection of the 3-D
    point under the feature's first pixel (learnt when the bank starts the feature); in mode `exact`
    the match is replaced by that projection + noise."""

    def __init__(self, truth_frames, camera, mode: str, rng: np.random.Generator, image_size):
        super().__init__(FrontEndOptions(subpixel="parabola" if mode == "parabola" else "affine"), image_size)
        self.truth, self.camera, self.mode, self.rng = truth_frames, camera, mode, rng
        self.frame = -1
        self.points_w: dict[int, tuple[np.ndarray, int]] = {}
        self.errors: list[tuple[int, float, float]] = []   # (age, du, dv)

    def measure(self, image, ids, uv_pred, cov):
        self.frame += 1
        uv, found = super().measure(image, ids, uv_pred, cov)
        for i in np.nonzero(found)[0]:
            known = self.points_w.get(int(ids[i]))
            if known is None:
                continue
            x_c = self.truth.R_cw[self.frame] @ known[0] + self.truth.p_cw[self.frame]
            exact = self.camera.project(x_c[None])[0]
            if not np.all(np.isfinite(exact)):
                continue
            self.errors.append((self.frame - known[1], *(uv[i] - exact)))
            if self.mode == "exact":
                uv[i] = exact + self.rng.normal(0.0, 0.3, 2)
        return uv, found

    def track(self, image, feature_ids, uv):
        super().track(image, feature_ids, uv)
        hits = self.truth.surface(self.frame, np.asarray(uv))
        for fid, point in zip(feature_ids, hits.points_w):
            self.points_w[int(fid)] = (point, self.frame)


def run(seed: int, frames: int, mode: str) -> dict:
    times, images, truth = frames_for(seed, frames)
    # Poses and per-pixel surface truth (cheap: no rendering of images).
    posed = render_scene_frames(num_frames=1, seed=seed)
    R, p = RoomWalkTrajectory(seed=seed).pose_cw(times)
    posed.R_cw, posed.p_cw = np.asarray(R), np.asarray(p)
    image_size = (images.shape[2], images.shape[1])
    recorder = _Recorder(posed, posed.camera, mode, np.random.default_rng([seed, 7]), image_size)
    result = self_calibrate(zip(times, images), image_size, front_end=recorder)
    err = np.array(recorder.errors)
    by_age = []
    for lo, hi in AGE_BINS:
        sel = err[(err[:, 0] >= lo) & (err[:, 0] < hi), 1:]
        by_age.append(float(np.sqrt(np.mean(np.sum(sel ** 2, axis=1)))) if len(sel) else None)
    inside = [bool(lo <= t <= hi) for (lo, hi), t in zip(result.bounds_99, truth)]
    return dict(seed=seed, mode=mode, f=float(result.mean[0]), f_error_rel=float(result.mean[0] / truth[0] - 1),
                cy_error_px=float(result.mean[2] - truth[2]), all_inside=all(inside), inside=inside,
                matches=len(err), match_rms_px_by_age=by_age)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sequences", type=int, default=4)
    parser.add_argument("--frames", type=int, default=300)
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "exp_match_bias.json")
    parser.add_argument("--figure", type=Path, default=ROOT / "docs" / "figures" / "exp_match_bias.png")
    args = parser.parse_args()
    info = machine_info()
    rows = []
    for s in range(args.sequences):
        for mode in ("parabola", "affine", "exact"):
            r = run(100 + s, args.frames, mode)
            rows.append(r)
            print(f"seed {r['seed']} {mode:8s}: f {r['f_error_rel'] * 100:+.2f} %, cy {r['cy_error_px']:+.2f} px, "
                  f"all five inside {r['all_inside']}, match RMS by age "
                  f"{[None if x is None else round(x, 3) for x in r['match_rms_px_by_age']]}", flush=True)
    lines = ["| front end | match RMS, age 1–5 | 5–15 | 15–40 | 40–100 | ≥ 100 frames | mean \\|f error\\| | f errors | mean cy error | all five inside |",
             "|---|---:|---:|---:|---:|---:|---:|---|---:|---:|"]
    for mode in ("parabola", "affine", "exact"):
        sel = [r for r in rows if r["mode"] == mode]
        ages = np.array([[np.nan if x is None else x for x in r["match_rms_px_by_age"]] for r in sel])
        cells = " | ".join(f"{v:.3f} px" for v in np.nanmean(ages, axis=0))
        each_f = ", ".join(f"{r['f_error_rel'] * 100:+.2f}" for r in sel)
        lines.append(f"| {mode} | {cells} | {np.mean([abs(r['f_error_rel']) for r in sel]) * 100:.2f} % | "
                     f"{each_f} % | "
                     f"{np.mean([r['cy_error_px'] for r in sel]):+.2f} px | "
                     f"{sum(r['all_inside'] for r in sel)}/{len(sel)} |")
    table = "\n".join(lines)
    print("\n" + table)
    figure(rows, args.figure)
    write_results(args.out, "exp_match_bias", info, {"sequences": args.sequences, "frames": args.frames}, rows, table)


def figure(rows, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(9, 3.6))
    centres = [3, 10, 27, 70, 200]
    for i, mode in enumerate(("parabola", "affine", "exact")):
        sel = [r for r in rows if r["mode"] == mode]
        ages = np.array([[np.nan if x is None else x for x in r["match_rms_px_by_age"]] for r in sel])
        ax0.plot(centres, np.nanmean(ages, axis=0), "o-", color=f"C{i}", label=mode)
        ax1.scatter(np.full(len(sel), i) + np.linspace(-0.15, 0.15, len(sel)),
                    [r["f_error_rel"] * 100 for r in sel], color=f"C{i}")
    ax0.set_xscale("log")
    ax0.set_xlabel("feature age (frames)")
    ax0.set_ylabel("match error RMS (px)")
    ax0.legend(fontsize=8)
    ax0.set_title("Match error vs the exact projection")
    ax1.axhline(0, color="k", lw=0.8)
    ax1.set_xticks([0, 1, 2], ["parabola", "affine", "exact"])
    ax1.set_ylabel("final f error (%)")
    ax1.set_title("Calibration from the same bank")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=90)
    plt.close(fig)


if __name__ == "__main__":
    main()
