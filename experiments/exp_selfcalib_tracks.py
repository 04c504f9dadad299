"""How good are the bundle adjustment's tracks? (issue 30; docs/sog.md §22)

rscalib.track_features (the self-calibration front end's tracker) over

- the realistic renders of docs/sog.md §16 (rscalib.sim.scene_realism: photographic tiles, rolling
  shutter, blur, auto-exposure, noise, frame jitter, H.264; walk-forward, look-around,
  sideways-dolly; 320x240 and 640x480), rendered into --cache when missing, audited against the
  renderer's truth (rscalib.sim.scene_truth.RenderTruth: each track's 3-D point is the one under its
  first observation; every later observation is compared with that point's pixel at its own row
  time): track count, lengths, error by track age (RMS of the observations within 2 px, and the
  radial systematic part: the mean radial error per pixel of radius from the principal point, a
  zoom of the tracks against the truth), outliers (> 2 px) that survive, re-identification count
  and precision, CPU ms per frame (OpenCV on one thread);
- the real desk video (../shared/data/real_selfcalib_s3phone/escritorio_traslacion.mp4; no truth):
  track count, lengths, the epipolar (Sampson) error of the tracks between frames k and k + 10
  against a fundamental matrix fitted to them by LMedS, CPU ms per frame; also the video played
  forth and back twice (~1400 frames) for the speed over a long sequence.

--variant picks TrackOptions (VARIANTS: e.g. no-anchor, to measure what anchoring does); --filter also
audits the filter's own tracks (the SOG bank with the image front end "tracked", docs/sog.md §19,
through benchmarks/exp_selfcalib_bundle.py) on the same renders.

Usage (after `make install`): RSCALIB_SHARED_DATA=../shared/data OMP_NUM_THREADS=1 .venv/bin/python
           experiments/exp_selfcalib_tracks.py [--sizes 320x240,640x480] [--styles walk-forward,...]
           [--seeds 3] [--seed0 1100] [--frames 200] [--cache /tmp/rscalib_h11_selfcalib_realistic]
           [--variant default|no-anchor|reanchor|no-reid|magsac|fast] [--filter] [--desk] [--no-renders]
           [--out benchmarks/results/exp_selfcalib_tracks.json]
       ... experiments/exp_selfcalib_tracks.py --table FILE [FILE ...]   (the markdown tables)
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import cv2
import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "benchmarks"))
from _common import machine_info, write_results  # noqa: E402

from rscalib import TrackOptions, TrackSet, read_gray_frames, track_features  # noqa: E402

SHARED_DATA = Path(os.environ.get("RSCALIB_SHARED_DATA", REPO.parent / "shared" / "data"))
DESK = SHARED_DATA / "real_selfcalib_s3phone" / "escritorio_traslacion.mp4"
STYLES = ("walk-forward", "look-around", "sideways-dolly")
AGE_BANDS = ((1, 5), (5, 15), (15, 40), (40, 100), (100, 10 ** 6))
VARIANTS = {
    "default": {},
    "no-anchor": {"anchor": False},
    "no-reid": {"reid": False},
    "reanchor": {"on_anchor_failure": "reanchor"},
    "magsac": {"ransac_method": "magsac"},
    "fast": {"target_tracks": 500},
}


def timed_tracks(frames: list, options: TrackOptions) -> tuple[TrackSet, float]:
    """The tracks of decoded ``frames`` and the CPU ms per frame they took (OpenCV on one thread)."""
    started = time.process_time()
    tracks = track_features(iter(frames), options)
    return tracks, 1e3 * (time.process_time() - started) / len(frames)


def length_stats(tracks: TrackSet, cpu_ms_per_frame: float) -> dict:
    lengths = tracks.track_lengths()
    span = lengths["span_frames"]
    return {"tracks": int(len(span)), "observations": int(len(tracks)),
            "live_tracks_median": tracks.stats["live_tracks_median"],
            "span_median": float(np.median(span)), "span_p90": float(np.percentile(span, 90)),
            "tracks_3_keyframes": int(np.sum(lengths["keyframes"] >= 3)),
            "tracks_10_keyframes": int(np.sum(lengths["keyframes"] >= 10)),
            "tracks_span_100": int(np.sum(span >= 100)),
            "keyframes": int(len(tracks.keyframes)),
            "ms_per_frame_cpu": round(cpu_ms_per_frame, 2),
            "ms_per_frame_wall": round(tracks.stats["ms_per_frame_wall"], 2),
            "first_view_mb": round(tracks.stats["first_view_mb"], 1),
            "observations_mb": round(tracks.stats["observations_mb"], 1),
            "counters": {k: v for k, v in tracks.stats.items() if isinstance(v, int)}}


def error_stats(err: np.ndarray, radial: np.ndarray, radius: np.ndarray, age: np.ndarray, sel: np.ndarray) -> dict:
    """RMS and radial systematic part by age over the observations ``sel`` (within 2 px), and the
    share beyond 2 px."""
    out = {"n": int(sel.sum()), "beyond_2px": float(np.mean(err[sel] > 2)) if sel.any() else None, "by_age": {}}
    good = sel & (err <= 2)
    for lo, hi in AGE_BANDS:
        band = good & (age >= lo) & (age < hi)
        if band.sum() < 20:
            continue
        out["by_age"][f"{lo}-{hi}"] = {
            "n": int(band.sum()), "rms_px": float(np.sqrt(np.mean(err[band] ** 2))),
            "mean_radial_px": float(np.mean(radial[band])),
            "radial_per_radius": float(np.sum(radial[band] * radius[band]) / np.sum(radius[band] ** 2))}
    return out


def audit(tracks: TrackSet, truth: dict) -> dict:
    from rscalib.sim.scene_truth import RenderTruth

    rt = RenderTruth(truth)
    uv_true = rt.track_pixels(tracks.frame, tracks.track_id, tracks.uv_px)
    e = tracks.uv_px - uv_true
    err = np.linalg.norm(e, axis=1)
    err = np.where(np.isfinite(err), err, np.inf)
    offset = uv_true - np.asarray(truth["camera"]["params"][1:3])
    radius = np.linalg.norm(offset, axis=1)
    radial = np.sum(e * offset, axis=1) / np.maximum(radius, 1e-9)
    order = np.lexsort((tracks.frame, tracks.track_id))
    first_of = {}
    for i in order.tolist():
        first_of.setdefault(int(tracks.track_id[i]), int(tracks.frame[i]))
    age = tracks.frame - np.array([first_of[int(i)] for i in tracks.track_id.tolist()])
    finite = np.isfinite(radial)
    at_keyframe = np.isin(tracks.frame, tracks.keyframes)
    out = {"all": error_stats(err, radial, radius, age, finite & (age > 0)),
           "keyframes": error_stats(err, radial, radius, age, finite & (age > 0) & at_keyframe)}
    # the tracks' own precision index against their error (keyframe observations, by quartile)
    sel = finite & (age > 0) & at_keyframe & (err <= 2)
    if sel.sum() > 100:
        edges = np.r_[-np.inf, np.percentile(tracks.position_sigma[sel], [25, 50, 75]), np.inf]
        out["by_sigma_quartile"] = []
        for lo, hi in zip(edges[:-1], edges[1:]):
            q = sel & (tracks.position_sigma > lo) & (tracks.position_sigma <= hi)
            young, old = q & (age < 5), q & (age >= 40)
            out["by_sigma_quartile"].append({
                "sigma_to": float(hi), "rms_px_ages_1_5": float(np.sqrt(np.mean(err[young] ** 2))) if young.any() else None,
                "rms_px_ages_40": float(np.sqrt(np.mean(err[old] ** 2))) if old.any() else None})
    # re-identification: the revived observation against the old id's truth
    events = tracks.reid_events
    correct = []
    for frame, track_id, _ in events.tolist():
        row = np.flatnonzero((tracks.frame == frame) & (tracks.track_id == track_id))
        correct.append(bool(err[row[0]] <= 2.0) if len(row) else False)
    correct = np.array(correct, bool)
    gap = events[:, 0] - events[:, 2] if len(events) else np.zeros(0)
    out["reid"] = {"fired": int(len(events)), "correct": int(correct.sum()),
                   "precision": float(correct.mean()) if len(correct) else None,
                   "fired_gap_over_30": int(np.sum(gap > 30)),
                   "correct_gap_over_30": int(np.sum(correct & (gap > 30)))}
    return out


def render_rows(args, options: TrackOptions) -> list[dict]:
    from rscalib.sim.scene_realism import render_realistic_scene

    rows = []
    for size in args.sizes.split(","):
        width, height = (int(s) for s in size.split("x"))
        for style in args.styles.split(","):
            for seed in range(args.seed0, args.seed0 + args.seeds):
                seq = Path(args.cache) / f"{style}_{size}_s{seed}_n{args.frames}"
                if not (seq / "truth.json").exists():
                    render_realistic_scene(seq, style, (width, height), args.frames, seed)
                truth = json.loads((seq / "truth.json").read_text())
                tracks, cpu_ms = timed_tracks(list(read_gray_frames(seq).frames), options)
                row = {"source": "render", "style": style, "size": size, "seed": seed, "variant": args.variant,
                       "textures": truth["textures"], "codec": truth["codec_used"], **length_stats(tracks, cpu_ms)}
                row["audit"] = audit(tracks, truth)
                if args.filter:
                    row["filter"] = filter_audit(seq)
                rows.append(row)
                print_row(row)
    return rows


def filter_audit(seq: Path) -> dict:
    """The SOG filter's own tracks (front end "tracked", docs/sog.md §19) audited the same way."""
    import exp_selfcalib_bundle as bundle_exp

    truth = json.loads((seq / "truth.json").read_text())
    camera = truth["camera"]
    row = bundle_exp.image_run({"part": "b", "style": truth["style"], "seed": truth["seed"]}, seq,
                               dict(zip(("f", "cx", "cy", "k1", "k2"), camera["params"])),
                               float(camera["pixel_size_mm"][0]), 3, front_end="tracked", audit_only=True)
    return {"front_end_ms_per_frame": row["front_end_ms_per_frame"], "audit": row["audit"],
            "observations": row["observations_recorded"]}


