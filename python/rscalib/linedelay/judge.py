"""The verdict of a line-delay estimate (rscalib.verdict.Verdict): trusted, not trusted (a check
failed: the reasons say which, the first cause first) or not determined (the data do not determine
d: no number is claimed). The rules and why: docs/formulation.md §9 and §17; they were set from the
confusion table of benchmarks/bench_linedelay_verdict.py (docs/benchmarks.md).

Two steps, so the rules can be judged again on stored numbers (the benchmark does):
:func:`line_delay_evidence` reduces a result and its run to plain numbers (JSON-ready), and
:func:`diagnose` applies the rules to them: the verdict, and the findings with their causes
(CAUSES), in the order a user should look at them.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from .._core import rotation_vector_to_matrix
from ..verdict import NOT_DETERMINED, NOT_TRUSTED, TRUSTED, Verdict

# What a finding blames, in the words of result.json's `diagnosis`.
TARGET_SIZE, CAMERA, MOTION, STABILISATION, COMPRESSION, COVERAGE, SOLVER = (
    "target_size", "camera", "motion", "stabilisation", "compression", "coverage", "solver")
READOUT = "readout"
# a caveat that blames nothing (J/2N below 1: sigma_d on the safe side)
NOISE_MODEL = "noise_model"
CAUSES = (TARGET_SIZE, CAMERA, MOTION, STABILISATION, COMPRESSION, COVERAGE, SOLVER, READOUT, NOISE_MODEL)
# a line delay this many sigma below 0 contradicts the readout direction used
NEGATIVE_SIGMA = 3.0

# J/2N above this: the model does not fit the detections (below 1 only says that the noise model
# overestimates sigma: sigma_d is then conservative, which is no reason to distrust it)
MAX_COST = 1.5
# fewer usable frames than this fraction of the video: most of it was not seen
MIN_FRAMES_USED_FRACTION = 0.3
# the board over fewer than this fraction of the image rows (2nd-98th percentile)
MIN_ROW_SPAN = 0.4
# the data's standard deviation above this fraction of the estimate: too uncertain to act on
MAX_RELATIVE_STD = 0.02
# Physical limits of a calibration video: the camera this far from the board, squares this large,
# are a wrong target size (a size in millimetres where metres are meant), not a real video.
DISTANCE_RANGE_M = (0.03, 20.0)
SQUARE_RANGE_M = (0.002, 0.5)
# a half's J/2N this many times the other's (and above MAX_COST): the misfit is in that half's motion
HALF_COST_RATIO = 4.0
# residual_structure chi-squares per degree of freedom (about 1 for noise) that name a cause: a fixed
# pattern over the image (the camera file), a shear per frame the line delay does not explain (a
# stabiliser shifting each frame). Set from the verdict benchmark's tuning set (docs/benchmarks.md):
# camera faults 5-91 against at most 3.5 for every other run; stabilised 13-28 against at most 5.4.
FIELD_CHI = 5.0
SHEAR_CHI = 5.0
# the camera check (pipeline.check_camera): refining the intrinsics moves d by this many of the data's
# sigma -- the camera file matters at this video's precision
CAMERA_SHIFT_SIGMA = 2.0
# below this many bits per pixel the video was likely re-encoded (guidance.MIN_BITS_PER_PIXEL)
LOW_BITS_PER_PIXEL = 0.15
# The camera check's refit prefers intrinsics this far from the camera file's (pipeline.camera_change):
# said as a caveat when d is trusted (the file is wrong for other uses, not for this d). Set from the
# verdict benchmark's set 4700 (docs/benchmarks.md): on its 20 clean runs at most 0.67 %, 1.3 px and
# 2.2 px (3.4 px, 6.9 px on re-encoded ones); its camera faults at least 1.9 %, 20.8 px and 17.4 px.
CAVEAT_FOCAL_FRACTION = 0.015
CAVEAT_CENTRE_PX = 8.0
CAVEAT_DISTORTION_PX = 10.0


@dataclass
class Finding:
    """One thing the verdict says: its cause (CAUSES), its weight (`not determined`, `not trusted`, or
    `caveat`: said without changing a trusted verdict), the sentence and what to do."""

    cause: str
    weight: str
    text: str
    advice: str = ""

    def sentence(self) -> str:
        return self.text + (f": {self.advice}" if self.advice else "")


@dataclass
class Diagnosis:
    """The verdict with the findings behind it (the first cause first) and the evidence judged."""

    verdict: Verdict
    findings: list = field(default_factory=list)
    evidence: dict = field(default_factory=dict)

    @property
    def causes(self) -> list:
        """The causes of the findings that cost trust, in order (empty when trusted)."""
        return [f.cause for f in self.findings if f.weight != "caveat"]

    @property
    def first_cause(self) -> Optional[str]:
        return self.causes[0] if self.causes else None

    @property
    def named_cause(self) -> Optional[str]:
        """What the verdict names first: the first cause, or on a trusted verdict the first caveat that
        blames something (a fault that did not bend d: the camera file, the compression)."""
        if self.first_cause:
            return self.first_cause
        return next((f.cause for f in self.findings if f.weight == "caveat" and f.cause != NOISE_MODEL), None)

    def to_dict(self) -> dict:
        return {"first_cause": self.first_cause, "causes": self.causes, "named_cause": self.named_cause,
                "findings": [{"cause": f.cause, "weight": f.weight, "text": f.text, "advice": f.advice}
                             for f in self.findings],
                "evidence": self.evidence}


def _us(x: float) -> str:
    return f"{x * 1e6:.3f}" if x is not None and math.isfinite(x) else "?"


def _finite(x) -> Optional[float]:
    return float(x) if x is not None and isinstance(x, (int, float, np.floating)) and math.isfinite(x) else None


def _median_board_distance_m(result) -> Optional[float]:
    """Median distance from the camera to the board's centre over the frames (the PnP poses)."""
    poses = getattr(result, "gs_poses", None)   # the linear model's PnP poses (its frame_poses are an array)
    if poses is None:
        poses = getattr(result, "frame_poses", None)
    if poses is None or not hasattr(poses, "translation"):
        return None
    try:
        centre = np.mean(result.used_observations.target_points, axis=0)
        t = np.asarray(poses.translation, dtype=float)
        phi = np.asarray(poses.rotation_vector, dtype=float)
        keep = np.all(np.isfinite(t), axis=1) & np.all(np.isfinite(phi), axis=1)
        if not keep.any():
            return None
        idx = np.flatnonzero(keep)[:: max(1, int(keep.sum()) // 100)]
        d = [np.linalg.norm(rotation_vector_to_matrix(phi[i]) @ centre + t[i]) for i in idx]
        return float(np.median(d))
    except (AttributeError, ValueError, TypeError):
        return None


def target_spacing_m(target_points: np.ndarray) -> Optional[float]:
    """The smallest distance between two target points (a checkerboard's square size)."""
    points = np.asarray(target_points, dtype=float).reshape(-1, 3)
    if len(points) < 2:
        return None
    if len(points) > 2000:
        points = points[:2000]
    diff = points[:, None, :] - points[None, :, :]
    dist = np.sqrt((diff ** 2).sum(-1))
    dist[np.diag_indices(len(points))] = np.inf
    nearest = float(dist.min())
    return nearest if math.isfinite(nearest) and nearest > 0 else None


# residual_structure: the image cut into this many cells (columns, rows) for the fixed-field test
FIELD_CELLS = (8, 6)


def residual_structure(result) -> dict:
    """Where the residuals' structure lives, each a chi-square per degree of freedom of group statistics
    (about 1 when the residuals do not depend on the grouping; the residual variance is the scale):

    - `image_field`: the mean residual of each cell of the image (FIELD_CELLS) over the whole video: a
      wrong camera file is a fixed function of the pixel;
    - `frame_common`: each frame's mean residual: a trajectory that does not follow the motion, or a
      frame shifted as a whole, errs per frame;
    - `frame_shear`: each frame's residual slope along the rows (u and v against v): a shear the line
      delay does not explain by the motion between frames (a stabiliser shifting each frame);
    - the two frame statistics for each half of the video too (`*_halves`)."""
    none = {"image_field": None, "frame_common": None, "frame_shear": None, "frame_common_halves": None,
            "frame_shear_halves": None}
    r = np.asarray(getattr(result, "residual_px", np.zeros((0, 2))), dtype=float)
    obs = result.used_observations
    if r.ndim != 2 or len(r) != len(getattr(obs, "uv", ())):
        return none
    keep = np.all(np.isfinite(r), axis=1)
    if keep.sum() < 20:
        return none
    r, uv, frames = r[keep], obs.uv[keep], obs.frame_index[keep]
    s2 = float(np.mean(r ** 2))   # per coordinate
    if not s2 > 0:
        return none

    def group_means(groups: np.ndarray, values: np.ndarray):
        labels, inverse, counts = np.unique(groups, return_inverse=True, return_counts=True)
        sums = np.stack([np.bincount(inverse, weights=values[:, k]) for k in range(values.shape[1])], axis=1)
        return labels, inverse, counts, sums / counts[:, None]

    def chi_of_means(groups: np.ndarray, mask=None) -> Optional[float]:
        labels, _, counts, means = group_means(groups, r)
        stat = counts * (means ** 2).sum(axis=1) / s2 / 2.0
        if mask is not None:
            stat = stat[mask(labels)]
        return float(np.mean(stat)) if len(stat) else None

    w, h = obs.image_size
    cells = (np.clip((uv[:, 0] / w * FIELD_CELLS[0]).astype(int), 0, FIELD_CELLS[0] - 1) * FIELD_CELLS[1]
             + np.clip((uv[:, 1] / h * FIELD_CELLS[1]).astype(int), 0, FIELD_CELLS[1] - 1))
    # per frame: the slope of the residuals against the row, scaled by its noise (s2 / sum (v - mean v)^2)
    labels, inverse, counts, mean_uv = group_means(frames, np.c_[uv[:, 1]])
    dv = uv[:, 1] - mean_uv[inverse, 0]
    svv = np.bincount(inverse, weights=dv * dv)
    slope = np.stack([np.bincount(inverse, weights=dv * r[:, k]) for k in range(2)], axis=1)
    ok = (counts >= 6) & (svv > 0)
    shear_stat = np.where(ok, (slope ** 2).sum(axis=1) / np.where(svv > 0, svv, 1.0) / s2 / 2.0, np.nan)
    times = obs.frame_times_s[labels]
    t_mid = 0.5 * (obs.frame_times_s[0] + obs.frame_times_s[-1])
    halves = [times < t_mid, times >= t_mid]

    def mean_of(x, mask):
        x = x[mask & np.isfinite(x)]
        return float(np.mean(x)) if len(x) else None

    common_stat = counts * (group_means(frames, r)[3] ** 2).sum(axis=1) / s2 / 2.0
    return {"image_field": chi_of_means(cells), "frame_common": mean_of(common_stat, np.ones(len(labels), bool)),
            "frame_shear": mean_of(shear_stat, np.ones(len(labels), bool)),
            "frame_common_halves": [mean_of(common_stat, m) for m in halves],
            "frame_shear_halves": [mean_of(shear_stat, m) for m in halves]}


def line_delay_evidence(result, *, frame_rate_hz: Optional[float] = None,
                        bits_per_pixel: Optional[float] = None, camera_check: Optional[dict] = None) -> dict:
    """The numbers the verdict judges, JSON-ready: the estimate and its sigmas (the data's, before the
    halves' widening, and the widened one), J/2N of the whole video and of each half, the halves' z,
    coverage, the physical quantities (readout against the frame interval, the camera-board distance,
    the target's square size) and the bitrate. frame_rate_hz: of a video (None for frames without a
    rate: no readout limit); bits_per_pixel: the video file's (io.video.video_bits_per_pixel);
    camera_check: pipeline.check_camera's (d with the intrinsics refined), when it ran."""
    check = getattr(result, "self_check", None) or {}
    widen = float(check.get("widen") or 1.0)
    std = _finite(result.line_delay_std_s)
    rows_seen = result.used_observations.uv[:, 1]
    span = float((np.percentile(rows_seen, 98) - np.percentile(rows_seen, 2)) / result.rows) if len(rows_seen) else 0.0
    halves = check.get("halves") or []
    target_points = getattr(result.used_observations, "target_points", None)
    return {
        "determined": bool(result.determined),
        "line_delay_s": _finite(result.line_delay_s),
        "std_s": std,
        "data_std_s": None if std is None else std / widen,
        "rows": int(result.rows),
        "normalised_cost": _finite(result.normalised_cost),
        "halves_z": _finite(check.get("z")),
        "halves_agree": check.get("agree") if check else True,
        "halves_reason": check.get("reason") if check else None,
        "halves_cost": [_finite(h.get("normalised_cost")) for h in halves],
        "halves_span_s": [[_finite(h.get("t_begin_s")), _finite(h.get("t_end_s"))] for h in halves],
        "frames_used": int(result.frames_used),
        "frames_total": int(result.frames_total),
        "row_span": span,
        "converged": bool(result.converged),
        "frame_interval_s": None if not frame_rate_hz else 1.0 / float(frame_rate_hz),
        "board_distance_m": _median_board_distance_m(result),
        "square_m": None if target_points is None else target_spacing_m(target_points),
        "bits_per_pixel": _finite(bits_per_pixel),
        "residual_structure": residual_structure(result),
        "camera_check": camera_check,
        "intrinsics_refined": getattr(result, "intrinsics", None) is not None,
        "can_refine_intrinsics": hasattr(result, "intrinsics") and getattr(result, "intrinsics", None) is None,
    }


def _readout_too_long(e: dict) -> Optional[str]:
    d, rows = e["line_delay_s"], e["rows"]
    if d is not None and e["frame_interval_s"] and abs(d) * rows > e["frame_interval_s"]:
        return (f"a readout of {abs(d) * rows * 1e3:.1f} ms is longer than the frame interval "
                f"({e['frame_interval_s'] * 1e3:.1f} ms), which no video camera can do")
    return None


def _physical(e: dict) -> Optional[Finding]:
    """An impossible board (the camera at an impossible distance from it, or impossible squares): the
    target's size, said with a readout longer than a frame if there is one."""
    distance, square = e["board_distance_m"], e["square_m"]
    problems = []
    if distance is not None and not DISTANCE_RANGE_M[0] <= distance <= DISTANCE_RANGE_M[1]:
        problems.append(f"the target's size puts the camera {distance:.3g} m from the board")
    elif square is not None and not SQUARE_RANGE_M[0] <= square <= SQUARE_RANGE_M[1]:
        problems.append(f"the target file's squares are {square:.3g} m")
    if not problems:
        return None
    readout = _readout_too_long(e)
    size = "" if square is None else f" (it says squares of {square:.4g} m = {square * 1e3:.6g} mm)"
    return Finding(TARGET_SIZE, NOT_TRUSTED, "; ".join(([readout] if readout else []) + problems),
                   f"check the square size in the target file first{size}: rowSpacingMeters and colSpacingMeters "
                   "are in metres (40 mm is 0.04)")


def _structure(e: dict) -> tuple[float, float]:
    rs = e.get("residual_structure") or {}
    field, shear = rs.get("image_field"), rs.get("frame_shear")
    return (0.0 if field is None else float(field)), (0.0 if shear is None else float(shear))


def _camera_finding(e: dict, text: str) -> Finding:
    advice = ("run again with --refine-intrinsics (the camera file becomes a prior and is refined with the "
              "line delay)" if e["can_refine_intrinsics"] else "calibrate the camera again (rscalib intrinsics)")
    return Finding(CAMERA, NOT_TRUSTED, text, advice)


def _refine_advice_only_first(findings: list) -> None:
    """--refine-intrinsics is advised only when the camera is the first cause: where the camera was a
    later finding (after the target size, the motion, stabilisation) the re-run never helped, in 23 of
    23 benchmark runs (sets 3900 and 4300), and once it ended in an input error (the focal length
    refined below 0 with a target in millimetres); where it was first it helped in 65 of 68
    (docs/benchmarks.md, issue 31). A later camera finding says to calibrate the camera again instead."""
    for finding in findings[1:]:
        if finding.cause == CAMERA and "--refine-intrinsics" in finding.advice:
            finding.advice = "calibrate the camera again (rscalib intrinsics) if this remains after that"


def _half_costs(e: dict) -> list:
    return [c for c in e["halves_cost"] if c is not None]


def _one_half_misfits(costs: list) -> bool:
    """One half's J/2N above MAX_COST and HALF_COST_RATIO times the other's: the model does not fit
    there, whatever the whole video's J/2N says (its noise model, fitted to the whole, can hide it)."""
    return len(costs) == 2 and max(costs) > MAX_COST and max(costs) > HALF_COST_RATIO * min(costs)


def _misfit_cause(e: dict) -> Finding:
    """Why the model does not fit (J/2N high, or the halves disagree), in this order: a fixed pattern
    of the residuals over the image (the camera file); the misfit in one half of the video (its motion);
    a shear per frame that the motion does not explain (a stabiliser); a low bitrate; else the camera."""
    field, shear = _structure(e)
    if field >= FIELD_CHI and field >= shear:
        return _camera_finding(e, f"the residuals form a fixed pattern over the image (chi-square {field:.0f} "
                               "per cell against about 1 for noise): the camera file (focal length, principal "
                               "point or distortion) does not describe this camera")
    costs = _half_costs(e)
    if _one_half_misfits(costs):
        worse = int(np.argmax(costs))
        span = e["halves_span_s"][worse]
        when = "" if None in span else f" ({span[0]:.1f}-{span[1]:.1f} s)"
        return Finding(MOTION, NOT_TRUSTED,
                       f"the trajectory does not follow the motion in the {('first', 'second')[worse]} half of the "
                       f"video{when}: J/2N {costs[worse]:.2f} there against {costs[1 - worse]:.2f}",
                       "move more smoothly (no vibration or jerks), or leave that part out with --start/--end")
    if shear >= SHEAR_CHI:
        return Finding(STABILISATION, NOT_TRUSTED,
                       f"the frames are sheared in a way their motion does not explain (chi-square {shear:.0f} per "
                       "frame against about 1 for noise): image stabilisation shifting each frame, or a video "
                       "edited after recording",
                       "turn off the phone's video stabilisation (and any 'smooth' or 'steady' mode), and use the "
                       "camera's original file")
    bpp = e["bits_per_pixel"]
    if bpp is not None and bpp < LOW_BITS_PER_PIXEL:
        return Finding(COMPRESSION, NOT_TRUSTED, f"the video is compressed to {bpp:.2f} bit/pixel (re-encoded?)",
                       "use the camera's original file, or record at a higher quality setting")
    return _camera_finding(e, "the first suspect is the camera file (focal length, principal point or distortion)")


def _harmless_faults(e: dict) -> list:
    """Caveats on a trusted d: faults the data show that did not bend d beyond its error bar -- a camera
    file the board's video disagrees with (the camera check's refit: the file is wrong for other uses),
    a video compressed like a re-encode (a camera original would give a smaller sigma_d); the compression
    first (a measured fact, and its noise moves the refit a little: set 4700)."""
    out = []
    bpp = e["bits_per_pixel"]
    if bpp is not None and bpp < LOW_BITS_PER_PIXEL:
        out.append(Finding(COMPRESSION, "caveat", f"the video is compressed to {bpp:.2f} bit/pixel (re-encoded?); "
                           "sigma_d includes its effect", "the camera's original file would give a smaller sigma_d"))
    check = e.get("camera_check") or {}
    focal, centre, distortion = (check.get(k) for k in ("focal_change_fraction", "centre_change_px",
                                                         "distortion_change_px"))
    parts = []
    if focal is not None and abs(focal) >= CAVEAT_FOCAL_FRACTION:
        parts.append(f"focal length {abs(focal) * 100:.1f} % {'longer' if focal > 0 else 'shorter'}")
    if centre is not None and centre >= CAVEAT_CENTRE_PX:
        parts.append(f"principal point {centre:.0f} px away")
    if distortion is not None and distortion >= CAVEAT_DISTORTION_PX:
        parts.append(f"distortion moving the image by up to {distortion:.0f} px")
    if parts:
        shift = check.get("shift_sigma")
        moved = "" if shift is None else f" (freeing the intrinsics moved d by {abs(shift):.1f} sigma)"
        out.append(Finding(CAMERA, "caveat", "the board's video disagrees with the camera file (" + ", ".join(parts)
                           + f"); d does not depend on it here{moved}",
                           "calibrate the camera again (rscalib intrinsics) before using the camera file elsewhere"))
    return out


def _coverage_and_precision(e: dict) -> list:
    """Findings 4-7 of docs/formulation.md §17: too few usable frames or rows, an inconclusive
    self-check, a data sigma above 2 % of d, a solver that did not converge."""
    out = []
    if e["frames_used"] < MIN_FRAMES_USED_FRACTION * e["frames_total"]:
        out.append(Finding(COVERAGE, NOT_TRUSTED, f"only {e['frames_used']} of {e['frames_total']} frames "
                           "were usable", "keep the whole board in view and sharp"))
    if e["row_span"] < MIN_ROW_SPAN:
        out.append(Finding(COVERAGE, NOT_TRUSTED, f"the target covered only {e['row_span'] * 100:.0f} % of "
                           "the image rows", "move it over the whole frame height"))
    if e["halves_agree"] is None:
        out.append(Finding(MOTION, NOT_TRUSTED, "self-check inconclusive: "
                           + (e["halves_reason"] or "a half could not be solved"),
                           "record longer, with the motion spread over the video"))
    d, data_std = e["line_delay_s"], e["data_std_s"]
    if data_std is not None and d and data_std > MAX_RELATIVE_STD * abs(d):
        text = f"the uncertainty is {data_std / abs(d) * 100:.1f} % of the estimate"
        bpp = e["bits_per_pixel"]
        if bpp is not None and bpp < LOW_BITS_PER_PIXEL:
            out.append(Finding(COMPRESSION, NOT_TRUSTED, text + f", in a video compressed to {bpp:.2f} "
                               "bit/pixel (re-encoded?)", "use the camera's original file, or record at a "
                               "higher quality setting"))
        else:
            out.append(Finding(MOTION, NOT_TRUSTED, text, "record longer or with faster motion"))
    if not e["converged"]:
        out.append(Finding(SOLVER, NOT_TRUSTED, "the solver did not report convergence",
                           "try --robust huber"))
    return out


def diagnose_evidence(e: dict) -> Diagnosis:
    """The verdict and its findings from the evidence of line_delay_evidence (the rules: module doc)."""
    quantity = dict(quantity="line_delay_s", unit="s/row")
    findings: list[Finding] = []
    physical = _physical(e)
    if not e["determined"]:
        std = e["data_std_s"]
        why = ("the covariance of d is rank deficient" if std is None else f"sigma_d = {_us(std)} us/row is too large")
        findings.append(Finding(MOTION, NOT_DETERMINED, f"the data do not determine the line delay ({why})",
                                "too little motion, or the wrong kind: move the camera faster, mostly rotating "
                                "about its vertical axis"))
        field, shear = _structure(e)
        if field >= FIELD_CHI and field >= shear:   # the misfit of a wrong camera file inflates the noise
            findings.insert(0, _camera_finding(e, f"the residuals form a fixed pattern over the image (chi-square "
                                                  f"{field:.0f} per cell against about 1 for noise): the camera "
                                                  "file does not describe this camera"))
        if physical is not None:
            findings.insert(0, physical)
        _refine_advice_only_first(findings)
        return Diagnosis(Verdict(NOT_DETERMINED, "Line delay not determined by this video.",
                                 [f.sentence() for f in findings], **quantity), findings, e)
    if physical is not None:
        findings.append(physical)
    cost = e["normalised_cost"]
    misfit = []
    if cost is not None and cost > MAX_COST:
        misfit.append(f"J/2N = {cost:.2f}: the detections do not fit the model")
    if cost is not None and not misfit and e["halves_agree"] is not False and _one_half_misfits(_half_costs(e)):
        # the stabilised sweeps of the fresh set 3500: J/2N 0.43 and 0.66 over the whole video, halves
        # 2.3 and 2.7 sigma apart, d 8 sigma off -- and one half's J/2N 1.9 and 3.1, 5-6x the other's
        misfit.append(f"J/2N = {cost:.2f} over the whole video, but {max(_half_costs(e)):.2f} in one half")
    if e["halves_agree"] is False:
        misfit.append(f"the two halves of the video disagree by {e['halves_z']:.1f} sigma (the error bar is "
                      f"widened x{e['halves_z']:.1f})")
    readout = None if physical is not None else _readout_too_long(e)
    if misfit:
        cause = _misfit_cause(e)
        cause.text = "; ".join(([readout] if readout else []) + misfit) + "; " + cause.text
        findings.append(cause)
    elif readout:   # a plausible board, yet an impossible readout: the rows, or the board's size
        findings.append(Finding(TARGET_SIZE, NOT_TRUSTED, readout,
                                "check the square size in the target file and the rows read out (--rows)"))

    check = e.get("camera_check") or {}
    shift = check.get("shift_sigma")
    if shift is not None and abs(shift) >= CAMERA_SHIFT_SIGMA and not any(f.cause == CAMERA for f in findings):
        findings.append(_camera_finding(e, f"refining the camera's intrinsics with the line delay moves d by "
                                           f"{shift:+.1f} sigma (to {_us(check['line_delay_s'])} us/row): the camera "
                                           "file does not describe this camera well enough for this video"))
    findings.extend(_coverage_and_precision(e))
    d = e["line_delay_s"]
    field, shear = _structure(e)
    if findings and field >= FIELD_CHI and field >= shear and findings[0].cause not in (TARGET_SIZE, CAMERA):
        # a strong fixed pattern over the image: whatever else failed, the camera file is the first suspect
        findings.insert(0, _camera_finding(e, f"the residuals form a fixed pattern over the image (chi-square "
                                              f"{field:.0f} per cell against about 1 for noise): the camera file "
                                              "does not describe this camera"))
    if d is not None and e["std_s"] and d < -NEGATIVE_SIGMA * e["std_s"]:
        # the rows were turned to top-to-bottom by the readout given (or assumed): a shutter reads
        # forwards, so a clearly negative d says the data contradict that direction (issue 33)
        findings.insert(0, Finding(READOUT, NOT_TRUSTED, f"the line delay came out negative ({_us(d)} us/row, "
                                   f"{-d / e['std_s']:.0f} sigma below 0): the rows are read in the other direction "
                                   "than the one given or assumed", "give the opposite --readout (bottom-to-top "
                                   "for top-to-bottom, right-to-left for left-to-right, or the reverse)"))
    if not findings:   # notes on a trusted d only: a verdict that is not trusted names its causes
        findings.extend(_harmless_faults(e))
        if cost is not None and cost < 1.0 / MAX_COST:
            findings.append(Finding(NOISE_MODEL, "caveat", f"J/2N = {cost:.2f} is below 1: the noise model "
                                    "overestimates the detection noise, so sigma_d is on the safe side"))
    _refine_advice_only_first(findings)
    trusted = not any(f.weight != "caveat" for f in findings)
    std = e["std_s"]
    readout = None if d is None else abs(d) * e["rows"]
    headline = (f"Line delay {_us(d)} ± {_us(std)} µs/row (readout {readout * 1e3:.3f} ms): "
                + ("trust it." if trusted else "estimated, but do not trust it yet."))
    verdict = Verdict(TRUSTED if trusted else NOT_TRUSTED, headline,
                      [f.sentence() for f in findings if f.weight != "caveat"], value=d, std=std, bounds_99=None,
                      caveats=[f.sentence() for f in findings if f.weight == "caveat"], **quantity)
    return Diagnosis(verdict, findings, e)


def diagnose(result, *, frame_rate_hz: Optional[float] = None, bits_per_pixel: Optional[float] = None,
             camera_check: Optional[dict] = None) -> Diagnosis:
    """The verdict of a line-delay result (LineDelayResult or LinearInterpResult, with its self-check
    when run) with its findings; frame_rate_hz and bits_per_pixel of the video when known, and the
    camera check of pipeline.check_camera when it ran."""
    return diagnose_evidence(line_delay_evidence(result, frame_rate_hz=frame_rate_hz, bits_per_pixel=bits_per_pixel,
                                                 camera_check=camera_check))


def judge_line_delay(result, *, frame_rate_hz: Optional[float] = None,
                     bits_per_pixel: Optional[float] = None) -> Verdict:
    """The verdict of a line-delay result (diagnose(...).verdict)."""
    return diagnose(result, frame_rate_hz=frame_rate_hz, bits_per_pixel=bits_per_pixel).verdict
