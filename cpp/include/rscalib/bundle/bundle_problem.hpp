#pragma once
// The self-calibration bundle adjustment (docs/sog.md §23): one shared camera (any camera model,
// a mask of its free parameters), the rolling shutter's line delay (held, estimated, or estimated
// with a Gaussian prior), a pose per keyframe and an anchored inverse-depth point per feature
// track (anchored_point.hpp), fitted to the tracks' pixels with a robust loss by Ceres
// (Levenberg-Marquardt, SPARSE_SCHUR with SuiteSparse, the points eliminated). Then the
// covariance of the globals (the free camera parameters and the line delay) three ways
// (global_covariance.hpp).
//
// Gauge: the first keyframe's pose is held; the scale by holding the distance between the first
// keyframe's camera centre and the scale keyframe's (by default the one farthest from it at the
// start) with baseline_manifold.hpp. Other poses move on pose_manifold.hpp.
#include <string>
#include <vector>

#include <Eigen/Core>

#include "rscalib/camera/camera_model.hpp"

namespace rscalib::bundle {

using KeyframePoseMatrix = Eigen::Matrix<double, Eigen::Dynamic, 6, Eigen::RowMajor>;
using AnchoredPointMatrix = Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor>;

// The tracks' pixels at the keyframes: N observations.
struct BundleObservations {
  Eigen::VectorXi keyframe;              // (N) index into the keyframe poses
  Eigen::VectorXi point;                 // (N) index into the points
  Eigen::MatrixX2d uv_px;                // (N, 2) observed (distorted) pixels
  Eigen::MatrixX2d image_velocity_px_s;  // (N, 2) the track's image velocity there; 0: still
};

enum class LineDelayMode { kFixed, kEstimated, kPrior };

struct LineDelaySetting {
  LineDelayMode mode = LineDelayMode::kFixed;
  double value_s = 0.0;        // the held value (kFixed) or the start (kEstimated, kPrior)
  double prior_mean_s = 0.0;   // kPrior
  double prior_sigma_s = 0.0;  // kPrior, > 0
};

struct BundleData {
  Eigen::Matrix<bool, Eigen::Dynamic, 1> free_intrinsics;  // per camera parameter; empty: all
  KeyframePoseMatrix keyframe_poses;                       // (K, 6) [p; phi] T_cw, start
  BundleObservations observations;
  Eigen::VectorXi point_anchor;  // (P) anchor keyframe of each point
  AnchoredPointMatrix points;    // (P, 3) (a, b, rho), start
  LineDelaySetting line_delay;
  double reference_row = 0.0;  // v_ref of the shutter term, px
};

struct BundleOptions {
  std::string robust_loss = "soft_l1";  // none | huber | cauchy | soft_l1 (Ceres' losses)
  double robust_loss_scale_px = 2.0;    // where the loss leaves its quadratic part
  int max_iterations = 200;
  double function_tolerance = 1e-9;  // the globals' remaining step <= 0.001 sigma (sog.md §23)
  double gradient_tolerance = 1e-12;
  double parameter_tolerance = 1e-10;
  int num_threads = 2;
  std::string linear_solver = "sparse_schur";  // sparse_schur | dense_schur | iterative_schur
  // Bounds of each point's inverse depth rho, relative to the median start rho m: a point stays
  // farther from its anchor than near_limit / m (rho <= m / near_limit) and at most
  // beyond_infinity_limit m beyond infinity (rho >= -beyond_infinity_limit m). <= 0 / < 0: none.
  double near_limit = 0.01;
  double beyond_infinity_limit = 0.1;
  int scale_keyframe = -1;  // -1: the keyframe farthest from the first at the start
  // Solve with the points free first: points that end outside the bounds above are dropped as
  // outliers while they are at most max_out_of_range_share of the points; more: solved again from
  // the start with Ceres' bounds (docs/sog.md §23). false: Ceres' bounds from the start.
  bool free_points_first = true;
  double max_out_of_range_share = 0.01;
  // The free solve's iterations at most (0: no cap of its own); a free solve that has not
  // converged by then goes on bounded from where it is (far points crawl along their valley
  // while free: docs/sog.md §25).
  int max_free_iterations = 0;
  double prior_pixel_sigma_px = 0.5;  // the pixel noise a line-delay prior is weighed against
  bool compute_covariance = true;
  bool verbose = false;  // Ceres' per-iteration log to stderr
};

struct BundleResult {
  // The estimate.
  Eigen::VectorXd camera_params;  // the camera model's layout
  double line_delay_s = 0.0;
  KeyframePoseMatrix keyframe_poses;              // (K, 6)
  AnchoredPointMatrix points;                     // (P, 3)
  Eigen::MatrixX2d residuals_px;                  // (N, 2) uv_obs - prediction; NaN where not used
  Eigen::Matrix<bool, Eigen::Dynamic, 1> used;    // (N) false: dropped at the start
  Eigen::Matrix<bool, Eigen::Dynamic, 1> inlier;  // (N) |r| <= the loss scale (used only)
  int dropped_observations = 0;  // could not be projected at the start, or their point
                                 // was then seen fewer than twice
  int dropped_points = 0;
  // Bounds of each point's inverse depth rho, relative to the median start rho m: a point stays
  // farther from its anchor than near_limit / m (rho <= m / near_limit) and at most
  // beyond_infinity_limit m beyond infinity (rho >= -beyond_infinity_limit m). <= 0 / < 0: none.
  double near_limit = 0.01;
  double beyond_infinity_limit = 0.1;
  int scale_keyframe = -1;         // the keyframe whose distance from the first was held
  int points_beyond_infinity = 0;  // rho < 0 at the end (far points' noise)
  int points_at_bounds = 0;     // rho at a bound (BundleOptions::near_limit, beyond_infinity_limit)
  int points_out_of_range = 0;  // ended outside the bounds in the free solve: dropped
  bool solved_with_bounds = false;  // Ceres' bounds gave the result (too many left the range,
                                    // or the free solve reached max_free_iterations)
  // Ceres' summary.
  std::string termination;  // CONVERGENCE | NO_CONVERGENCE | FAILURE | ...
  bool converged = false;
  int iterations = 0;
  double initial_cost = 0.0;  // Ceres' cost: 1/2 sum rho(|r|^2) (+ the prior)
  double final_cost = 0.0;
  std::string message;
  double solve_time_s = 0.0;
  double covariance_time_s = 0.0;
  // The covariance of the globals, (n + 1, n + 1): the camera's n parameters in its layout, then
  // the line delay in s/row; rows and columns of held unknowns are zero.
  double sigma_px = 0.0;  // robustly weighted residual sigma, sqrt(sum w r^2 / dof)
  double rms_px = 0.0;    // of the used residuals, per coordinate
  int dof = 0;
  bool covariance_ok = false;  // computed, every block invertible
  Eigen::MatrixXd covariance_model;
  Eigen::MatrixXd covariance_tracks;   // clustered by track (point)
  Eigen::MatrixXd covariance_two_way;  // clustered by track and by keyframe
  Eigen::VectorXd remaining_step;      // (n + 1) the globals' remaining Gauss-Newton step
  double step_sigma = 0.0;             // its largest |step| / model sigma over the free globals
};

// Throws InputError on bad input (sizes, indices, NaN, too few observations, nothing free, more
// memory than the machine has); never aborts.
BundleResult SolveBundle(const camera::CameraModel& camera, const BundleData& data,
                         const BundleOptions& options);

}  // namespace rscalib::bundle