def desk_rows(args, options: TrackOptions) -> list[dict]:
    rows = []
    gray = read_gray_frames(DESK)
    frames = list(gray.frames)
    tracks, cpu_ms = timed_tracks(frames, options)
    row = {"source": "desk", "variant": args.variant, "frames": len(frames), **length_stats(tracks, cpu_ms)}
    row["epipolar"] = epipolar_check(tracks)
    rows.append(row)
    print_row(row)
    # forth and back twice: a long sequence for the speed (times kept increasing)
    step = float(np.median(np.diff([t for t, _ in frames])))
    order = list(range(len(frames))) + list(range(len(frames) - 2, 0, -1))
    order = order + order
    long_tracks, cpu_ms = timed_tracks([(k * step, frames[i][1]) for k, i in enumerate(order)], options)
    rows.append({"source": "desk forth and back x2", "variant": args.variant, "frames": len(order),
                 **length_stats(long_tracks, cpu_ms), "peak_rss_mb": peak_rss_mb()})
    print_row(rows[-1])
    return rows


def peak_rss_mb() -> float:
    import resource
    return round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1)


def epipolar_check(tracks: TrackSet, gap: int = 10, stride: int = 5) -> dict:
    """Sampson distances (px) of the tracks between frames k and k + gap from an LMedS fundamental
    matrix fitted to those same correspondences (a truth-free check of consistency)."""
    distances = []
    by_frame = {}
    for f in np.unique(tracks.frame):
        rows = np.flatnonzero(tracks.frame == f)
        by_frame[int(f)] = dict(zip(tracks.track_id[rows].tolist(), tracks.uv_px[rows]))
    frames = sorted(by_frame)
    for k in frames[:-gap:stride]:
        a, b = by_frame[k], by_frame.get(k + gap)
        if b is None:
            continue
        common = sorted(set(a) & set(b))
        if len(common) < 30:
            continue
        p0 = np.array([a[i] for i in common])
        p1 = np.array([b[i] for i in common])
        F, _ = cv2.findFundamentalMat(p0, p1, cv2.FM_LMEDS)
        if F is None or F.shape != (3, 3):
            continue
        x0, x1 = np.c_[p0, np.ones(len(p0))], np.c_[p1, np.ones(len(p1))]
        Fx0, Ftx1 = x0 @ F.T, x1 @ F
        e = np.sum(x1 * Fx0, axis=1)
        distances.append(np.abs(e) / np.sqrt(Fx0[:, 0] ** 2 + Fx0[:, 1] ** 2 + Ftx1[:, 0] ** 2 + Ftx1[:, 1] ** 2))
    d = np.concatenate(distances) if distances else np.zeros(0)
    return {"pairs": len(distances), "correspondences": int(len(d)), "median_px": float(np.median(d)),
            "rms_within_2px": float(np.sqrt(np.mean(d[d <= 2] ** 2))), "p90_px": float(np.percentile(d, 90)),
            "beyond_2px": float(np.mean(d > 2))}


