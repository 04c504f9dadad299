"""Simulation for tests, benchmarks and `rscalib simulate`: trajectories, rolling-shutter target videos, textured-scene videos, feature-level sequences. No production module imports it."""
