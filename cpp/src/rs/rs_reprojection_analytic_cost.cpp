#include "rscalib/rs/rs_reprojection_analytic_cost.hpp"

#include <utility>
#include <vector>

#include <ceres/jet.h>

namespace rscalib::rs {

namespace {

constexpr int kStateDim = geometry::kPoseStateDim;

// r = W (y - pi(T(x) P)) for a pose state x; false if the point cannot be projected.
template <typename T>
bool ResidualOfState(const SpanCamera& cam, const WeightedMeasurement& measurement, const T* state,
                     T* residual) {
  T point_c[3];
  geometry::TransformWorldToCamera(state, measurement.point_w, point_c);
  T uv[2];
  if (!cam.Project(point_c, uv)) return false;
  measurement.Residual(uv, residual);
  return true;
}

// The chain of docs/formulation.md §15 into the Jacobians of blocks c0..c3 and d (each may be
// null): dr/dc_j = w_j(u) G, dr/dd = G x'(u) v, with G = dr/dx.
void ChainStateJacobian(const Eigen::Matrix<double, 2, kStateDim>& dr_dstate,
                        const double (&weights)[3][4], double const* const* parameters, double v,
                        double** jacobians) {
  for (int j = 0; j < 4; ++j) {
    if (!jacobians[j]) continue;
    Eigen::Map<Eigen::Matrix<double, 2, kStateDim, Eigen::RowMajor>> jacobian(jacobians[j]);
    jacobian = weights[0][j] * dr_dstate;
  }
  if (jacobians[4]) {
    double state_rate[kStateDim];  // dx/du
    spline::CombineControlPoints(weights[1], parameters, kStateDim, state_rate);
    const Eigen::Vector2d dr_dd =
        dr_dstate * (v * Eigen::Map<const Eigen::Matrix<double, kStateDim, 1>>(state_rate));
    jacobians[4][0] = dr_dd[0];
    jacobians[4][1] = dr_dd[1];
  }
}

// A group's members evaluated in turn: member m's residuals at row 2m, its row-major Jacobian rows
// at row 2m of each (2k x block size) block Jacobian.
template <typename Term, size_t kBlocks>
bool EvaluateMembers(const std::vector<Term>& terms, const int (&block_sizes)[kBlocks],
                     double const* const* parameters, double* residuals, double** jacobians) {
  double* member_jacobians[kBlocks];
  for (size_t m = 0; m < terms.size(); ++m) {
    if (jacobians) {
      for (size_t b = 0; b < kBlocks; ++b)
        member_jacobians[b] = jacobians[b] ? jacobians[b] + 2 * m * block_sizes[b] : nullptr;
    }
    if (!terms[m].Evaluate(parameters, residuals + 2 * m, jacobians ? member_jacobians : nullptr))
      return false;
  }
  return true;
}

}  // namespace

AnalyticReprojectionTerm::AnalyticReprojectionTerm(const spline::SpanPowerBasis& basis_in,
                                                   const SpanCamera& cam_in,
                                                   double frame_time_minus_span_start_s,
                                                   const double* uv_measured, const double* point_w,
                                                   const Eigen::Matrix2d& sqrt_information)
    : basis(basis_in),
      cam(cam_in),
      frame_offset_s(frame_time_minus_span_start_s),
      measurement(uv_measured, point_w, sqrt_information) {
  basis.span_start = 0.0;
}

bool AnalyticReprojectionTerm::Evaluate(double const* const* parameters, double* residuals,
                                        double** jacobians) const {
  // The same arithmetic as RsReprojectionCost / ProjectAtSpanTime, in double.
  const double v = measurement.uv[1];
  const double u = frame_offset_s + v * parameters[4][0];
  double weights[3][4];
  spline::EvaluateSpanBasis(basis, u, jacobians ? 1 : 0, weights);
  double state[kStateDim];
  spline::CombineControlPoints(weights[0], parameters, kStateDim, state);
  if (!jacobians) return ResidualOfState(cam, measurement, state, residuals);

  using Jet = ceres::Jet<double, kStateDim>;
  Jet state_jet[kStateDim];
  for (int k = 0; k < kStateDim; ++k) state_jet[k] = Jet(state[k], k);
  Jet residual_jet[2];
  if (!ResidualOfState(cam, measurement, state_jet, residual_jet)) return false;
  residuals[0] = residual_jet[0].a;
  residuals[1] = residual_jet[1].a;
  const Eigen::Matrix<double, 2, kStateDim> dr_dstate =
      (Eigen::Matrix<double, 2, kStateDim>() << residual_jet[0].v.transpose(),
       residual_jet[1].v.transpose())
          .finished();
  ChainStateJacobian(dr_dstate, weights, parameters, v, jacobians);
  return true;
}

RsReprojectionGroupCost::RsReprojectionGroupCost(std::vector<AnalyticReprojectionTerm> terms)
    : terms_(std::move(terms)) {
  set_num_residuals(2 * static_cast<int>(terms_.size()));
  *mutable_parameter_block_sizes() = {6, 6, 6, 6, 1};
}

bool RsReprojectionGroupCost::Evaluate(double const* const* parameters, double* residuals,
                                       double** jacobians) const {
  constexpr int kBlockSizes[5] = {6, 6, 6, 6, 1};
  return EvaluateMembers(terms_, kBlockSizes, parameters, residuals, jacobians);
}

AnalyticIntrinsicsTerm::AnalyticIntrinsicsTerm(const spline::SpanPowerBasis& basis_in,
                                               const CameraModelOf& camera_in,
                                               double frame_time_minus_span_start_s,
                                               const double* uv_measured, const double* point_w,
                                               const Eigen::Matrix2d& sqrt_information)
    : basis(basis_in),
      camera(camera_in),
      frame_offset_s(frame_time_minus_span_start_s),
      measurement(uv_measured, point_w, sqrt_information) {
  basis.span_start = 0.0;
}

bool AnalyticIntrinsicsTerm::Evaluate(double const* const* parameters, double* residuals,
                                      double** jacobians) const {
  const double v = measurement.uv[1];
  const double u = frame_offset_s + v * parameters[4][0];
  double weights[3][4];
  spline::EvaluateSpanBasis(basis, u, jacobians ? 1 : 0, weights);
  double state[kStateDim];
  spline::CombineControlPoints(weights[0], parameters, kStateDim, state);
  const double* theta = parameters[5];
  if (!jacobians) {
    double point_c[3], uv[2];
    geometry::TransformWorldToCamera(state, measurement.point_w, point_c);
    if (!camera.Project(theta, point_c, uv)) return false;
    measurement.Residual(uv, residuals);
    return true;
  }

  constexpr int kWidth = kStateDim + kIntrinsicsBlockSize;
  using Jet = ceres::Jet<double, kWidth>;
  Jet state_jet[kStateDim], theta_jet[kIntrinsicsBlockSize];
  for (int k = 0; k < kStateDim; ++k) state_jet[k] = Jet(state[k], k);
  for (int k = 0; k < kIntrinsicsBlockSize; ++k) theta_jet[k] = Jet(theta[k], kStateDim + k);
  Jet point_c[3], uv[2], residual_jet[2];
  geometry::TransformWorldToCamera(state_jet, measurement.point_w, point_c);
  if (!camera.Project(theta_jet, point_c, uv)) return false;
  measurement.Residual(uv, residual_jet);
  residuals[0] = residual_jet[0].a;
  residuals[1] = residual_jet[1].a;
  Eigen::Matrix<double, 2, kStateDim> dr_dstate;
  for (int r = 0; r < 2; ++r) dr_dstate.row(r) = residual_jet[r].v.head<kStateDim>().transpose();
  ChainStateJacobian(dr_dstate, weights, parameters, v, jacobians);
  if (jacobians[5]) {
    Eigen::Map<Eigen::Matrix<double, 2, kIntrinsicsBlockSize, Eigen::RowMajor>> dr_dtheta(
        jacobians[5]);
    for (int r = 0; r < 2; ++r)
      dr_dtheta.row(r) = residual_jet[r].v.tail<kIntrinsicsBlockSize>().transpose();
  }
  return true;
}

RsReprojectionIntrinsicsGroupCost::RsReprojectionIntrinsicsGroupCost(
    std::vector<AnalyticIntrinsicsTerm> terms)
    : terms_(std::move(terms)) {
  set_num_residuals(2 * static_cast<int>(terms_.size()));
  *mutable_parameter_block_sizes() = {6, 6, 6, 6, 1, kIntrinsicsBlockSize};
}

bool RsReprojectionIntrinsicsGroupCost::Evaluate(double const* const* parameters, double* residuals,
                                                 double** jacobians) const {
  constexpr int kBlockSizes[6] = {6, 6, 6, 6, 1, kIntrinsicsBlockSize};
  return EvaluateMembers(terms_, kBlockSizes, parameters, residuals, jacobians);
}

}  // namespace rscalib::rs
