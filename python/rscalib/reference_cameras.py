"""Cameras of the papers and data we reproduce: the one definition, shared by the self-calibration
prior, the command line's defaults and the simulators (which depend on it, not on each other)."""
from __future__ import annotations

# Civera et al. 2009, §6: an offline calibration of the paper's 320x240 sequence, in the civera-radial
# model (distorted -> undistorted, radii in mm): f px, cx, cy px, k1 mm^-2, k2 mm^-4.
PAPER_CAMERA_PARAMS = (194.06, 160.22, 128.87, 0.06333, 0.0139)
PAPER_IMAGE_SIZE = (320, 240)
PAPER_PIXEL_SIZE_MM = 0.0112

# The S3 phone of ../shared/data/real_selfcalib_s3phone (its offline calibration, civera-radial).
PHONE_CAMERA_PARAMS = (525.06, 308.65, 236.54, -7.613e-3, 9.388e-4)
PHONE_IMAGE_SIZE = (640, 480)
PHONE_PIXEL_SIZE_MM = 0.0070216
