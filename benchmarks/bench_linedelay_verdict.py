"""The line-delay verdict as a classifier (issue 31): realistic renders with known faults next to clean
ones, each run through the front door (rscalib.calibrate_video), with the verdict, the error in sigma and
the named first cause recorded; the confusion table and the bars of docs/benchmarks.md.

    .venv/bin/python benchmarks/bench_linedelay_verdict.py --seed0 3100 --render   # render the videos (slow)
    .venv/bin/python benchmarks/bench_linedelay_verdict.py --seed0 3100            # run, judge, summarise
    .venv/bin/python benchmarks/bench_linedelay_verdict.py --seed0 3100 --rejudge  # judge the stored evidence again

A seed set is `base` moving videos (hand-held, shake, sweep; 640x480, 854x480 and 1280x720 through three
cameras; 24 and 30 fps; d 20-40 us/row; rscalib.sim.realism with motion blur, a board on a screen, noise,
frame-time jitter and drops), rendered once without compression (cached in --videos), plus near-static
videos and videos whose second half shakes at 12-25 Hz (motion a spline of half-frame knots cannot follow).
Every base video is run with its exact camera (clean) and with about three of these faults:

    camera f +3 %, -3 %, +6 %, -6 %; principal point +15 px; distortion dropped (camera file)
    target squares x0.75; target in millimetres (target file)
    digital stabilisation: each frame shifted to cancel the fast part of the board's image motion
    re-encoded at 0.04 bit/pixel (a messaging app) instead of the phone's 0.22

The encodings are H.264 through imageio-ffmpeg (the phone's; `pip install 'rscalib[bench]'`).
A fault's *cause* is what the verdict should name first (judge.CAUSES). The bars: trusted-and-wrong
(|error| > 3 sigma while trusted) <= 1 % of the runs, clean videos not trusted <= 5 %, and the first
cause named right in >= 80 % of the faulty runs, counted two ways: of the runs the verdict does not trust
(their first reason), and of every faulty run (a trusted run names a fault that did not bend d in a
caveat: judge.Diagnosis.named_cause; a clean run should name none). Runs with the advice
--refine-intrinsics are re-run with it, and whether that helped is counted (advice only where it helps).
Results: benchmarks/results/bench_linedelay_verdict_<seed0>.json.
"""
from __future__ import annotations

import argparse
import contextlib
import json
import math
import sys
import time
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
import yaml

import rscalib
from rscalib.sim import realism
from rscalib.sim.trajectories import CameraMotion, SinusoidBank, calm_then_wild

STYLES = ("handheld", "shake", "sweep")
# (size, camera params [fx, fy, cx, cy, k1, k2, p1, p2, k3]) -- three cameras
CAMERAS = (((640, 480), [500.0, 500.0, 319.5, 239.5, -0.1, 0.05, 0.0, 0.0, 0.0]),
           ((854, 480), [600.0, 600.0, 426.5, 239.5, -0.25, 0.08, 0.0, 0.0, 0.0]),
           ((1280, 720), [900.0, 900.0, 639.5, 359.5, -0.05, 0.02, 0.0, 0.0, 0.0]))
FPS = (30.0, 24.0)
DELAYS_US = (20.0, 30.0, 40.0)
FAULTS = ("f+3%", "f-3%", "f+6%", "f-6%", "pp+15px", "no-distortion", "size x0.75", "size mm",
          "stabilised", "re-encoded")
# what the verdict should name first for each fault (None: the video is fine)
EXPECTED_CAUSE = {"clean": None, "f+3%": "camera", "f-3%": "camera", "f+6%": "camera", "f-6%": "camera",
                  "pp+15px": "camera", "no-distortion": "camera", "size x0.75": "target_size",
                  "size mm": "target_size", "stabilised": "stabilisation", "re-encoded": "compression",
                  "near-static": "motion", "wild half": "motion"}
PHONE_BPP, LOW_BPP = 0.22, 0.04


# ------------------------------------------------------------------------------------ the videos

