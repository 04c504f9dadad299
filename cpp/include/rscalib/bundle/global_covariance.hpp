#pragma once
// The covariance of the bundle adjustment's global unknowns (the free camera parameters and the
// line delay) from its linearisation at the minimum (docs/sog.md §23), three ways:
//   model     sigma^2 [H^-1]_gg, H = sum_o J_o^T w_o J_o, sigma^2 = sum_o w_o |r_o|^2 / dof
//   by track  sum_c g_c g_c^T G/(G-1), g_c = [H^-1]_g. sum_{o in c} J_o^T w_o r_o over the
//             observations of point c (cluster-robust: errors correlated along a track count once)
//   two-way   V_track + V_keyframe - V_observation (Cameron, Gelbach & Miller 2011), keyframes the
//             observing ones, each with its G/(G-1); clipped to positive semi-definite
// w_o: the robust loss's weight rho'(|r_o|^2) (iteratively reweighted least squares). [H^-1]_g. is
// reached through Schur complements, never a dense inverse of H: the points' 3x3 blocks are
// eliminated into S over [globals; poses], then the poses (a sparse Cholesky factorisation) into
// the globals' own small block M = S_gg - S_gp S_pp^-1 S_pg, whose inverse is [H^-1]_gg; the
// other rows of H^-1 E_g follow by back-substitution. Singular point blocks (a point whose depth
// the keyframes do not fix) take a pseudo-inverse, as the Python adjustment does.
#include <vector>

#include <Eigen/Core>

namespace rscalib::bundle {

constexpr int kMaxGlobals = 10;  // 9 camera parameters (pinhole-radtan) + the line delay

// The tangent layout of the unknowns: the globals first, then each keyframe's pose (0 when held,
// 5 for the scale keyframe, 6 otherwise), then 3 per point.
struct UnknownLayout {
  int num_globals = 0;
  std::vector<int> pose_size;  // per keyframe
  int num_points = 0;
};

// One observation linearised at the solution: residual, robust weight, Jacobians in the tangent
// spaces of its blocks (only the first pose_size columns of a pose block are read).
struct ObservationLinearisation {
  int point = 0;
  int keyframe = 0;        // the observing keyframe (the cluster of the two-way covariance)
  int pose[2] = {-1, -1};  // the keyframes whose poses the residual depends on; -1: none
  Eigen::Vector2d residual = Eigen::Vector2d::Zero();
  double weight = 1.0;
  Eigen::Matrix<double, 2, Eigen::Dynamic, Eigen::RowMajor, 2, kMaxGlobals> d_r_d_globals;
  Eigen::Matrix<double, 2, 6, Eigen::RowMajor> d_r_d_pose[2];
  Eigen::Matrix<double, 2, 3, Eigen::RowMajor> d_r_d_point;
};

// A Gaussian prior on one global, in the units of the pixel residuals: it adds `information` to
// H's diagonal and, as one more independent cluster, `score_variance` to the clustered sums.
struct GlobalPrior {
  int global = 0;
  double information = 0.0;
  double score_variance = 0.0;
};

struct GlobalCovariances {
  Eigen::MatrixXd model;           // (g, g)
  Eigen::MatrixXd by_track;        // (g, g)
  Eigen::MatrixXd two_way;         // (g, g)
  Eigen::MatrixXd inverse_normal;  // [H^-1]_gg (g, g)
  Eigen::VectorXd step;            // the globals' remaining Gauss-Newton step, -[H^-1 J^T W r]_g
  double sigma_px = 0.0;           // sqrt(sum w |r|^2 / dof)
  int dof = 0;                     // 2 N - unknowns
  bool full_rank = true;  // false: a pseudo-inverse stood in for a singular pose or global block
  int num_tracks = 0;     // clusters with observations
  int num_keyframes = 0;
};

// Throws InputError on inconsistent sizes or indices. The poses' block S_pp is factorised densely
// (blocked Cholesky) when it is over 5 % full and has at most dense_pose_limit rows (long tracks
// link most keyframes), else by a sparse LDL^T.
GlobalCovariances ComputeGlobalCovariances(const UnknownLayout& layout,
                                           const std::vector<ObservationLinearisation>& obs,
                                           const std::vector<GlobalPrior>& priors = {},
                                           int dense_pose_limit = 6000);

}  // namespace rscalib::bundle
