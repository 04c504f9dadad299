"""The `rscalib` command line: one entry point, a subcommand per job (SPEC §5).

Exit codes: 0 success; 2 bad input (one line on stderr, no traceback); 3 the data does
not determine the answer (results are still written, with the warning).
"""
from __future__ import annotations

import argparse
import sys
import time

from . import __version__
from .errors import InputError

EXIT_OK = 0
EXIT_BAD_INPUT = 2
EXIT_UNDETERMINED = 3


class _Parser(argparse.ArgumentParser):
    """argparse exits with 2 on usage errors already; keep its message to one line."""

    def error(self, message: str) -> None:  # pragma: no cover - exercised via CLI tests
        self.exit(EXIT_BAD_INPUT, f"{self.prog}: error: {message}\n")


def _cmd_demo(args: argparse.Namespace) -> int:
    import numpy as np

    from ._core import BSpline, CameraModel, fit_bspline, poses_at, unwrap_rotation_vectors

    started = time.perf_counter()
    # A hand-held-like pose sampled at 30 fps for 4 s, with the rotation vector crossing pi.
    times = np.arange(0.0, 4.0, 1 / 30)
    position = np.c_[0.05 * np.sin(2.1 * times), 0.03 * np.cos(1.3 * times), 0.6 + 0.02 * np.sin(3 * times)]
    angle = 2.9 + 0.25 * np.sin(1.7 * times)
    axis = np.array([0.2, 1.0, 0.1]) / np.linalg.norm([0.2, 1.0, 0.1])
    rotvec = angle[:, None] * axis
    wrapped = np.where(angle[:, None] > np.pi, rotvec * (angle[:, None] - 2 * np.pi) / angle[:, None], rotvec)
    unwrapped = unwrap_rotation_vectors(wrapped)
    knots = BSpline.clamped_knots(np.linspace(times[0], times[-1], 9))
    spline = fit_bspline(knots, times, np.c_[position, unwrapped], acceleration_weight=[1e-6])
    fit_error = np.abs(spline.evaluate(times) - np.c_[position, rotvec]).max()
    n_ins = 8
    for t in np.linspace(times[0], times[-1], n_ins + 2)[1:-1] + 0.01:
        spline.insert_knot(t)
    insert_change = np.abs(spline.evaluate(times) - np.c_[position, rotvec]).max() - fit_error
    camera = CameraModel("pinhole-radtan", [500, 500, 319.5, 239.5, -0.1, 0.05, 0, 0, 0], 640, 480)
    cols, rows = np.meshgrid(np.arange(9), np.arange(6))
    target = np.c_[cols.ravel() * 0.04 - 0.16, rows.ravel() * 0.04 - 0.10, np.zeros(54)]
    rotations, translations = poses_at(spline, times)
    points_c = np.einsum("fij,pj->fpi", rotations, target) + translations[:, None, :]
    uv = camera.project(points_c.reshape(-1, 3))
    elapsed = time.perf_counter() - started
    print(f"rscalib {__version__} demo (foundation): C++ core exercised end to end")
    print(f"  rotation vectors unwrapped across pi: max jump {np.abs(np.diff(wrapped, axis=0)).max():.2f} rad "
          f"-> {np.abs(np.diff(unwrapped, axis=0)).max():.3f} rad")
    print(f"  smoothing spline fitted to {len(times)} poses with 8 segments: max error {fit_error:.2e}")
    print(f"  {n_ins} knots inserted (Boehm), curve change {abs(insert_change):.1e}; now {spline.num_segments} segments")
    print(f"  projected a 9x6 target from {len(times)} spline poses: {np.isfinite(uv[:, 0]).sum()} pixels, "
          f"u in [{np.nanmin(uv[:, 0]):.1f}, {np.nanmax(uv[:, 0]):.1f}], v in [{np.nanmin(uv[:, 1]):.1f}, {np.nanmax(uv[:, 1]):.1f}]")
    print(f"  took {elapsed * 1e3:.1f} ms")
    return EXIT_OK


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="rscalib", description="Camera calibration from video: rolling-shutter line delay "
                     "and self-calibration.")
    parser.add_argument("--version", action="version", version=f"rscalib {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    demo = sub.add_parser("demo", help="run the built-in demonstration (no arguments needed)",
                          description="Run the built-in demonstration on synthetic data.")
    demo.set_defaults(func=_cmd_demo)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return EXIT_BAD_INPUT
    try:
        return int(args.func(args))
    except InputError as error:
        print(f"rscalib {args.command}: error: {error}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print("rscalib: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
