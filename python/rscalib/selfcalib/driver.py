"""The one per-frame loop of self-calibration (docs/sog.md §1), for images and for simulated features.

Per frame: predict the bank over the time step (constant velocity, docs/sog.md §3), predict the
visible features' pixels with their merged covariances (Civera et al. 2009, eq. 5), let a
*measurement source* search for them, update every filter, the weights and the SPRT (eq. 1–4,
14–18), tell the source which features the bank deleted, start new features where the map is thin,
and record the calibration. The source is the only part that differs:

- :class:`rscalib.selfcalib.front_end.ImageFrontEnd`: frames are images; NCC active search inside
  each 99 % ellipse, new features at corners;
- ``rscalib.sim.scene_features.TrueCorrespondences``: frames are indices of a simulated sequence
  whose correspondences are known (it satisfies :class:`MeasurementSource` structurally and does
  not import this module).
"""
from __future__ import annotations

import itertools
import time
from dataclasses import dataclass
from typing import Any, Callable, Iterable, Optional, Protocol

import numpy as np

from .._core import SogBank, SogUpdateReport
from ..errors import InputError
from .options import FrontEndOptions

__all__ = ["FrameSearch", "MeasurementSource", "OUT_OF_VIEW_FRAMES", "SelfCalibHistory", "run_bank"]

# Frames after which a feature not predicted inside the image may be deleted (run_bank's
# out_of_view_frames). Off by default: the bank's cap (SogOptions.max_features) already bounds the map
# and deletes the features not searched, oldest first; deleting them earlier lost the features a walk
# sees again, and the README's room walk then ended with 2 Gaussians instead of 1.
OUT_OF_VIEW_FRAMES = 60


@dataclass(frozen=True)
class FrameSearch:
    """One frame's active search: the features the bank predicted (``ids`` (n,), ``uv_pred`` (n, 2),
    ``cov`` (n, 2, 2)) and what the source measured (``uv`` (n, 2), NaN where not ``found`` (n,))."""

    ids: np.ndarray
    uv_pred: np.ndarray
    cov: np.ndarray
    uv: np.ndarray
    found: np.ndarray


