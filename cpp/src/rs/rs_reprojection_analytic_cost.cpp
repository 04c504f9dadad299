#include "rscalib/rs/rs_reprojection_analytic_cost.hpp"

#include <ceres/jet.h>

namespace rscalib::rs {

namespace {

constexpr int kStateDim = geometry::kPoseStateDim;

// r = W (y - pi(T(x) P)) for a pose state x; false if the point cannot be projected.
template <typename T>
bool ResidualOfState(const SpanCamera& cam, const WeightedMeasurement& measurement,
                     const T* state, T* residual) {
  T point_c[3];
  geometry::TransformWorldToCamera(state, measurement.point_w, point_c);
  T uv[2];
  if (!cam.Project(point_c, uv)) return false;
  measurement.Residual(uv, residual);
  return true;
}

}  // namespace

RsReprojectionAnalyticCost::RsReprojectionAnalyticCost(const spline::SpanPowerBasis& basis,
                                                       const SpanCamera& cam,
                                                       double frame_time_minus_span_start_s,
                                                       const double* uv_measured,
                                                       const double* point_w,
                                                       const Eigen::Matrix2d& sqrt_information)
    : basis_(basis),
      cam_(cam),
      frame_offset_s_(frame_time_minus_span_start_s),
      measurement_(uv_measured, point_w, sqrt_information) {
  basis_.span_start = 0.0;
}

bool RsReprojectionAnalyticCost::Evaluate(double const* const* parameters, double* residuals,
                                          double** jacobians) const {
  // The same arithmetic as RsReprojectionCost / ProjectAtSpanTime, in double.
  const double v = measurement_.uv[1];
  const double u = frame_offset_s_ + v * parameters[4][0];
  double weights[3][4];
  spline::EvaluateSpanBasis(basis_, u, jacobians ? 1 : 0, weights);
  double state[kStateDim];
  spline::CombineControlPoints(weights[0], parameters, kStateDim, state);
  if (!jacobians) return ResidualOfState(cam_, measurement_, state, residuals);

  using Jet = ceres::Jet<double, kStateDim>;
  Jet state_jet[kStateDim];
  for (int k = 0; k < kStateDim; ++k) state_jet[k] = Jet(state[k], k);
  Jet residual_jet[2];
  if (!ResidualOfState(cam_, measurement_, state_jet, residual_jet)) return false;
  residuals[0] = residual_jet[0].a;
  residuals[1] = residual_jet[1].a;
  const Eigen::Matrix<double, 2, kStateDim> dr_dstate =
      (Eigen::Matrix<double, 2, kStateDim>() << residual_jet[0].v.transpose(),
       residual_jet[1].v.transpose())
          .finished();
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
  return true;
}

}  // namespace rscalib::rs
