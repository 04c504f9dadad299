"""Target detection: detectors for one image, quality checks, the video pipeline with worker processes, and its cache."""