def print_row(row: dict) -> None:
    head = (f"{row['source']:8s} {row.get('style', ''):15s} {row.get('size', ''):8s} {row.get('seed', '')} "
            f"[{row['variant']}]: {row['tracks']} tracks, live {row['live_tracks_median']:.0f}, span median "
            f"{row['span_median']:.0f} p90 {row['span_p90']:.0f}, >=3 kf {row['tracks_3_keyframes']}, "
            f"{row['ms_per_frame_cpu']:.1f} ms/frame CPU")
    if "audit" in row:
        a = row["audit"]
        head += (f" | >2px {100 * a['all']['beyond_2px']:.2f} %, rms by age "
                 + " ".join(f"{k}:{v['rms_px']:.3f}({v['radial_per_radius']:+.1e})" for k, v in a["all"]["by_age"].items())
                 + f" | reid {a['reid']['fired']} ({a['reid']['correct']} right)")
    if "epipolar" in row:
        e = row["epipolar"]
        head += f" | epipolar median {e['median_px']:.3f} px, rms {e['rms_within_2px']:.3f}, >2px {100 * e['beyond_2px']:.2f} %"
    if "filter" in row:
        f = row["filter"]["audit"]
        head += (f" || filter: >2px {100 * f['beyond_2px']:.2f} %, "
                 + " ".join(f"{k}:{v['rms_px']:.3f}" for k, v in f["by_age"].items()))
    print(head, flush=True)


