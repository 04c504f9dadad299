"""Paper Fig. 2 (Oth et al. 2013 §3.5): covariance ellipses of the standardised error, A R Aᵀ.

A feature detected with unit variance (R = I px²) has, in a rolling-shutter camera, an error
covariance A R Aᵀ with A = I − d [[0, u̇], [0, v̇]] (docs/formulation.md §4: the matrix the solver
whitens with; tests/python/core/test_rs_cost.py checks the C++ core's against this form). The
image velocity (u̇, v̇) of each feature comes from projecting, with the camera model, a point at
depth Z while the camera translates along its x, y or z axis with speed −V (red), 0 (green) or +V
(blue); the black circle is R itself. d = 137.5 us (the paper's
12 MHz BlueFOX setting), V = 3.5 m/s (exaggerated, as the paper's figure), Z = 0.5 m, 640x480 default camera (f = 500 px, k1 = −0.1).
Ellipses are drawn at ELLIPSE_SCALE px per px of standard deviation (exaggerated).

Usage: .venv/bin/python experiments/exp_fig2_ellipses.py [--quick] [--seeds N]  (seeds unused: no rendering)
Writes benchmarks/results/exp_fig2_ellipses.json and docs/figures/exp_fig2_ellipses.png.
"""
from __future__ import annotations

import time

import _common as C
import numpy as np

from rscalib.sim.target_video import default_camera

NAME = "exp_fig2_ellipses"
D_S = 137.5e-6
SPEED_M_S = 3.5  # exaggerated: d·v̇ ≈ 0.5 at the centre
DEPTH_M = 0.5
ELLIPSE_SCALE = 45.0  # drawn px per px of standard deviation


def image_velocity(camera, uv: np.ndarray, depth_m: float, cam_velocity: np.ndarray, h: float = 1e-4) -> np.ndarray:
    """d/dt of the projection of the static point seen at uv (depth Z) while the camera moves with
    cam_velocity (camera frame): the point moves by −V in the camera frame."""
    ray = np.asarray(camera.unproject(uv[None]))[0]
    X0 = ray / ray[2] * depth_m
    plus = np.asarray(camera.project((X0 - cam_velocity * h)[None]))[0]
    minus = np.asarray(camera.project((X0 + cam_velocity * h)[None]))[0]
    return (plus - minus) / (2 * h)


def error_noise_map(d: float, image_velocity_px_s: np.ndarray) -> np.ndarray:
    """A = I − d [[0, u̇], [0, v̇]]: how pixel noise on (u, v) reaches the error through the row time."""
    return np.eye(2) - d * np.array([[0.0, image_velocity_px_s[0]], [0.0, image_velocity_px_s[1]]])


def main() -> None:
    p = C.parser(__doc__.splitlines()[0], default_seeds=1, quick_seeds=1)
    p.parse_args()
    started = time.perf_counter()
    camera = default_camera((640, 480))
    us = np.linspace(90, 550, 3)
    vs = np.linspace(70, 410, 3)
    grid = np.array([[u, v] for v in vs for u in us])
    rows = []
    for axis, name in enumerate("xyz"):
        for sign in (-1, 0, 1):
            V = np.zeros(3)
            V[axis] = sign * SPEED_M_S
            for uv in grid:
                vel = image_velocity(camera, uv, DEPTH_M, V)
                A = error_noise_map(D_S, vel)
                cov = A @ A.T
                w, _ = np.linalg.eigh(cov)
                rows.append({"motion_axis": name, "velocity_m_s": sign * SPEED_M_S, "u": uv[0], "v": uv[1],
                             "image_velocity_px_s": vel.tolist(), "A": A.tolist(), "cov": cov.tolist(),
                             "sigma_u": float(np.sqrt(cov[0, 0])), "sigma_v": float(np.sqrt(cov[1, 1])),
                             "axis_lengths": np.sqrt(w).tolist()})
    # Table: the centre feature (nearest the principal point) and a corner one.
    centre = grid[np.argmin(np.linalg.norm(grid - [319.5, 239.5], axis=1))]
    corner = grid[-1]
    table_rows = []
    for r in rows:
        for label, pt in (("centre", centre), ("bottom right", corner)):
            if np.allclose([r["u"], r["v"]], pt):
                table_rows.append([r["motion_axis"], f"{r['velocity_m_s']:+.1f}", f"{label} ({pt[0]:.0f}, {pt[1]:.0f})",
                                   f"{r['image_velocity_px_s'][0]:.0f}, {r['image_velocity_px_s'][1]:.0f}",
                                   f"{r['sigma_u']:.3f}", f"{r['sigma_v']:.3f}",
                                   f"{r['cov'][0][1]:+.3f}"])
    table = C.markdown_table(["motion axis", "V (m/s)", "feature (px)", "u̇, v̇ (px/s)", "σ_u (px)", "σ_v (px)",
                              "cov_uv (px²)"], table_rows, align="llllrrr")
    print(table)
    settings = {"line_delay_s": D_S, "speed_m_s": SPEED_M_S, "depth_m": DEPTH_M, "R": "I (1 px^2)",
                "camera": "default 640x480, f = 500 px, k1 = -0.1, k2 = 0.05", "ellipse_scale": ELLIPSE_SCALE}
    C.write_results(NAME, settings, rows, table, {"total": time.perf_counter() - started})
    figure(rows, grid)


def figure(rows, grid) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = np.linspace(0, 2 * np.pi, 80)
    circle = np.c_[np.cos(t), np.sin(t)]
    colours = {-1: "tab:red", 0: "tab:green", 1: "tab:blue"}
    fig, axes = plt.subplots(1, 3, figsize=(12, 3.6), constrained_layout=True)
    for ax, name in zip(axes, "xyz"):
        for uv in grid:
            ax.plot(uv[0] + ELLIPSE_SCALE * circle[:, 0], uv[1] + ELLIPSE_SCALE * circle[:, 1], "k-", lw=1.6)
        for r in rows:
            if r["motion_axis"] != name:
                continue
            L = np.linalg.cholesky(np.array(r["cov"]))
            e = circle @ L.T * ELLIPSE_SCALE
            sign = int(np.sign(r["velocity_m_s"]))
            ax.plot(r["u"] + e[:, 0], r["v"] + e[:, 1], color=colours[sign], lw=1.4,
                    ls="--" if sign == 0 else "-")
        ax.set_xlim(0, 640)
        ax.set_ylim(480, 0)
        ax.set_aspect("equal")
        ax.set_title(f"camera moves along {name}: −{SPEED_M_S:g} (red), +{SPEED_M_S:g} m/s (blue)", fontsize=9)
        ax.set_xlabel("u (px)")
        ax.set_ylabel("v (px)")
    fig.suptitle(f"Error covariance A R Aᵀ, R = 1 px², d = {D_S * 1e6:g} µs, depth {DEPTH_M} m; "
                 f"ellipses ×{ELLIPSE_SCALE:g} (black: R, green dashed: no motion)", fontsize=9)
    C.save_figure(fig, NAME)
    plt.close(fig)


if __name__ == "__main__":
    main()
