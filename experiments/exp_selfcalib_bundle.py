"""Does a batch bundle adjustment make self-calibration trustworthy? (issue 11, an experiment)

The SOG bank runs as `rscalib selfcalib` runs it (default_options(), the image front end, no
restarts); rscalib.selfcalib.bundle.TrackRecorder keeps the measurements it used, its poses and
points; rscalib.selfcalib.bundle.bundle_adjust refines [f, cx, cy, k1, k2] over every 3rd frame,
started (1) from the filter's estimate and (2) from a generic camera (f = image width, c = centre,
k = 0; the filter's poses and points still start the rest). Per run: filter f error, BA f error,
whether the truth is inside the BA's 99 % bounds of each parameter, BA time.

Parts: (a) feature level: true correspondences of the rendered walks' motions
(bench_selfcalib_realistic.feature_level_source), 320x240, 0.5 px noise; (b) image level: the
cached realistic renders (bench_selfcalib_realistic.py renders them into --cache); (c) the real
desk video (truth: the offline calibration; $RSCALIB_SHARED_DATA, else ../shared/data beside the
repository: worktrees set the variable).

Usage: PYTHONPATH=python .venv/bin/python benchmarks/exp_selfcalib_bundle.py [--parts abc]
           [--sizes 320x240,640x480] [--seeds 5] [--seed0 1100] [--frames 200] [--step 3]
           [--cache /tmp/rscalib_h11_selfcalib_realistic] [--out benchmarks/results/exp_selfcalib_bundle.json]
           [--styles walk-forward,...] [--front-end default|tracked|tracked-h|...] [--audit | --audit-only]

--front-end picks the image front end's options (FRONT_ENDS); --audit-only runs the filter and
the audit of the tracks against the renderer's true pixels, without the bundle adjustment (a quick
comparison of front ends: track error by age, its radial part, the front end's CPU ms per frame).
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path
from typing import Optional

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import machine_info  # noqa: E402
from bench_selfcalib_realistic import NAMES, STYLES, feature_level_source, pixel_size_mm  # noqa: E402

from rscalib.selfcalib.bundle import TrackRecorder, bundle_adjust  # noqa: E402
from rscalib.selfcalib.calibrate import default_options, read_gray_frames  # noqa: E402
from rscalib.selfcalib.driver import run_bank  # noqa: E402
from rscalib.selfcalib.front_end import FrontEndOptions, ImageFrontEnd  # noqa: E402
from rscalib.selfcalib.prior import make_bank  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
SHARED_DATA = Path(os.environ.get("RSCALIB_SHARED_DATA", REPO.parent / "shared" / "data"))
DESK = SHARED_DATA / "real_selfcalib_s3phone" / "escritorio_traslacion.mp4"
DESK_TRUTH = {"f": 524.65, "cx": 308.6, "cy": 236.5}
DESK_PIXEL_SIZE_MM = 0.0070216


# --front-end: FrontEndOptions of the image front end (sizes for 320 px, scaled with the width)
FRONT_ENDS = {
    "default": {},
    "parabola": {"subpixel": "parabola"},
    "tracked": {"subpixel": "tracked"},
    "tracked-h": {"subpixel": "tracked", "warp_model": "homography"},
    "tracked-h8": {"subpixel": "tracked", "warp_model": "homography", "refine_half_px": 8},
    "tracked-8": {"subpixel": "tracked", "refine_half_px": 8},
    "klt": {"subpixel": "klt"},
}


class TimedSource:
    """A measurement source that adds up the CPU time of ``source``'s calls (the front end's cost)."""

    def __init__(self, source) -> None:
        self.source = source
        self.cpu_s = 0.0
        self.calls = 0

    @property
    def options(self):
        return self.source.options

    def _timed(self, name: str, *args):
        started = time.process_time()
        out = getattr(self.source, name)(*args)
        self.cpu_s += time.process_time() - started
        return out

    def measure(self, frame, ids, uv_pred, cov):
        self.calls += 1
        return self._timed("measure", frame, ids, uv_pred, cov)

    def forget(self, feature_ids) -> None:
        self.source.forget(feature_ids)

    def new_features(self, frame, count, search):
        return self._timed("new_features", frame, count, search)

    def track(self, frame, feature_ids, uv) -> None:
        self._timed("track", frame, feature_ids, uv)


def filter_and_tracks(frames, source, size: tuple[int, int], pixel_mm: float) -> tuple[np.ndarray, object, float]:
    """The bank over ``frames`` with ``source`` wrapped in a TrackRecorder: final calibration mean,
    the tracks, wall time (s)."""
    recorder = TrackRecorder(source)
    bank = make_bank(size[0], size[1], pixel_mm, options=default_options())
    started = time.perf_counter()
    history = run_bank(bank, frames, recorder, min_visible=getattr(source, "options", FrontEndOptions()).min_visible,
                       max_new_per_frame=getattr(source, "options", FrontEndOptions()).max_new_per_frame,
                       on_frame=recorder.on_frame)
    return history.mean[-1].copy(), recorder.tracks(), time.perf_counter() - started


def compare(label: dict, truth: dict, filter_mean: np.ndarray, tracks, size: tuple[int, int], pixel_mm: float,
            step: int, filter_s: float, max_track_frames: Optional[int] = None) -> dict:
    """BA from the filter and from a generic camera; errors and coverage against ``truth``."""
    row = dict(label, truth=truth, filter=dict(zip(NAMES, filter_mean.tolist())), filter_s=round(filter_s, 2),
               filter_f_error_pct=100 * (filter_mean[0] / truth["f"] - 1), observations_recorded=len(tracks))
    generic = np.array([size[0], size[0] / 2, size[1] / 2, 0.0, 0.0])
    for name, start in (("ba", filter_mean), ("ba_generic", generic)):
        try:
            ba = bundle_adjust(tracks, start, pixel_mm, keyframe_step=step, max_track_frames=max_track_frames)
        except (ValueError, np.linalg.LinAlgError) as err:   # InputError is a ValueError
            row[name] = {"error": str(err)}
            continue
        out = ba.summary_dict()
        out["f_error_pct"] = 100 * (ba.camera[0] / truth["f"] - 1)
        out["inside"] = {n: bool(ba.bounds_99[i, 0] <= truth[n] <= ba.bounds_99[i, 1])
                         for i, n in enumerate(NAMES) if n in truth}
        out["inside_tracks"] = {n: bool(ba.bounds_99_tracks[i, 0] <= truth[n] <= ba.bounds_99_tracks[i, 1])
                                for i, n in enumerate(NAMES) if n in truth}
        row[name] = out
    return row


def print_row(row: dict) -> None:
    ba, gen = row.get("ba", {}), row.get("ba_generic", {})
    print(f"{row['part']} {row.get('style', ''):15s} {row.get('size', '')} {row.get('seed', '')}: "
          f"filter f {row['filter']['f']:.1f} ({row['filter_f_error_pct']:+.1f} %)  "
          f"BA f {ba.get('f', float('nan')):.1f} ({ba.get('f_error_pct', float('nan')):+.2f} %) "
          f"[{ba.get('f_bounds_99', [np.nan] * 2)[0]:.1f}, {ba.get('f_bounds_99', [np.nan] * 2)[1]:.1f}] "
          f"inside {sum(ba.get('inside', {}).values())}/{len(ba.get('inside', {}))} "
          f"(by track [{ba.get('f_bounds_99_tracks', [np.nan] * 2)[0]:.1f}, {ba.get('f_bounds_99_tracks', [np.nan] * 2)[1]:.1f}] "
          f"{sum(ba.get('inside_tracks', {}).values())}/{len(ba.get('inside_tracks', {}))}) "
          f"sigma {ba.get('sigma_px', np.nan):.2f} px {ba.get('elapsed_s', np.nan):.1f} s | "
          f"generic f {gen.get('f', float('nan')):.1f} ({gen.get('f_error_pct', float('nan')):+.2f} %)"
          + (f" ERROR {ba['error']}" if "error" in ba else ""), flush=True)


def part_a(args) -> list[dict]:
    from rscalib.sim.scene_features import PAPER_CAMERA

    truth = dict(zip(NAMES, PAPER_CAMERA.params.tolist()))
    rows = []
    for style in STYLES:
        for seed in range(args.seed0, args.seed0 + args.seeds):
            source = feature_level_source(style, seed, args.frames)
            mean, tracks, filter_s = filter_and_tracks(source.frames(), source, (320, 240), pixel_size_mm(320))
            rows.append(compare({"part": "a", "style": style, "size": "320x240", "seed": seed}, truth, mean, tracks,
                                (320, 240), pixel_size_mm(320), args.step, filter_s, args.max_track_frames))
            print_row(rows[-1])
    return rows


def image_run(label: dict, source_path: Path, truth: dict, pixel_mm: float, step: int, audited: bool = False,
              max_track_frames: Optional[int] = None, front_end: str = "default", audit_only: bool = False) -> dict:
    """The bank with the image front end ``front_end`` (a FRONT_ENDS name), the BA (unless
    ``audit_only``) and the audit of its tracks (``audited`` or ``audit_only``)."""
    gray = read_gray_frames(source_path)
    source = TimedSource(ImageFrontEnd(FrontEndOptions(**FRONT_ENDS[front_end]), gray.image_size))
    mean, tracks, filter_s = filter_and_tracks(gray.frames, source, gray.image_size, pixel_mm)
    label = dict(label, size=f"{gray.image_size[0]}x{gray.image_size[1]}", front_end=front_end,
                 front_end_ms_per_frame=round(1e3 * source.cpu_s / max(source.calls, 1), 2))
    if audit_only:
        row = dict(label, truth=truth, filter=dict(zip(NAMES, mean.tolist())), filter_s=round(filter_s, 2),
                   filter_f_error_pct=100 * (mean[0] / truth["f"] - 1), observations_recorded=len(tracks))
        row["audit"] = track_errors(source_path, tracks)
        print_audit(row)
        return row
    row = compare(label, truth, mean, tracks, gray.image_size, pixel_mm, step, filter_s, max_track_frames)
    print_row(row)
    if audited:
        row["audit"] = audit(source_path, tracks, mean, pixel_mm, step)
    return row


def print_audit(row: dict) -> None:
    a = row["audit"]
    print(f"{row['front_end']:10s} {row['style']:15s} {row['size']} {row['seed']}: filter f {row['filter_f_error_pct']:+.1f} %"
          f", track error rms {a['rms_px']:.2f} px, >2 px {100 * a['beyond_2px']:.1f} %, by age "
          + ", ".join(f"{k}: {v['rms_px']:.2f} px radial {v['radial_per_radius']:+.1e}/px (n {v['n']})"
                      for k, v in a["by_age"].items())
          + f"; front end {row['front_end_ms_per_frame']:.1f} ms/frame", flush=True)


def true_pixels(seq: Path, tracks) -> np.ndarray:
    """The noise-free pixels of the recorded observations of a rendered sequence: each feature's
    3-D point is where the true ray of its first pixel (the corner the front end started it at) meets
    the room's box; every observation is that point projected at its row's mid-exposure time
    (rolling shutter: row v at t_s + v d + exposure / 2, v from the measured pixel)."""
    from rscalib.selfcalib.bundle import project_civera
    from rscalib.sim.scene_features import CiveraCamera
    from rscalib.sim.scene_realism import ROOM_SIZE_M, StyledRoomMotion

    truth = json.loads((seq / "truth.json").read_text())
    params, pixel_mm = np.array(truth["camera"]["params"]), float(truth["camera"]["pixel_size_mm"][0])
    motion = StyledRoomMotion(truth["style"], truth["seed"], truth["num_frames_requested"] / truth["fps"])
    t_frame = np.array([f["t_s"] for f in truth["frames"]])
    t_obs = t_frame[tracks.frame] + tracks.uv[:, 1] * truth["line_delay_s"] + 0.5 * truth["exposure_s"]
    R, p = motion.pose_cw(t_obs)
    camera = CiveraCamera(*params, width=truth["camera"]["width"], height=truth["camera"]["height"],
                          pixel_size_mm=pixel_mm)
    order = np.lexsort((tracks.frame, tracks.feature_id))
    first = order[np.r_[True, np.diff(tracks.feature_id[order]) != 0]]
    ray_c = np.c_[(camera.undistort(tracks.uv[first]) - params[1:3]) / params[0], np.ones(len(first))]
    ray_w = np.einsum("nji,nj->ni", R[first], ray_c)                  # R_cwᵀ ray
    centre = -np.einsum("nji,nj->ni", R[first], p[first])
    lx, ly, lz = ROOM_SIZE_M
    lo, hi = np.array([-lx / 2, -ly / 2, 0.0]), np.array([lx / 2, ly / 2, lz])
    with np.errstate(divide="ignore", invalid="ignore"):
        exit_t = np.where(ray_w > 0, (hi - centre) / ray_w, (lo - centre) / ray_w)
    X = centre + np.nanmin(np.where(exit_t > 0, exit_t, np.nan), axis=1)[:, None] * ray_w
    point_of = dict(zip(tracks.feature_id[first].tolist(), range(len(first))))
    Xo = X[[point_of[i] for i in tracks.feature_id.tolist()]]
    return project_civera(params, np.einsum("nij,nj->ni", R, Xo) + p, pixel_mm)


def track_errors(seq: Path, tracks) -> dict:
    """How far the front end's pixels are from the true ones: RMS, share beyond 2 px, and by track
    age (observations within 2 px): RMS and the radial component (outwards positive, from the true
    principal point), as a mean and per pixel of radius."""
    truth = json.loads((seq / "truth.json").read_text())
    params = np.array(truth["camera"]["params"])
    uv_true = true_pixels(seq, tracks)
    err = tracks.uv - uv_true
    offset = uv_true - params[1:3]
    radial = np.sum(err * offset, axis=1) / np.maximum(np.linalg.norm(offset, axis=1), 1e-9)
    first = {}
    for k, fid in zip(tracks.frame.tolist(), tracks.feature_id.tolist()):
        first.setdefault(fid, k)
    age = tracks.frame - np.array([first[i] for i in tracks.feature_id.tolist()])
    out = {"rms_px": float(np.sqrt(np.mean(err ** 2))), "beyond_2px": float(np.mean(np.linalg.norm(err, axis=1) > 2)),
           "by_age": {}}
    good = np.linalg.norm(err, axis=1) <= 2
    for lo, hi in ((1, 5), (5, 15), (15, 40), (40, 10 ** 6)):
        sel = good & (age >= lo) & (age < hi)
        if sel.any():
            out["by_age"][f"{lo}-{hi}"] = {
                "n": int(sel.sum()), "rms_px": float(np.sqrt(np.mean(err[sel] ** 2))),
                "mean_radial_px": float(np.mean(radial[sel])),
                # radial error per px of radius: a zoom of the tracks against the truth
                "radial_per_radius": float(np.sum(radial[sel] * np.linalg.norm(offset[sel], axis=1))
                                           / np.sum(np.linalg.norm(offset[sel], axis=1) ** 2))}
    return out


def audit(seq: Path, tracks, filter_mean: np.ndarray, pixel_mm: float, step: int, with_ba: bool = True) -> dict:
    """:func:`track_errors`, and the BA on the true pixels of the same observations (noise-free,
    and with 0.2 px independent noise) unless not ``with_ba``."""
    import dataclasses

    out = track_errors(seq, tracks)
    uv_true = true_pixels(seq, tracks)
    params = np.array(json.loads((seq / "truth.json").read_text())["camera"]["params"])
    rng = np.random.default_rng(7)
    truth_d = dict(zip(NAMES, params.tolist()))
    for name, uv in (("ba_true_pixels", uv_true), ("ba_true_pixels_0.2px", uv_true + rng.normal(0, 0.2, uv_true.shape))):
        try:
            ba = bundle_adjust(dataclasses.replace(tracks, uv=uv), filter_mean, pixel_mm, keyframe_step=step)
        except ValueError as err_ba:
            out[name] = {"error": str(err_ba)}
            continue
        out[name] = {"f": float(ba.camera[0]), "f_error_pct": 100 * (ba.camera[0] / params[0] - 1),
                     "f_bounds_99": ba.bounds_99[0].tolist(), "sigma_px": ba.sigma_px,
                     "inside": {n: bool(ba.bounds_99[i, 0] <= truth_d[n] <= ba.bounds_99[i, 1])
                                for i, n in enumerate(NAMES)}}
    print(f"  audit: rms {out['rms_px']:.2f} px, >2 px {100 * out['beyond_2px']:.1f} %, by age "
          + ", ".join(f"{k}: {v['rms_px']:.2f} px radial {v['mean_radial_px']:+.3f} ({v['radial_per_radius']:+.2e}/px)"
                      for k, v in out["by_age"].items())
          + f"; BA on true pixels f {out['ba_true_pixels'].get('f_error_pct', np.nan):+.2f} %, "
          f"+0.2 px noise {out['ba_true_pixels_0.2px'].get('f_error_pct', np.nan):+.2f} %", flush=True)
    return out


def part_b(args) -> list[dict]:
    rows = []
    for size in args.sizes.split(","):
        for style in args.styles.split(","):
            for seed in range(args.seed0, args.seed0 + args.seeds):
                seq = Path(args.cache) / f"{style}_{size}_s{seed}_n{args.frames}"
                if not (seq / "truth.json").exists():
                    print(f"missing {seq} (render it with bench_selfcalib_realistic.py)", flush=True)
                    continue
                camera = json.loads((seq / "truth.json").read_text())["camera"]
                truth = dict(zip(NAMES, camera["params"]))
                rows.append(image_run({"part": "b", "style": style, "seed": seed}, seq, truth,
                                      float(camera["pixel_size_mm"][0]), args.step, args.audit, args.max_track_frames,
                                      args.front_end, args.audit_only))
    return rows


def part_c(args) -> list[dict]:
    return [image_run({"part": "c", "style": "desk video", "seed": None}, DESK, DESK_TRUTH, DESK_PIXEL_SIZE_MM,
                      args.step, max_track_frames=args.max_track_frames, front_end=args.front_end)]


def _groups(rows: list[dict], by_style: bool = True) -> dict:
    """Rows with a BA result by (part, front end, style, size); style "all" unless ``by_style``."""
    out: dict = {}
    for r in rows:
        if "f" in r.get("ba", {}):
            key = (r["part"], r.get("front_end", "default"), r.get("style") if by_style else "all", r.get("size"))
            out.setdefault(key, []).append(r)
    return dict(sorted(out.items(), key=lambda item: str(item[0])))


def _summary_of(group: list[dict]) -> dict:
    inside = {n: sum(r["ba"]["inside"].get(n, False) for r in group) for n in NAMES if n in group[0]["ba"]["inside"]}
    return {
        "runs": len(group),
        "filter_f_error_pct": [round(r["filter_f_error_pct"], 2) for r in group],
        "ba_f_error_pct": [round(r["ba"]["f_error_pct"], 2) for r in group],
        "ba_f_within_2pct": sum(abs(r["ba"]["f_error_pct"]) <= 2 for r in group),
        "ba_inside_99": inside,
        "ba_inside_all": sum(all(r["ba"]["inside"].values()) for r in group),
        "ba_inside_99_tracks": {n: sum(r["ba"]["inside_tracks"].get(n, False) for r in group) for n in inside},
        "ba_inside_all_tracks": sum(all(r["ba"]["inside_tracks"].values()) for r in group),
        "ba_generic_f_error_pct": [round(r["ba_generic"].get("f_error_pct", np.nan), 2) for r in group],
        "ba_generic_same": sum(abs(r["ba_generic"].get("f", np.inf) / r["ba"]["f"] - 1) <= 0.005 for r in group),
        "ba_median_s": float(np.median([r["ba"]["elapsed_s"] for r in group])),
        "filter_median_s": float(np.median([r["filter_s"] for r in group])),
    }


def summarise(rows: list[dict]) -> dict:
    return {" ".join(str(k) for k in key): _summary_of(group)
            for grouping in (True, False) for key, group in _groups(rows, grouping).items()}


def table(rows: list[dict]) -> str:
    """Markdown: one line per part/front end/style/size, then per part/front end/size."""
    lines = ["| part | front end | style | size | runs | filter median abs f err % | BA median (max) abs f err % "
             "| BA f within 2 % | BA truth in 99 % f/cx/cy/k1/k2 (model) | (by track) "
             "| generic start lands within 0.5 % of BA | BA median s |", "|" + " --- |" * 12]
    for grouping in (True, False):
        for (part, front_end, style, size), group in _groups(rows, grouping).items():
            g = _summary_of(group)
            inside = "/".join(str(v) for v in g["ba_inside_99"].values())
            inside_t = "/".join(str(v) for v in g["ba_inside_99_tracks"].values())
            lines.append(f"| {part} | {front_end} | {style} | {size} | {g['runs']} "
                         f"| {np.median(np.abs(g['filter_f_error_pct'])):.1f} "
                         f"| {np.median(np.abs(g['ba_f_error_pct'])):.2f} ({np.max(np.abs(g['ba_f_error_pct'])):.2f}) "
                         f"| {g['ba_f_within_2pct']} | {inside} | {inside_t} | {g['ba_generic_same']} "
                         f"| {g['ba_median_s']:.1f} |")
    return "\n".join(lines)


def audit_table(rows: list[dict]) -> str:
    """Markdown: the audit of the tracks per front end and size (medians over the runs)."""
    bands = ("1-5", "5-15", "15-40", "40-1000000")
    lines = ["| front end | size | runs | track error RMS px by age 1-5 / 5-15 / 15-40 / 40+ (median; max at 40+) "
             "| abs radial per px of radius at 40+ (median; max) | > 2 px | front end CPU ms/frame |", "|" + " --- |" * 7]
    for key in sorted({(r.get("front_end", "default"), r.get("size")) for r in rows if "audit" in r}, key=str):
        group = [r for r in rows if "audit" in r and (r.get("front_end", "default"), r.get("size")) == key]
        by_age = [[r["audit"]["by_age"][b] for r in group if b in r["audit"]["by_age"]] for b in bands]
        radial = [abs(a["radial_per_radius"]) for a in by_age[-1]]
        cost = [r["front_end_ms_per_frame"] for r in group if "front_end_ms_per_frame" in r]
        lines.append(f"| {key[0]} | {key[1]} | {len(group)} | "
                     + " / ".join(f"{np.median([a['rms_px'] for a in band]):.2f}" for band in by_age)
                     + f" ({max(a['rms_px'] for a in by_age[-1]):.2f}) | {np.median(radial):.1e} ({max(radial):.1e}) "
                     f"| {100 * np.mean([r['audit']['beyond_2px'] for r in group]):.2f} % "
                     f"| {np.median(cost) if cost else float('nan'):.1f} |")
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--parts", default="abc")
    ap.add_argument("--sizes", default="320x240,640x480")
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--seed0", type=int, default=1100)
    ap.add_argument("--frames", type=int, default=200)
    ap.add_argument("--step", type=int, default=3, help="keyframe every STEP frames")
    ap.add_argument("--cache", default="/tmp/rscalib_h11_selfcalib_realistic")
    ap.add_argument("--out", default=str(REPO / "benchmarks" / "results" / "exp_selfcalib_bundle.json"))
    ap.add_argument("--max-track-frames", type=int, default=None,
                    help="cut tracks into points of at most this many frames (bundle_adjust's max_track_frames)")
    ap.add_argument("--audit", action="store_true",
                    help="part b: also compare the tracks with the true pixels and run the BA on those")
    ap.add_argument("--table", nargs="*", metavar="JSON", help="only print the table of these result files")
    ap.add_argument("--styles", default=",".join(STYLES), help="part b: these motion styles")
    ap.add_argument("--front-end", default="default", choices=sorted(FRONT_ENDS),
                    help="parts b, c: the image front end's options (FRONT_ENDS)")
    ap.add_argument("--audit-only", action="store_true",
                    help="part b: only the filter and the track errors of --audit (no bundle adjustment)")
    args = ap.parse_args()
    if args.table is not None:
        rows = [r for path in args.table for r in json.loads(Path(path).read_text())["runs"]]
        print(table(rows))
        if any("audit" in r for r in rows):
            print("\n" + audit_table(rows))
        return
    started = time.perf_counter()
    rows: list[dict] = []
    for part, run in (("a", part_a), ("b", part_b), ("c", part_c)):
        if part in args.parts:
            if part == "b" and args.audit_only:
                rows += run(args)
                Path(args.out).write_text(json.dumps({"experiment": "exp_selfcalib_bundle (front-end audit)",
                                                      "args": vars(args), "machine": machine_info(),
                                                      "command": " ".join(sys.argv), "runs": rows}, indent=1,
                                                     default=float))
                continue
            rows += run(args)
            doc = {"experiment": "exp_selfcalib_bundle", "args": vars(args), "machine": machine_info(),
                   "command": " ".join(sys.argv), "total_wall_s": round(time.perf_counter() - started, 1),
                   "load_average_at_end": os.getloadavg(), "summary": summarise(rows), "runs": rows}
            Path(args.out).write_text(json.dumps(doc, indent=1, default=float))
    print(json.dumps(summarise(rows), indent=1, default=float))


if __name__ == "__main__":
    main()