def tables(paths: list[str]) -> str:
    rows = []
    for p in paths:
        rows += json.loads(Path(p).read_text())["results"]
    out = ["| variant | style | size | runs | tracks | live | span median / p90 | tracks >= 3 kf | RMS px at ages 1-5 / 5-15 / 15-40 / 40-100 / >= 100 (keyframe obs.) | radial per px of radius, age >= 40 | > 2 px | re-id fired (right) | CPU ms/frame |",
           "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    renders = [r for r in rows if r["source"] == "render"]
    keys = sorted({(r["variant"], r["size"], r["style"]) for r in renders}, key=lambda k: (k[0], k[1], STYLES.index(k[2])))
    for variant, size, style in keys:
        g = [r for r in renders if (r["variant"], r["size"], r["style"]) == (variant, size, style)]
        def med(f, g=g):
            vals = [f(r) for r in g]
            vals = [v for v in vals if v is not None]
            return float(np.median(vals)) if vals else float("nan")
        rms = " / ".join(f"{med(lambda r, b=b: r['audit']['keyframes']['by_age'].get(b, {}).get('rms_px')):.3f}"
                         for b in ("1-5", "5-15", "15-40", "40-100", "100-1000000"))
        radial = med(lambda r: np.nan if not r["audit"]["keyframes"]["by_age"] else np.nanmean(
            [v["radial_per_radius"] for k, v in r["audit"]["keyframes"]["by_age"].items() if int(k.split("-")[0]) >= 40] or [np.nan]))
        fired = sum(r["audit"]["reid"]["fired"] for r in g)
        right = sum(r["audit"]["reid"]["correct"] for r in g)
        out.append(f"| {variant} | {style} | {size} | {len(g)} | {med(lambda r: r['tracks']):.0f} | "
                   f"{med(lambda r: r['live_tracks_median']):.0f} | {med(lambda r: r['span_median']):.0f} / "
                   f"{med(lambda r: r['span_p90']):.0f} | {med(lambda r: r['tracks_3_keyframes']):.0f} | {rms} | "
                   f"{radial:+.1e} | {100 * med(lambda r: r['audit']['all']['beyond_2px']):.2f} % | {fired} ({right}) | "
                   f"{med(lambda r: r['ms_per_frame_cpu']):.1f} |")
    quart = [r for r in renders if "by_sigma_quartile" in r["audit"]]
    if quart:
        out += ["", "| variant | style | size | RMS px at ages >= 40 (1-5) by quartile of position_sigma, best to worst |",
                "|---|---|---|---|"]
        for variant, size, style in keys:
            g = [r for r in quart if (r["variant"], r["size"], r["style"]) == (variant, size, style)]
            if not g:
                continue
            cells = []
            for i in range(4):
                old = [r["audit"]["by_sigma_quartile"][i]["rms_px_ages_40"] for r in g]
                young = [r["audit"]["by_sigma_quartile"][i]["rms_px_ages_1_5"] for r in g]
                old = [v for v in old if v is not None]
                young = [v for v in young if v is not None]
                cells.append(f"{np.median(old) if old else np.nan:.2f} ({np.median(young) if young else np.nan:.2f})")
            out.append(f"| {variant} | {style} | {size} | {' / '.join(cells)} |")
    filt = [r for r in renders if "filter" in r]
    if filt:
        out += ["", "| filter front end (\"tracked\") | size | runs | RMS px at ages 1-5 / 5-15 / 15-40 / >= 40 | > 2 px | observations |",
                "|---|---|---|---|---|---|"]
        for size in sorted({r["size"] for r in filt}):
            for style in STYLES:
                g = [r for r in filt if r["size"] == size and r["style"] == style]
                if not g:
                    continue
                rms = " / ".join(f"{np.median([r['filter']['audit']['by_age'][b]['rms_px'] for r in g if b in r['filter']['audit']['by_age']] or [np.nan]):.3f}"
                                 for b in ("1-5", "5-15", "15-40", "40-1000000"))
                out.append(f"| {style} | {size} | {len(g)} | {rms} | "
                           f"{100 * np.median([r['filter']['audit']['beyond_2px'] for r in g]):.2f} % | "
                           f"{np.median([r['filter']['observations'] for r in g]):.0f} |")
    desk = [r for r in rows if r["source"].startswith("desk")]
    if desk:
        out += ["", "| desk video | variant | frames | tracks | live | span median / p90 | tracks >= 3 kf | epipolar median / RMS px (k, k+10) | > 2 px | CPU ms/frame |",
                "|---|---|---|---|---|---|---|---|---|---|"]
        for r in desk:
            e = r.get("epipolar")
            ep = f"{e['median_px']:.3f} / {e['rms_within_2px']:.3f} | {100 * e['beyond_2px']:.2f} %" if e else "— | —"
            out.append(f"| {r['source']} | {r['variant']} | {r['frames']} | {r['tracks']} | {r['live_tracks_median']:.0f} | "
                       f"{r['span_median']:.0f} / {r['span_p90']:.0f} | {r['tracks_3_keyframes']} | {ep} | "
                       f"{r['ms_per_frame_cpu']:.1f} |")
    return "\n".join(out)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sizes", default="320x240,640x480")
    ap.add_argument("--styles", default=",".join(STYLES))
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--seed0", type=int, default=1100)
    ap.add_argument("--frames", type=int, default=200)
    ap.add_argument("--cache", default="/tmp/rscalib_h11_selfcalib_realistic")
    ap.add_argument("--variant", default="default", choices=sorted(VARIANTS))
    ap.add_argument("--filter", action="store_true", help="also audit the SOG filter's own tracks (slow)")
    ap.add_argument("--desk", action="store_true", help="also the real desk video (no truth)")
    ap.add_argument("--no-renders", action="store_true", help="only the desk video")
    ap.add_argument("--out", default=None)
    ap.add_argument("--table", nargs="+", help="print the markdown tables of these result files")
    args = ap.parse_args()
    if args.table:
        print(tables(args.table))
        return
    cv2.setNumThreads(1)            # CPU ms per frame on one core: the other runs the filter
    options = TrackOptions(**VARIANTS[args.variant])
    started = time.perf_counter()
    rows = [] if args.no_renders else render_rows(args, options)
    if args.desk or args.no_renders:
        rows += desk_rows(args, options)
    out = Path(args.out or REPO / "benchmarks" / "results" / f"exp_selfcalib_tracks_{args.variant}.json")
    write_results(out, "exp_selfcalib_tracks", machine_info(elapsed_s=round(time.perf_counter() - started, 1)),
                  {k: v for k, v in vars(args).items() if k not in ("table", "out")}, rows, "")
    out_json = json.loads(out.read_text())
    out_json["table_markdown"] = tables([str(out)])
    out.write_text(json.dumps(out_json, indent=2) + "\n")
    print(out_json["table_markdown"])


if __name__ == "__main__":
    main()
