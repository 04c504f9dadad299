"""What a user should film differently: coverage of the image rows, motion per axis, blur and
dropped frames of a line-delay run, with advice in plain words (docs/capture.md explains why).

The line delay lives in the rows: it is seen as the image moving while the shutter scans down, so
it needs the board over many rows, image motion across the rows (rotation about the camera's
vertical axis, y, shears the board; about x it stretches it), and sharp frames.
"""
from __future__ import annotations

from typing import Optional

import numpy as np

from .._core import rotation_matrix_to_vector, rotation_vector_to_matrix

# thresholds of the advice (docs/capture.md)
MIN_ROW_SPAN = 0.6           # fraction of the image rows the board should cover over the video
MIN_SPEED_PX_S = 150.0       # median image speed below this: too slow
MAX_BLURRED_FRACTION = 0.2   # frames with edges wider than BLURRED_PX
BLURRED_PX = 4.0
MAX_DROPPED_FRACTION = 0.2
# Below this the video was likely re-encoded (a phone records about 0.2-0.4 bit/pixel): on renders the
# line-delay error at 0.12 bit/pixel is about twice that at 0.25 (docs/experiments.md).
MIN_BITS_PER_PIXEL = 0.15


def angular_rates(result, samples: int = 400) -> Optional[np.ndarray]:
    """(n, 3) angular velocity in the camera frame (rad/s) along the spline trajectory, or None."""
    trajectory = getattr(result, "trajectory", None)
    if trajectory is None:
        return None
    t = np.linspace(trajectory.t_begin, trajectory.t_end, samples)
    phi = trajectory.evaluate(t)[:, 3:]
    R = np.array([rotation_vector_to_matrix(p) for p in phi])
    dt = t[1] - t[0]
    # with R = R_cw: R_wc' = R_wc [w]x (w in the camera frame), so R(t) R(t + dt)^T = exp([w dt]x)
    rel = np.einsum("nij,nkj->nik", R[:-1], R[1:])
    return np.array([rotation_matrix_to_vector(r) for r in rel]) / dt


def capture_guidance(result, detection=None, bits_per_pixel: Optional[float] = None) -> dict:
    """Coverage, motion, blur, drops and compression of a line-delay result (spline or linear), the
    detection it came from and the video's bitrate per pixel (io.video.video_bits_per_pixel), with
    `advice`: sentences a user can act on (empty when the video is fine)."""
    obs = result.used_observations
    rows = int(result.rows)
    v = obs.uv[:, 1]
    span = float((np.percentile(v, 98) - np.percentile(v, 2)) / rows) if len(v) else 0.0
    hist, _ = np.histogram(v, bins=10, range=(0, rows))
    out: dict = {"row_span": span, "row_coverage_deciles": (hist > 0).astype(int).tolist()}
    advice = []
    if span < MIN_ROW_SPAN:
        out_of = obs.uv[:, 0]
        width = obs.image_size[0]
        col_span = float((np.percentile(out_of, 98) - np.percentile(out_of, 2)) / width) if len(out_of) else 0.0
        advice.append(f"the board spans {span * 100:.0f} % of the image rows (and {col_span * 100:.0f} % of the "
                      "columns): hold it closer, or move it over the whole frame height")
    velocity = getattr(result, "image_velocity_px_s", None)
    if velocity is not None and len(velocity):
        speed = np.linalg.norm(velocity, axis=1)
        speed = speed[np.isfinite(speed)]
        if speed.size:
            out["image_speed_px_s"] = {"median": float(np.median(speed)), "p90": float(np.percentile(speed, 90))}
            vel = np.abs(velocity[np.all(np.isfinite(velocity), axis=1)])
            out["image_speed_across_rows_px_s"] = float(np.median(vel[:, 0]))
            out["image_speed_along_columns_px_s"] = float(np.median(vel[:, 1]))
            if np.median(speed) < MIN_SPEED_PX_S:
                advice.append(f"motion too slow (median image speed {np.median(speed):.0f} px/s): shake the camera "
                              "about its vertical axis (left-right), a few times per second")
    rates = angular_rates(result)
    if rates is not None:
        rms = np.sqrt(np.mean(rates ** 2, axis=0))
        out["angular_rate_rms_deg_s"] = {"x (pitch)": float(np.degrees(rms[0])), "y (yaw)": float(np.degrees(rms[1])),
                                         "z (roll)": float(np.degrees(rms[2]))}
        if rms[1] < 0.5 * max(rms[0], rms[2]) and rms[1] < np.radians(15):
            advice.append("little rotation about the vertical axis (yaw): turn the camera left-right, which shears "
                          "the board across the rows and shows the line delay best")
    if detection is not None:
        blur = np.asarray(getattr(detection, "blur_px", []), dtype=float)
        blur = blur[np.isfinite(blur)]
        total = max(1, int(detection.frames_total))
        if blur.size:
            blurred = float(np.mean(blur > BLURRED_PX))
            out["blur_px"] = {"median": float(np.median(blur)), "p90": float(np.percentile(blur, 90)),
                              "blurred_fraction": blurred}
            if blurred > MAX_BLURRED_FRACTION:
                advice.append(f"too fast or too dark: {blurred * 100:.0f} % of frames are blurred (edges wider than "
                              f"{BLURRED_PX:g} px): move more slowly or add light (shorter exposure)")
        dropped = dict(detection.dropped)
        out["frames_dropped"] = dropped
        lost = sum(dropped.values())
        if lost > MAX_DROPPED_FRACTION * total:
            reasons = ", ".join(f"{k} {n}" for k, n in sorted(dropped.items(), key=lambda kv: -kv[1]))
            advice.append(f"{lost} of {total} frames had no usable board ({reasons}): keep the whole board in view "
                          "and sharp")
    if bits_per_pixel is not None:
        out["video_bits_per_pixel"] = float(bits_per_pixel)
        if bits_per_pixel < MIN_BITS_PER_PIXEL:
            advice.append(f"the video is compressed to {bits_per_pixel:.2f} bit/pixel, below what phones record "
                          "(about 0.2-0.4): if it was re-encoded (a messaging app, an editor), use the camera's "
                          "original file, or record at a higher quality setting")
    out["advice"] = advice
    return out
