"""Intrinsic calibration from stills or a slow video of a target (OpenCV), for the camera files engine 1 needs."""