class MeasurementSource(Protocol):
    """What the loop needs from a front end. ``frame`` is what the frames iterable pairs with each
    time: an image for the image front end, a frame index for the simulator."""

    def measure(self, frame: Any, ids: np.ndarray, uv_pred: np.ndarray,
                cov: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Search ``frame`` for the predicted features: pixels (n, 2) (NaN where not found) and
        found (n,) bool. Every predicted feature counts as searched (the deletion rule needs misses)."""
        ...

    def forget(self, feature_ids: np.ndarray) -> None:
        """The bank deleted these features."""
        ...

    def new_features(self, frame: Any, count: int, search: FrameSearch) -> np.ndarray:
        """At most ``count`` pixels (m, 2) where new features should start, away from the features of
        this frame's ``search``; (0, 2) when there are none."""
        ...

    def track(self, frame: Any, feature_ids: np.ndarray, uv: np.ndarray) -> None:
        """The bank started ``feature_ids`` at ``uv``, the pixels :meth:`new_features` just returned."""
        ...


@dataclass
class SelfCalibHistory:
    """Per processed frame: its index in the frame sequence, the bank's moment-matched calibration
    ``mean`` (K, 5) [f, cx, cy, k1 (mm^-2), k2 (mm^-4)] and 99 % ``bounds_99`` (K, 5, 2), the number of
    Gaussians, the measurements used in the update, the map size after the frame, and the wall time
    of the filter calls (s); ``elapsed_s`` is the wall time of the whole loop."""

    frame: np.ndarray
    mean: np.ndarray
    bounds_99: np.ndarray
    gaussians: np.ndarray
    features_used: np.ndarray
    map_size: np.ndarray
    filter_time_s: np.ndarray
    elapsed_s: float

    def __len__(self) -> int:
        return len(self.frame)

    @property
    def collapse_frame(self) -> Optional[int]:
        """The first frame after which the bank holds one Gaussian (None if it never does)."""
        single = np.flatnonzero(self.gaussians == 1)
        return int(self.frame[single[0]]) if len(single) else None

    @property
    def frames_per_s(self) -> float:
        return len(self) / self.elapsed_s if self.elapsed_s > 0 else float("inf")

    def summary_dict(self) -> dict:
        return {"frame": self.frame.tolist(), "mean": self.mean.tolist(), "bounds_99": self.bounds_99.tolist(),
                "gaussians": self.gaussians.tolist(), "features_used": self.features_used.tolist()}


def run_bank(bank: SogBank, frames: Iterable[tuple[float, Any]], source: MeasurementSource, *,
             min_visible: Optional[int] = None, max_new_per_frame: Optional[int] = None,
             max_frames: Optional[int] = None,
             out_of_view_frames: Optional[int] = None,
             on_frame: Optional[Callable[[int, SogBank, SogUpdateReport], None]] = None
             ) -> SelfCalibHistory:
    """Run ``bank`` over ``frames``, pairs (time in s, frame) with increasing times; a frame of None
    (unreadable) is skipped. While fewer than ``min_visible`` measurements were used in a frame's
    update, ask ``source`` for new features: as many as missing in the first frame (to start the
    map at once), at most ``max_new_per_frame`` later (None: FrontEndOptions' values). A feature the
    bank has not predicted inside
    the image for ``out_of_view_frames`` processed frames is deleted (None: never). Stops after
    ``max_frames`` frames.
    ``on_frame(k, bank, report)`` is called after each processed frame."""
    defaults = FrontEndOptions()
    min_visible = defaults.min_visible if min_visible is None else min_visible
    max_new_per_frame = defaults.max_new_per_frame if max_new_per_frame is None else max_new_per_frame
    rows: dict[str, list] = {name: [] for name in ("frame", "mean", "bounds", "gaussians", "used", "map", "time")}
    t_prev = None
    last_in_view: dict[int, int] = {}   # feature id -> the last processed frame it was predicted in view
    processed = 0
    started = time.perf_counter()
    for k, (t_s, frame) in enumerate(itertools.islice(frames, max_frames)):
        if frame is None:
            continue
        first = t_prev is None
        t0 = time.perf_counter()
        if not first:
            dt = float(t_s - t_prev)
            if not dt > 0:
                raise InputError(f"frame times must increase (frame {k}: dt = {dt} s)")
            bank.predict(dt)
        ids, uv_pred, cov = bank.predict_measurements()
        filter_s = time.perf_counter() - t0
        last_in_view.update((int(fid), processed) for fid in ids)
        uv, found = source.measure(frame, ids, uv_pred, cov)
        t0 = time.perf_counter()
        report = bank.update(ids, uv, found)
        filter_s += time.perf_counter() - t0
        source.forget(report.deleted_feature_ids)
        for fid in report.deleted_feature_ids:
            last_in_view.pop(int(fid), None)
        if out_of_view_frames is not None:
            gone = np.array([fid for fid, seen in last_in_view.items() if processed - seen >= out_of_view_frames],
                            dtype=np.int64)
            if len(gone):
                bank.remove_features(gone)
                source.forget(gone)
                for fid in gone:
                    del last_in_view[int(fid)]
        needed = min_visible - int(report.num_used)
        if needed > 0:
            count = needed if first else min(needed, max_new_per_frame)
            new_uv = source.new_features(frame, count, FrameSearch(ids, uv_pred, cov, uv, found))
            if len(new_uv):
                t0 = time.perf_counter()
                new_ids = bank.add_features(new_uv)
                filter_s += time.perf_counter() - t0
                source.track(frame, new_ids, new_uv)
                last_in_view.update((int(fid), processed) for fid in new_ids)
        t_prev = t_s
        processed += 1
        rows["frame"].append(k)
        rows["mean"].append(np.asarray(bank.calibration_mean))
        rows["bounds"].append(np.asarray(bank.calibration_bounds_99()))
        rows["gaussians"].append(bank.num_gaussians)
        rows["used"].append(int(report.num_used))
        rows["map"].append(bank.num_features)
        rows["time"].append(filter_s)
        if on_frame is not None:
            on_frame(k, bank, report)
    elapsed = time.perf_counter() - started
    if not rows["frame"]:
        raise InputError("no frames to process")
    return SelfCalibHistory(frame=np.asarray(rows["frame"]), mean=np.asarray(rows["mean"]),
                            bounds_99=np.asarray(rows["bounds"]), gaussians=np.asarray(rows["gaussians"]),
                            features_used=np.asarray(rows["used"]), map_size=np.asarray(rows["map"]),
                            filter_time_s=np.asarray(rows["time"]), elapsed_s=elapsed)