def base_cases(seed0: int, base: int, static: int, wild: int) -> list[dict]:
    out = []
    for k in range(base):
        size, params = CAMERAS[{1: 1, 4: 2}.get(k % 6, 0)]
        fps = FPS[(k // 3) % 2] if size != (1280, 720) else 30.0
        out.append({"name": f"b{k:02d}", "seed": seed0 + k, "kind": "base", "style": STYLES[k % 3], "size": size,
                    "camera": params, "fps": fps,
                    # readout + exposure within the frame period: 1280x720 at most 30 us/row
                    "line_delay_us": min(DELAYS_US[(k // 2) % 3], 30.0 if size == (1280, 720) else 99.0),
                    "duration_s": 3.0 if size == (1280, 720) else 4.0})
    for k in range(static):
        size, params = CAMERAS[k % 2]
        out.append({"name": f"s{k:02d}", "seed": seed0 + 200 + k, "kind": "near-static", "style": "near-static",
                    "size": size, "camera": params, "fps": 30.0, "line_delay_us": 30.0, "duration_s": 4.0})
    for k in range(wild):
        size, params = CAMERAS[k % 2]
        out.append({"name": f"w{k:02d}", "seed": seed0 + 300 + k, "kind": "wild half", "style": STYLES[k % 3],
                    "size": size, "camera": params, "fps": 30.0, "line_delay_us": 30.0, "duration_s": 4.0})
    return out


class VibratingSecondHalf(CameraMotion):
    """A hand-held motion whose second half adds a 12-25 Hz vibration (a camera on a running engine, a
    shaking hand): faster than a spline with knots half a frame apart can follow."""

    def __init__(self, base, duration_s: float, seed: int, peak_deg: float = 0.6) -> None:
        self.base = base
        rng = np.random.default_rng([0x56494252, seed])
        self.bank = SinusoidBank.draw(rng, 3, 3, (12.0, 25.0), np.radians([peak_deg, peak_deg, 0.5 * peak_deg]))
        self.profile = calm_then_wild(duration_s, calm=0.0, wild=1.0, transition_s=0.2)

    def _pose(self, t_s):
        R, centre = self.base._pose(t_s)
        from scipy.spatial.transform import Rotation

        shake = Rotation.from_rotvec(self.bank(t_s) * self.profile(t_s)[:, None]).as_matrix()
        return np.einsum("nij,njk->nik", shake, R), centre


@contextlib.contextmanager
def _vibrating_motion(seed: int):
    """render_realistic_video with the VibratingSecondHalf of its motion (the renderer takes a style,
    not a trajectory: its motion_trajectory is wrapped for the duration of the render)."""
    original = realism.motion_trajectory

    def motion(camera, target, duration_s, s, style):
        return VibratingSecondHalf(original(camera, target, duration_s, s, style), duration_s, seed)

    realism.motion_trajectory = motion
    try:
        yield
    finally:
        realism.motion_trajectory = original


def render(case: dict, videos: Path) -> Path:
    """The uncompressed render of a case (frames/ PNG + timestamps.txt, truth.json, camera.yaml)."""
    folder = videos / case["name"]
    if (folder / "truth.json").is_file():
        return folder
    camera = rscalib.CameraModel("pinhole-radtan", case["camera"], *case["size"])
    options = realism.RealismOptions(codec="none", exposure_samples=3)
    wrap = _vibrating_motion(case["seed"]) if case["kind"] == "wild half" else contextlib.nullcontext()
    with wrap:
        realism.render_realistic_video(folder, line_delay_s=case["line_delay_us"] * 1e-6, fps=case["fps"],
                                       duration_s=case["duration_s"], seed=case["seed"], motion_style=case["style"],
                                       camera=camera, options=options, supersample=1, workers=2)
    return folder


# ------------------------------------------------------------------------------------ the encodings

def _ffmpeg() -> str:
    try:
        import imageio_ffmpeg  # the phone's H.264 (libx264)
    except ImportError:
        sys.exit("bench_linedelay_verdict: the phone's H.264 needs imageio-ffmpeg: pip install 'rscalib[bench]'")
    return imageio_ffmpeg.get_ffmpeg_exe()


def _frames(folder: Path) -> tuple[list, np.ndarray]:
    names = sorted((folder / "frames").glob("frame_*.png"))
    times = np.loadtxt(folder / "frames" / "timestamps.txt", ndmin=1)
    return names, times


def _encode(images: list, times: np.ndarray, fps: float, bits_per_pixel: float, out: Path, work: Path) -> Path:
    """PNG frames at their recorded times -> H.264 (baseline, a key frame a second) at the given bitrate, the
    frame times kept in the container (variable frame rate, as a phone's)."""
    import subprocess

    work.mkdir(parents=True, exist_ok=True)
    # each image a 1/90000 s stream (option framerate) lasting until the next frame's time (duration):
    # the container then carries the recorded times (to 1/90000 s)
    lines = ["ffconcat version 1.0"]
    for i, image in enumerate(images):
        lines += [f"file '{Path(image).resolve()}'", "option framerate 90000",
                  f"duration {(times[i + 1] - times[i]) if i + 1 < len(times) else 1.0 / fps:.9f}"]
    (work / "list.txt").write_text("\n".join(lines) + "\n")
    h, w = cv2.imread(str(images[0]), cv2.IMREAD_GRAYSCALE).shape
    rate = int(bits_per_pixel * w * h * fps)
    subprocess.run([_ffmpeg(), "-hide_banner", "-loglevel", "error", "-y", "-f", "concat", "-safe", "0",
                    "-i", str(work / "list.txt"), "-fps_mode", "passthrough", "-video_track_timescale", "90000",
                    "-c:v", "libx264", "-preset", "fast", "-profile:v", "baseline", "-b:v", str(rate),
                    "-maxrate", str(int(1.5 * rate)), "-bufsize", str(2 * rate), "-g", str(int(round(fps))),
                    "-pix_fmt", "yuv420p", str(out)], check=True)
    return out


def phone_video(folder: Path, fps: float) -> Path:
    out = folder / "phone.mp4"
    if not out.is_file():
        names, times = _frames(folder)
        _encode(names, times, fps, PHONE_BPP, out, folder / "work_phone")
    return out


def reencoded_video(folder: Path, fps: float) -> Path:
    """The phone's video re-encoded at LOW_BPP (a messaging app), its frame times kept."""
    import subprocess

    out = folder / "reencoded.mp4"
    if not out.is_file():
        source = phone_video(folder, fps)
        h, w = cv2.imread(str(_frames(folder)[0][0]), cv2.IMREAD_GRAYSCALE).shape
        rate = int(LOW_BPP * w * h * fps)
        subprocess.run([_ffmpeg(), "-hide_banner", "-loglevel", "error", "-y", "-i", str(source), "-fps_mode",
                        "passthrough", "-video_track_timescale", "90000", "-c:v", "libx264", "-preset", "fast",
                        "-b:v", str(rate), "-maxrate", str(int(1.5 * rate)), "-bufsize", str(2 * rate),
                        "-pix_fmt", "yuv420p", str(out)], check=True)
    return out


def stabilisation_shifts(truth: dict, sigma_frames: float = 4.0, limit_px: float = 40.0) -> np.ndarray:
    """(n, 2) per-frame image shifts that move the board's image centre onto its smoothed path: what an
    electronic stabiliser does (it cancels the fast part of the motion by shifting the frame)."""
    uv = truth["projections"]["uv_rs_mid_exposure"]
    centre = np.array([np.nanmean(np.array([p if p is not None else [np.nan, np.nan] for p in f], float), axis=0)
                       for f in uv])
    for k in range(2):   # frames without the board: their neighbours' centre
        bad = ~np.isfinite(centre[:, k])
        if bad.any() and (~bad).any():
            centre[bad, k] = np.interp(np.flatnonzero(bad), np.flatnonzero(~bad), centre[~bad, k])
    radius = int(3 * sigma_frames)
    kernel = np.exp(-0.5 * (np.arange(-radius, radius + 1) / sigma_frames) ** 2)
    padded = np.pad(centre, ((radius, radius), (0, 0)), mode="edge")
    smooth = np.stack([np.convolve(padded[:, k], kernel / kernel.sum(), mode="valid") for k in range(2)], axis=1)
    return np.clip(smooth - centre, -limit_px, limit_px)


def stabilised_video(folder: Path, fps: float) -> Path:
    out = folder / "stabilised.mp4"
    if not out.is_file():
        names, times = _frames(folder)
        shifts = stabilisation_shifts(json.loads((folder / "truth.json").read_text()))
        work = folder / "work_stabilised"
        work.mkdir(parents=True, exist_ok=True)
        shifted = []
        for name, (dx, dy) in zip(names, shifts):
            image = cv2.imread(str(name), cv2.IMREAD_GRAYSCALE)
            m = np.array([[1.0, 0.0, dx], [0.0, 1.0, dy]])
            path = work / name.name
            cv2.imwrite(str(path), cv2.warpAffine(image, m, image.shape[::-1], flags=cv2.INTER_LINEAR,
                                                  borderMode=cv2.BORDER_REFLECT))
            shifted.append(path)
        _encode(shifted, times, fps, PHONE_BPP, out, work)
    return out


# ------------------------------------------------------------------------------------ the runs

def runs_of(cases: list[dict], faults_per_base: int) -> list[dict]:
    """Every run: each base video clean and with `faults_per_base` faults (in rotation), the near-static
    and the vibrating videos as they are."""
    out = []
    for k, case in enumerate(c for c in cases if c["kind"] == "base"):
        out.append(case | {"fault": "clean"})
        for j in range(faults_per_base):
            out.append(case | {"fault": FAULTS[(k * faults_per_base + j) % len(FAULTS)]})
    out += [c | {"fault": c["kind"]} for c in cases if c["kind"] != "base"]
    return out


def _camera_of(run: dict):
    p = list(run["camera"])
    fault = run["fault"]
    if fault.startswith("f") and fault.endswith("%"):
        scale = 1.0 + float(fault[1:-1]) / 100.0
        p[0] *= scale
        p[1] *= scale
    elif fault == "pp+15px":
        p[2] += 15.0
        p[3] += 15.0
    elif fault == "no-distortion":
        p[4:] = [0.0] * len(p[4:])
    return rscalib.CameraModel("pinhole-radtan", p, *run["size"])


def _target_of(run: dict, folder: Path) -> Path:
    scale = {"size x0.75": 0.75, "size mm": 1000.0}.get(run["fault"])
    if scale is None:
        return folder / "target.yaml"
    data = yaml.safe_load((folder / "target.yaml").read_text())
    for key in ("rowSpacingMeters", "colSpacingMeters"):
        data[key] = float(data[key]) * scale
    out = folder / f"target_{run['fault'].replace(' ', '_')}.yaml"
    out.write_text(yaml.safe_dump(data, sort_keys=False))
    return out


def _video_of(run: dict, folder: Path) -> Path:
    if run["fault"] == "stabilised":
        return stabilised_video(folder, run["fps"])
    if run["fault"] == "re-encoded":
        return reencoded_video(folder, run["fps"])
    return phone_video(folder, run["fps"])


def _record(run: dict, out, truth_s: float) -> dict:
    verdict = out.verdict
    d, std = out.result.line_delay_s, out.result.line_delay_std_s
    diagnosis = out.diagnosis
    return {"status": verdict.status, "exit": verdict.exit_code, "d_us": d * 1e6,
            "std_us": std * 1e6 if math.isfinite(std) else None,
            "z": (d - truth_s) / std if math.isfinite(std) and std > 0 else None,
            "rel_err": (d - truth_s) / truth_s, "first_cause": diagnosis.first_cause, "causes": diagnosis.causes,
            "named_cause": diagnosis.named_cause, "reasons": list(verdict.reasons), "caveats": list(verdict.caveats), "evidence": diagnosis.evidence,
            "advice": list((out.guidance or {}).get("advice", []))}


def run_one(run: dict, videos: Path, cache: Path) -> dict:
    folder = videos / run["name"]
    truth_s = run["line_delay_us"] * 1e-6
    options = rscalib.LineDelayOptions(detection=rscalib.DetectOptions(cache_dir=cache))
    row = {k: v for k, v in run.items() if k != "camera"}
    started = time.perf_counter()
    try:
        video, target, camera = _video_of(run, folder), _target_of(run, folder), _camera_of(run)
        out = rscalib.calibrate_video(video, target, camera, options)
    except rscalib.InputError as error:
        return row | {"status": "input error", "exit": 2, "error": str(error), "seconds": time.perf_counter() - started}
    row |= _record(run, out, truth_s) | {"seconds": time.perf_counter() - started}
    if any("--refine-intrinsics" in r for r in out.verdict.reasons):
        # the advice is measured before it is given: run what it says, and count whether it helped
        started = time.perf_counter()
        try:
            refined = rscalib.calibrate_video(video, target, camera, replace(options, refine_intrinsics=True))
            row["refined"] = _record(run, refined, truth_s) | {"seconds": time.perf_counter() - started}
        except rscalib.InputError as error:
            row["refined"] = {"status": "input error", "exit": 2, "error": str(error)}
    return row


# ------------------------------------------------------------------------------------ the table

def rejudge(rows: list[dict]) -> list[dict]:
    """The verdicts of the stored evidence under the current rules (judge.diagnose_evidence)."""
    from rscalib.linedelay.judge import diagnose_evidence

    out = []
    for row in rows:
        if "evidence" not in row:
            out.append(row)
            continue
        diagnosis = diagnose_evidence(row["evidence"])
        row = dict(row, status=diagnosis.verdict.status, exit=diagnosis.verdict.exit_code,
                   first_cause=diagnosis.first_cause, causes=diagnosis.causes, named_cause=diagnosis.named_cause,
                   reasons=list(diagnosis.verdict.reasons), caveats=list(diagnosis.verdict.caveats))
        out.append(row)
    return out


def wrong(row: dict) -> bool:
    return row.get("z") is not None and abs(row["z"]) > 3.0


def summarise(rows: list[dict]) -> dict:
    classes = ["clean"] + list(FAULTS) + ["near-static", "wild half"]
    table = {}
    for fault in classes:
        mine = [r for r in rows if r["fault"] == fault]
        if not mine:
            continue
        flagged = [r for r in mine if r["status"] in ("not trusted", "not determined")]
        table[fault] = {
            "runs": len(mine),
            "trusted, within 3 sigma": sum(r["status"] == "trusted" and not wrong(r) for r in mine),
            "trusted, > 3 sigma off": sum(r["status"] == "trusted" and wrong(r) for r in mine),
            "not trusted": sum(r["status"] == "not trusted" for r in mine),
            "not determined": sum(r["status"] == "not determined" for r in mine),
            "input error": sum(r["status"] == "input error" for r in mine),
            "first cause right": sum(r.get("first_cause") == EXPECTED_CAUSE[fault] for r in flagged),
            "flagged": len(flagged),
            "wrong (> 3 sigma)": sum(wrong(r) for r in mine),
            "first causes": sorted({str(r.get("first_cause")) for r in flagged}),
            # what the verdict names first on every run, trusted ones included (their caveats)
            "named cause right": sum(r.get("named_cause") == EXPECTED_CAUSE[fault] for r in mine),
            "named causes": sorted({str(r.get("named_cause")) for r in mine}),
        }
    estimated = [r for r in rows if r["status"] != "input error"]
    faulty = [r for r in rows if r["fault"] != "clean"]
    faulty_flagged = [r for r in faulty if r["status"] in ("not trusted", "not determined")]
    clean = [r for r in rows if r["fault"] == "clean"]
    # advised: the verdict's reasons (re-judged ones too) say --refine-intrinsics; the outcome is the stored re-run
    advised = [r for r in rows if "refined" in r and any("--refine-intrinsics" in x for x in r.get("reasons", []))]
    helped = [r for r in advised if r["refined"].get("status") == "trusted" and not wrong(r["refined"])]
    not_advised = [r for r in rows if "refined" in r and r not in advised]
    trusted = [r for r in rows if r["status"] == "trusted"]
    return {
        "runs": len(rows), "table": table,
        "trusted_and_wrong": sum(r["status"] == "trusted" and wrong(r) for r in rows),
        "trusted_and_wrong_fraction_of_runs": sum(r["status"] == "trusted" and wrong(r) for r in rows) / max(1, len(estimated)),
        "trusted_and_wrong_fraction_of_trusted": sum(wrong(r) for r in trusted) / max(1, len(trusted)),
        "clean_not_trusted": sum(r["status"] != "trusted" for r in clean),
        "clean_not_trusted_fraction": sum(r["status"] != "trusted" for r in clean) / max(1, len(clean)),
        "faulty_flagged": len(faulty_flagged),
        "first_cause_right": sum(r.get("first_cause") == EXPECTED_CAUSE[r["fault"]] for r in faulty_flagged),
        "first_cause_right_fraction": sum(r.get("first_cause") == EXPECTED_CAUSE[r["fault"]] for r in faulty_flagged)
        / max(1, len(faulty_flagged)),
        # the same over every faulty run, trusted ones included (those name no cause: most are right, a
        # harmless fault -- a board declared 0.75x its size gives the same d)
        "faulty_runs": len(faulty),
        "first_cause_right_of_all_faulty_fraction": sum(r.get("first_cause") == EXPECTED_CAUSE[r["fault"]]
                                                        for r in faulty_flagged) / max(1, len(faulty)),
        # the cause named first on every faulty run: a trusted run names it in a caveat (a fault that did
        # not bend d beyond its error bar); a clean run should name none
        "named_cause_right": sum(r.get("named_cause") == EXPECTED_CAUSE[r["fault"]] for r in faulty),
        "named_cause_right_of_all_faulty_fraction": sum(r.get("named_cause") == EXPECTED_CAUSE[r["fault"]]
                                                        for r in faulty) / max(1, len(faulty)),
        "clean_with_a_cause_named": sum(r.get("named_cause") is not None for r in clean),
        "faulty_wrong": sum(wrong(r) for r in faulty),
        "faulty_wrong_flagged": sum(wrong(r) and r["status"] != "trusted" for r in faulty),
        "refine_advised": len(advised), "refine_helped": len(helped),
        "refine_trusted_and_wrong": sum(r["refined"].get("status") == "trusted" and wrong(r["refined"]) for r in advised),
        # re-runs of advice the rules no longer give, and how many of those would have helped
        "refine_no_longer_advised": len(not_advised),
        "refine_no_longer_advised_would_have_helped": sum(r["refined"].get("status") == "trusted"
                                                          and not wrong(r["refined"]) for r in not_advised),
    }


def markdown(summary: dict) -> str:
    head = ["fault", "runs", "trusted, within 3σ", "trusted, > 3σ off", "not trusted", "not determined",
            "input error", "first cause right (of flagged)", "first causes named", "named cause right (all runs)",
            "named first (all runs)"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for fault, t in summary["table"].items():
        lines.append(f"| {fault} | {t['runs']} | {t['trusted, within 3 sigma']} | {t['trusted, > 3 sigma off']} | "
                     f"{t['not trusted']} | {t['not determined']} | {t['input error']} | "
                     f"{t['first cause right']}/{t['flagged']} | {', '.join(t['first causes'])} | "
                     f"{t.get('named cause right', '')}/{t['runs']} | {', '.join(t.get('named causes', []))} |")
    return "\n".join(lines)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed0", type=int, default=3100, help="first seed of the set (tune on one, report another)")
    parser.add_argument("--base", type=int, default=12, help="moving videos, each run clean and with faults")
    parser.add_argument("--faults-per-base", type=int, default=6)
    parser.add_argument("--static", type=int, default=3)
    parser.add_argument("--wild", type=int, default=3)
    parser.add_argument("--videos", type=Path, default=Path("/tmp/rscalib_bench_verdict"))
    parser.add_argument("--render", action="store_true", help="render missing videos, then stop")
    parser.add_argument("--rejudge", action="store_true", help="judge the stored evidence again, no solving")
    parser.add_argument("--rerun-camera-check", action="store_true",
                        help="solve again the stored runs the camera check would run on, then judge all again")
    parser.add_argument("--only", default=None, help="comma-separated video names")
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args()
    videos = args.videos / f"set{args.seed0}"
    out_path = args.out or Path(__file__).parent / "results" / f"bench_linedelay_verdict_{args.seed0}.json"
    cases = base_cases(args.seed0, args.base, args.static, args.wild)
    if args.render:
        for case in cases:
            started = time.perf_counter()
            render(case, videos)
            print(f"{case['name']}: {time.perf_counter() - started:.0f} s", flush=True)
        return 0
    if args.rejudge or args.rerun_camera_check:
        rows = json.loads(out_path.read_text())["runs"]
        if args.rerun_camera_check:
            # runs stored without a camera check: solve again those it runs on (every determined one)
            by_name = {c["name"]: c for c in cases}
            for i, row in enumerate(rows):
                evidence = row.get("evidence") or {}
                if evidence.get("determined") and not evidence.get("camera_check"):
                    rows[i] = run_one(by_name[row["name"]] | {"fault": row["fault"]}, videos, args.videos / "cache")
                    print(json.dumps({k: rows[i].get(k) for k in ("name", "fault", "status", "z", "first_cause")}),
                          flush=True)
        rows = rejudge(rows)
    else:
        todo = runs_of(cases, args.faults_per_base)
        if args.only:
            todo = [r for r in todo if r["name"] in set(args.only.split(","))]
        rows = []
        for run in todo:
            if not (videos / run["name"] / "truth.json").is_file():
                print(f"{run['name']}: not rendered (run with --render)", file=sys.stderr)
                continue
            row = run_one(run, videos, args.videos / "cache")
            rows.append(row)
            partial = Path("/tmp") / (out_path.stem + ".partial.json")
            partial.parent.mkdir(parents=True, exist_ok=True)
            partial.write_text(json.dumps({"runs": rows}, default=str))
            print(json.dumps({k: row.get(k) for k in ("name", "fault", "status", "z", "first_cause", "seconds")}
                             | {"refined": (row.get("refined") or {}).get("status")}), flush=True)
    summary = summarise(rows)
    table = markdown(summary)
    print(table)
    print(json.dumps({k: v for k, v in summary.items() if k != "table"}, indent=1))
    out_path.parent.mkdir(parents=True, exist_ok=True)
    out_path.write_text(json.dumps({"summary": summary, "table_markdown": table, "runs": rows}, indent=1,
                                   default=str))
    return 0


if __name__ == "__main__":
    sys.exit(main())
