"""What detection over a video returns (shared by the pipeline and the cache)."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..observations import Observations


@dataclass
class DetectionResult:
    """Accepted detections of a video or image sequence.

    observations: frames with an accepted detection only (their times from the source),
                  target_points = target.points_m.
    frame_numbers: (F,) index in the source of each observation frame.
    frame_labels: (F,) file name (stills) or "frame N" (videos) of each observation frame.
    blur_px: (F,) edge width of each observation frame (see edge_width_px).
    frames_total: frames read; frames_total = frames_detected + sum(dropped.values()).
    dropped: reason -> number of frames (DROP_REASONS).
    timestamps: where the times come from: "container", "frame rate", "timestamps file", "frame index".
    """

    observations: Observations
    frames_total: int
    frames_detected: int
    dropped: dict
    from_cache: bool
    image_size: tuple[int, int]
    frame_numbers: np.ndarray
    frame_labels: list
    blur_px: np.ndarray
    timestamps: str
    warnings: list = field(default_factory=list)
    detect_time_s: float = 0.0

    @classmethod
    def from_observations(cls, observations: Observations, timestamps: str = "given") -> DetectionResult:
        """Detections made elsewhere (another detector, a simulation) as a DetectionResult: every
        frame of `observations` detected, none dropped, no blur measured."""
        if not isinstance(observations, Observations):
            raise TypeError("observations must be an rscalib.Observations")
        frames = observations.num_frames
        return cls(observations=observations, frames_total=frames, frames_detected=frames, dropped={},
                   from_cache=False, image_size=tuple(int(x) for x in observations.image_size),
                   frame_numbers=np.arange(frames), frame_labels=[f"frame {k}" for k in range(frames)],
                   blur_px=np.full(frames, np.nan), timestamps=timestamps)
