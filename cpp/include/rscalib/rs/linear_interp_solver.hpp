#pragma once
// Line delay with the baseline trajectory model of Hedborg et al. 2012: one pose per frame,
// linear / SLERP interpolation between consecutive frames (linear_interp_cost.hpp).
// Ceres, trust-region DOGLEG, SPARSE_NORMAL_CHOLESKY, as the spline solver.
//
// Pairing. An observation of frame k at row v is taken at t = t_k + v d. Frames k and
// k + 1 are neighbours when t_{k+1} - t_k <= max_frame_interval_s (a longer interval is a
// gap: frames without detections or without a pose break the chain). With v d >= 0 the
// observation uses the pair (k, k + 1); with v d < 0 (only for a negative d) the pair
// (k - 1, k). When that neighbour is missing (chain end) it uses the pair on the other
// side, extrapolated (s outside [0, 1]: `extrapolated`); a frame with no neighbour at all
// is dropped (`isolated`). Pairs depend on the sign of d, so they are re-chosen between
// solves until none changes.
#include <string>
#include <vector>

#include <Eigen/Core>

#include "rscalib/camera/camera_model.hpp"

namespace rscalib::rs {

// One row per detected target point; frames index into the frame arrays of the solve.
struct LinearInterpObservations {
  Eigen::VectorXi frame_index;  // (M) frame of the observation
  Eigen::MatrixX2d uv;          // (M, 2) measured pixel
  Eigen::MatrixX3d point_w;     // (M, 3) target point, world (= target) frame
};

// Per-frame poses T_cw at the frames' row-0 times, one [p; phi] row per frame (contiguous).
using FramePoseMatrix = Eigen::Matrix<double, Eigen::Dynamic, 6, Eigen::RowMajor>;

struct LinearInterpOptions {
  double pixel_sigma = 0.3;           // R = sigma^2 I, px
  bool standardise_errors = false;    // the baseline is plain reprojection error / sigma
  double max_rs_gain = 0.8;           // clamp of d * v_dot when standardising
  double max_frame_interval_s = 0.0;  // neighbours at most this far apart; 0: 1.5 x median
  bool estimate_line_delay = true;    // false: poses only
  std::string robust_loss = "none";   // none | huber | cauchy
  double robust_loss_scale = 3.0;     // in standardised units (sigmas)
  int max_iterations = 100;
  int max_outer_iterations = 4;  // re-pairing rounds (only a sign change of d re-pairs)
  double function_tolerance = 1e-9;
  double gradient_tolerance = 1e-12;
  double parameter_tolerance = 1e-10;
  int num_threads = 2;
  bool compute_covariance = true;
  bool verbose = false;
};

struct LinearInterpSummary {
  bool converged = false;
  std::string message;
  int iterations = 0;
  int outer_iterations = 0;
  double line_delay_s = 0.0;
  double line_delay_std_s = 0.0;  // +inf when the covariance is rank deficient
  bool covariance_ok = false;
  double measurement_cost = 0.0;  // J = sum of squared (standardised) errors
  int num_error_terms = 0;        // N (2-D errors used)
  double rms_px = 0.0;            // RMS of the raw pixel errors (per coordinate)
  int isolated = 0;               // observations dropped: their frame has no neighbour
  int extrapolated = 0;           // observations using the pair on the other side
  int unprojectable = 0;          // observations dropped (behind the camera etc.)
  int clamped_weights = 0;
  int num_chains = 0;                 // runs of neighbouring frames (>= 2 frames)
  double max_frame_interval_s = 0.0;  // the threshold used
  double solve_time_s = 0.0;
  double covariance_time_s = 0.0;
  // Per observation: first frame a of its pair (-1: not used), raw error, squared
  // standardised norm and time t_k + v d.
  Eigen::VectorXi pair_first;
  Eigen::MatrixX2d residual_px;
  Eigen::MatrixX2d image_velocity_px_s;  // (M, 2) d(uv)/dt at the final estimate, NaN if not used
  Eigen::VectorXd standardised_sq;
  Eigen::VectorXd observation_time_s;
};

// Refines `frame_poses` (F x 6, T_cw at frame_time_s) and `line_delay_s` in place. Poses of
// frames that no observation uses are left as given.
LinearInterpSummary SolveLineDelayLinear(const LinearInterpObservations& observations,
                                         const Eigen::VectorXd& frame_time_s,
                                         const camera::CameraModel& camera,
                                         FramePoseMatrix* frame_poses, double* line_delay_s,
                                         const LinearInterpOptions& options);

// T_cw ([p; phi], |phi| <= pi) at parameter s between poses a and b (s = 0: a, s = 1: b).
Eigen::Matrix<double, 6, 1> LinearInterpPoseState(const Eigen::Matrix<double, 6, 1>& pose_a,
                                                  const Eigen::Matrix<double, 6, 1>& pose_b,
                                                  double s);

}  // namespace rscalib::rs
