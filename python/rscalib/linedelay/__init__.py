"""Engine 1: the rolling-shutter line delay from a video of a known target (Oth et al. 2013), with the linear/SLERP baseline."""
