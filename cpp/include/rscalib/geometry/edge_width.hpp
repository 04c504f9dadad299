#pragma once
// The detectors' blur measure (rscalib.detection.quality.edge_width_px), split around the image
// sampling, which stays OpenCV's (cv2.remap): where to sample an intensity profile across each of
// the target's edges, then the edge width from the sampled profiles. The numbers are numpy's to
// the bit (element by element, in numpy's order of operations): the two halves replace ~40 small
// numpy calls a detected frame (0.25 ms of a tracked frame's ~2 ms).
#include <Eigen/Core>

namespace rscalib::geometry {

// Where the profiles run: one row per kept edge, profile_s.size() samples each.
struct EdgeProfileMaps {
  Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> map_x, map_y;
  Eigen::VectorXd half_px;  // each profile's half length
};

// a, b (m x 2): the pixels at the two ends of each target edge. across_rim: circle grids (from
// each centre fraction x the edge's length towards the other, both directions, across the
// circle's rim, as long again); otherwise across the edge at its midpoint, half length
// fraction x the edge's length. Half
// lengths are capped at max_half_px; profiles shorter than min_half_px and edges of (near) zero
// length are left out. profile_s: the sample positions in [-1, 1].
EdgeProfileMaps EdgeProfileMapsFor(const Eigen::MatrixX2d& a, const Eigen::MatrixX2d& b,
                                   bool across_rim, double fraction,
                                   const Eigen::VectorXd& profile_s, double max_half_px,
                                   double min_half_px);

// The 75th percentile (linear interpolation) over the profiles (m x samples, grey levels) of the
// edge width contrast / steepest slope - one sample step, after a 3-tap smoothing; profiles with
// a contrast of min_contrast grey levels or less (or no slope) are left out. NaN if none is left.
double EdgeWidthFromProfiles(
    const Eigen::Ref<const Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>>&
        profiles,
    const Eigen::VectorXd& half_px, double min_contrast);

}  // namespace rscalib::geometry
