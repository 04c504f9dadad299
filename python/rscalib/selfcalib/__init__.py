"""Engine 2: sequential self-calibration with a Sum-of-Gaussians bank of inverse-depth EKFs (Civera et al. 2009)."""
