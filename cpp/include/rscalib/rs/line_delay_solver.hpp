#pragma once
// Joint continuous-time estimation of the camera trajectory and the line delay
// (paper §3-4): Ceres, trust-region DOGLEG, SPARSE_NORMAL_CHOLESKY on SuiteSparse.
//
// Outer loop (at most max_outer_iterations): attach every observation to the span of its
// current time t_i + v d, compute its standardisation weight at the current estimate,
// build the problem, solve. Stop when d has settled and no observation changed span.
#include <string>
#include <vector>

#include <Eigen/Core>

#include "rscalib/camera/camera_model.hpp"
#include "rscalib/spline/cubic_bspline.hpp"

namespace rscalib::rs {

// One row per detected target point.
struct RsObservations {
  Eigen::VectorXd frame_time_s;  // (M) time row 0 of the observation's frame is exposed
  Eigen::MatrixX2d uv;           // (M, 2) measured pixel
  Eigen::MatrixX3d point_w;      // (M, 3) target point, world (= target) frame
};

struct RsSolverOptions {
  double pixel_sigma = 0.3;  // R = sigma^2 I, px
  // Optional per-observation noise (M values, px): observation m has R = sigma_m^2 I. Empty:
  // every observation has pixel_sigma (the noise model of docs/formulation.md §8).
  Eigen::VectorXd observation_sigma;
  bool standardise_errors = true;  // A R A^T (false: plain R)
  double max_rs_gain = 0.8;        // clamp of d * v_dot in A
  bool use_motion_prior = true;
  // diag(Q) of the acceleration prior; see docs/formulation.md for why not the paper's
  // 1e-5 / 1e-2 (which biases d with errors standardised in pixels).
  Eigen::Matrix<double, 6, 1> motion_prior_q =
      (Eigen::Matrix<double, 6, 1>() << 1.0, 1.0, 1.0, 1e2, 1e2, 1e2).finished();
  bool estimate_line_delay = true;   // false: trajectory only (localisation)
  std::string robust_loss = "none";  // none | huber | cauchy
  double robust_loss_scale = 3.0;    // in standardised units (sigmas)
  int max_iterations = 100;          // per Ceres solve; 0: build + covariance only
  int max_outer_iterations = 4;
  double function_tolerance = 1e-9;
  double gradient_tolerance = 1e-12;
  double parameter_tolerance = 1e-10;
  int num_threads = 2;
  bool compute_covariance = true;
  // The Jacobian of the reprojection errors chained by hand through the basis weights
  // (RsReprojectionAnalyticCost, docs/formulation.md §15; with refine_intrinsics
  // AnalyticIntrinsicsTerm); false: autodiff of the whole functor (RsReprojectionCost,
  // RsReprojectionIntrinsicsCost; the same numbers, slower; kept as the reference).
  bool analytic_jacobian = true;
  // sigma_d from the Schur complement of the normal equations (docs/formulation.md §15); false:
  // Ceres' covariance (sparse QR). The Schur path falls back to Ceres' when the trajectory block
  // is singular or a robust loss is used; with refine_intrinsics Ceres' covariance is always used.
  bool schur_variance = true;
  // With schur_variance: also each observation's score of d (RsSolveSummary::line_delay_score),
  // a second pass over the Jacobian; for experiments on correlated errors.
  bool line_delay_score = false;
  bool verbose = false;
  // Joint refinement of the intrinsics (docs/formulation.md §14). false: the camera is known
  // (the path of every other option, unchanged). true: the camera's parameters (its layout,
  // docs/conventions.md) are a parameter block, started at the camera passed to the solver and
  // pulled towards intrinsics_prior_mean by the prior N(mean, covariance) on the free ones.
  bool refine_intrinsics = false;
  Eigen::VectorXd intrinsics_prior_mean;        // (n) the model's n parameters
  Eigen::MatrixXd intrinsics_prior_covariance;  // (n, n); rows of fixed parameters ignored
  std::vector<int> fixed_intrinsics;            // indices held at the starting value
};

struct RsSolveSummary {
  bool converged = false;  // Ceres reported convergence in the last solve
  std::string message;     // Ceres' or ours
  int iterations = 0;      // Ceres iterations over all outer loops
  int outer_iterations = 0;
  int reattached = 0;       // observations that changed span in the last re-attach
  int clamped_weights = 0;  // observations whose RS gain was clamped
  int unprojectable = 0;    // observations dropped (behind camera etc.)
  double line_delay_s = 0.0;
  double line_delay_std_s = 0.0;  // +inf when the covariance is rank deficient
  bool covariance_ok = false;
  double measurement_cost = 0.0;  // J = sum of squared standardised errors
  double prior_cost = 0.0;        // motion prior part
  int num_error_terms = 0;        // N (2-D reprojection errors)
  double rms_px = 0.0;            // RMS of the raw pixel errors (per coordinate)
  double solve_time_s = 0.0;
  double covariance_time_s = 0.0;
  // Per knot segment s (spline.num_segments()): J_s and N_s of the errors in it.
  std::vector<double> segment_cost;
  std::vector<int> segment_count;
  // Per observation: raw error e = y - pi(...) and standardised squared norm.
  Eigen::MatrixX2d residual_px;
  Eigen::MatrixX2d image_velocity_px_s;  // (M, 2) d(uv)/dt at the final estimate, NaN if not used
  Eigen::VectorXd standardised_sq;
  Eigen::VectorXd observation_time_s;
  // (M, 2) each observation's linearised contribution to d_hat (u, v; whitened), from the final
  // Schur-complement variance: sums over frames or time windows give a cluster-robust variance
  // of d (docs/formulation.md §8). Empty when that variance was not computed.
  Eigen::MatrixX2d line_delay_score;
  // refine_intrinsics only (empty otherwise): the refined parameters (n, the model's layout),
  // the covariance of [d, intrinsics] ((1 + n) x (1 + n), s/row and the layout's units; zero
  // rows for fixed parameters; empty when not computed) and the prior's cost.
  Eigen::VectorXd intrinsics;
  Eigen::MatrixXd line_delay_intrinsics_covariance;
  double intrinsics_prior_cost = 0.0;
};

// Refines `trajectory` (6-D pose spline [p; phi], T_cw) and `line_delay_s` in place (and, with
// options.refine_intrinsics, the intrinsics starting from `camera`'s: summary.intrinsics).
RsSolveSummary SolveLineDelay(const RsObservations& observations, const camera::CameraModel& camera,
                              spline::CubicBSpline* trajectory, double* line_delay_s,
                              const RsSolverOptions& options);

// Evaluates residuals and per-segment statistics without solving.
RsSolveSummary EvaluateLineDelay(const RsObservations& observations,
                                 const camera::CameraModel& camera,
                                 const spline::CubicBSpline& trajectory, double line_delay_s,
                                 const RsSolverOptions& options);

}  // namespace rscalib::rs
