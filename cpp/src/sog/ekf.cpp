// One EKF of the SOG self-calibration bank (docs/sog.md §2-5); the bank: sog_bank.cpp.
// Comments here say why the code is shaped as it is.
#include "rscalib/sog/ekf.hpp"

#include <cmath>

#include <Eigen/Dense>

#include "rscalib/sog/inverse_depth.hpp"

namespace rscalib::sog {

namespace {

// Copies the lower triangle onto the upper one (after triangular-only updates).
void MirrorLower(Eigen::MatrixXd* p) {
  const Eigen::Index n = p->rows();
  for (Eigen::Index j = 1; j < n; ++j)
    for (Eigen::Index i = 0; i < j; ++i) (*p)(i, j) = (*p)(j, i);
}

}  // namespace

SelfCalibrationEkf::SelfCalibrationEkf(const Vector5d& calibration,
                                       const Matrix5d& calibration_covariance,
                                       const MotionState& motion,
                                       const Matrix13d& motion_covariance)
    : x_(kCameraDim), p_(Eigen::MatrixXd::Zero(kCameraDim, kCameraDim)) {
  x_.head<5>() = calibration;
  x_.segment<13>(kPosition) = motion;
  p_.topLeftCorner<5, 5>() = calibration_covariance;
  p_.block<13, 13>(kPosition, kPosition) = motion_covariance;
}

void SelfCalibrationEkf::SetMotionState(const MotionState& motion, const Matrix13d& covariance) {
  x_.segment<13>(kPosition) = motion;
  p_.middleRows<13>(kPosition).setZero();
  p_.middleCols<13>(kPosition).setZero();
  p_.block<13, 13>(kPosition, kPosition) = covariance;
}

void SelfCalibrationEkf::Predict(double dt_s, const ProcessNoise& noise) {
  const MotionState motion = x_.segment<13>(kPosition);
  MotionJacobian f;
  x_.segment<13>(kPosition) = PredictMotion(motion, dt_s, &f, nullptr);
  // Only the 13 motion rows/columns change: P <- F P F^T in O(13^2 n), not O(n^3).
  const Eigen::Matrix<double, 13, Eigen::Dynamic> rows = f * p_.middleRows<13>(kPosition);
  p_.middleRows<13>(kPosition) = rows;
  const Eigen::Matrix<double, Eigen::Dynamic, 13> cols =
      p_.middleCols<13>(kPosition) * f.transpose();
  p_.middleCols<13>(kPosition) = cols;
  p_.block<13, 13>(kPosition, kPosition) +=
      MotionProcessNoise(motion, dt_s, noise.accel_sigma, noise.angular_accel_sigma);
  for (int i = 0; i < kCalibrationDim; ++i) {
    const double s = noise.calibration_random_walk[i];
    p_(i, i) += s * s * dt_s;
  }
}

namespace {

template <int D>
Eigen::Matrix2d InnovationCovariance(const Eigen::MatrixXd& p, int offset,
                                     const Eigen::Matrix<double, 2, 12>& h_camera,
                                     const Eigen::Matrix<double, 2, D>& h_feature,
                                     double variance) {
  const Eigen::Matrix<double, 2, 12> a =
      h_camera * p.topLeftCorner<12, 12>() + h_feature * p.block<D, 12>(offset, 0);
  const Eigen::Matrix<double, 2, D> b =
      h_camera * p.block<12, D>(0, offset) + h_feature * p.block<D, D>(offset, offset);
  Eigen::Matrix2d s = a * h_camera.transpose() + b * h_feature.transpose();
  s = 0.5 * (s + s.transpose()).eval();
  s.diagonal().array() += variance;
  return s;
}

}  // namespace

void SelfCalibrationEkf::PredictMeasurements(const FeatureMap& map, const std::vector<int>& indices,
                                             const Eigen::Vector2d& pixel_size_mm,
                                             double pixel_sigma,
                                             std::vector<FeaturePrediction>* predictions) const {
  const MeasuredCamera camera = measured_camera();
  const double variance = pixel_sigma * pixel_sigma;
  for (int index : indices) {
    const MapFeature& feature = map[index];
    FeaturePrediction& out = (*predictions)[index];
    out.valid =
        ProjectFeatureWithJacobians(camera, pixel_size_mm, feature.kind, x_.data() + feature.offset,
                                    &out.uv, &out.d_uv_d_camera, &out.d_uv_d_feature);
    if (!out.valid) continue;
    if (feature.kind == FeatureKind::kInverseDepth)
      out.innovation_covariance = InnovationCovariance<6>(p_, feature.offset, out.d_uv_d_camera,
                                                          out.d_uv_d_feature, variance);
    else
      out.innovation_covariance = InnovationCovariance<3>(
          p_, feature.offset, out.d_uv_d_camera, out.d_uv_d_feature.leftCols<3>(), variance);
    out.valid = out.innovation_covariance.allFinite();
  }
}

namespace {

// Projections and Jacobians of map features at state x (no covariance); false if any fails.
bool Linearise(const Eigen::VectorXd& x, const FeatureMap& map, const std::vector<int>& indices,
               const Eigen::Vector2d& pixel_size_mm, std::vector<FeaturePrediction>* out) {
  const MeasuredCamera camera = x.head<kMeasuredCameraDim>();
  for (size_t j = 0; j < indices.size(); ++j) {
    const MapFeature& f = map[indices[j]];
    FeaturePrediction& p = (*out)[j];
    p.valid = ProjectFeatureWithJacobians(camera, pixel_size_mm, f.kind, x.data() + f.offset, &p.uv,
                                          &p.d_uv_d_camera, &p.d_uv_d_feature);
    if (!p.valid) return false;
  }
  return true;
}

// P H^T (n x m) and S = H P H^T + sigma^2 I for the sparse H of `predictions`: each pair of
// rows touches the 12 calibration+pose columns and one feature's columns.
void SparseInnovation(const Eigen::MatrixXd& p, const FeatureMap& map,
                      const std::vector<int>& indices,
                      const std::vector<FeaturePrediction>& predictions, double pixel_sigma,
                      Eigen::MatrixXd* pht, Eigen::MatrixXd* s) {
  const int k = static_cast<int>(indices.size());
  pht->resize(p.rows(), 2 * k);
  s->resize(2 * k, 2 * k);
  for (int j = 0; j < k; ++j) {
    const MapFeature& f = map[indices[j]];
    const FeaturePrediction& pr = predictions[j];
    const int d = FeatureDim(f.kind);
    pht->middleCols<2>(2 * j).noalias() = p.leftCols<12>() * pr.d_uv_d_camera.transpose();
    pht->middleCols<2>(2 * j).noalias() +=
        p.middleCols(f.offset, d) * pr.d_uv_d_feature.leftCols(d).transpose();
  }
  for (int i = 0; i < k; ++i) {
    const MapFeature& f = map[indices[i]];
    const FeaturePrediction& pr = predictions[i];
    const int d = FeatureDim(f.kind);
    s->middleRows<2>(2 * i).noalias() = pr.d_uv_d_camera * pht->topRows<12>();
    s->middleRows<2>(2 * i).noalias() +=
        pr.d_uv_d_feature.leftCols(d) * pht->middleRows(f.offset, d);
  }
  *s = 0.5 * (*s + s->transpose()).eval();
  s->diagonal().array() += pixel_sigma * pixel_sigma;
}

}  // namespace

bool SelfCalibrationEkf::Update(const FeatureMap& map, const std::vector<int>& indices,
                                const std::vector<FeaturePrediction>& predictions,
                                const std::vector<Eigen::Vector2d>& z,
                                const UpdateSettings& settings, double* log_likelihood,
                                double* nis) {
  const int k = static_cast<int>(indices.size());
  const int m = 2 * k;
  *log_likelihood = 0.0;
  if (nis != nullptr) *nis = 0.0;
  if (k == 0) return true;
  Eigen::MatrixXd pht, s;
  SparseInnovation(p_, map, indices, predictions, settings.pixel_sigma, &pht, &s);
  Eigen::LLT<Eigen::MatrixXd> llt(s);
  if (llt.info() != Eigen::Success) return false;
  Eigen::VectorXd residual(m);  // z - h(x_i) - H_i (x_prior - x_i); the innovation at i = 0
  for (int j = 0; j < k; ++j) residual.segment<2>(2 * j) = z[j] - predictions[j].uv;
  // The weight of this filter uses the prior predictive density of the innovation.
  const Eigen::VectorXd white0 = llt.matrixL().solve(residual);
  const double log_det = 2.0 * llt.matrixLLT().diagonal().array().log().sum();
  *log_likelihood = -0.5 * (white0.squaredNorm() + log_det + m * std::log(2.0 * M_PI));
  if (nis != nullptr) *nis = white0.squaredNorm();
  if (!std::isfinite(*log_likelihood)) return false;

  // Iterated EKF (Gauss-Newton on the MAP cost): relinearise h at the updated mean; each
  // iteration costs O(n m^2), only the final covariance update is O(n^2 m).
  const Eigen::VectorXd x_prior = x_;
  Eigen::VectorXd x_i = x_prior;
  std::vector<FeaturePrediction> lin = predictions;
  for (int it = 1; it < settings.iterations; ++it) {
    const Eigen::VectorXd x_next = x_prior + pht * llt.solve(residual);
    const double step = (x_next - x_i).norm();
    std::vector<FeaturePrediction> next = lin;
    if (!x_next.allFinite() || !Linearise(x_next, map, indices, settings.pixel_size_mm, &next))
      break;
    Eigen::MatrixXd pht_next, s_next;
    SparseInnovation(p_, map, indices, next, settings.pixel_sigma, &pht_next, &s_next);
    Eigen::LLT<Eigen::MatrixXd> llt_next(s_next);
    if (llt_next.info() != Eigen::Success) break;
    x_i = x_next;
    lin.swap(next);
    pht.swap(pht_next);
    llt = llt_next;
    const Eigen::VectorXd dx = x_prior - x_i;
    for (int j = 0; j < k; ++j) {
      const MapFeature& f = map[indices[j]];
      const int d = FeatureDim(f.kind);
      residual.segment<2>(2 * j) = z[j] - lin[j].uv - lin[j].d_uv_d_camera * dx.head<12>() -
                                   lin[j].d_uv_d_feature.leftCols(d) * dx.segment(f.offset, d);
    }
    if (step <= 1e-9 * (1.0 + x_i.norm())) break;
  }
  // With W = P H^T L^-T: x = x_prior + W L^-1 r, P -= W W^T (= K S K^T). Only the lower
  // triangle of the O(n^2 m) product is formed, then mirrored.
  const Eigen::MatrixXd w_t = llt.matrixL().solve(pht.transpose());  // m x n
  x_ = x_prior;
  x_.noalias() += w_t.transpose() * llt.matrixL().solve(residual);
  p_.selfadjointView<Eigen::Lower>().rankUpdate(w_t.transpose(), -1.0);
  MirrorLower(&p_);
  NormaliseQuaternion();
  return true;
}

void SelfCalibrationEkf::NormaliseQuaternion() {
  const Eigen::Vector4d q = x_.segment<4>(kQuaternion);
  const double norm = q.norm();
  const Eigen::Vector4d unit = q / norm;
  const Eigen::Matrix4d j = (Eigen::Matrix4d::Identity() - unit * unit.transpose()) / norm;
  x_.segment<4>(kQuaternion) = unit;
  const Eigen::Matrix<double, 4, Eigen::Dynamic> rows = j * p_.middleRows<4>(kQuaternion);
  p_.middleRows<4>(kQuaternion) = rows;
  const Eigen::Matrix<double, Eigen::Dynamic, 4> cols =
      p_.middleCols<4>(kQuaternion) * j.transpose();
  p_.middleCols<4>(kQuaternion) = cols;
}

bool SelfCalibrationEkf::AddInverseDepthFeatures(const std::vector<Eigen::Vector2d>& uv,
                                                 const Eigen::Vector2d& pixel_size_mm, double rho0,
                                                 double rho_sigma, double pixel_sigma) {
  const int count = static_cast<int>(uv.size());
  if (count == 0) return true;
  const int n = dim();
  const int added = kInverseDepthDim * count;
  const MeasuredCamera camera = measured_camera();
  Eigen::Matrix<double, Eigen::Dynamic, 12> j_camera(added, 12);
  Eigen::VectorXd y(added);
  Eigen::MatrixXd noise = Eigen::MatrixXd::Zero(added, added);
  for (int i = 0; i < count; ++i) {
    Eigen::Matrix<double, 6, 12> jc;
    Eigen::Matrix<double, 6, 2> juv;
    y.segment<6>(6 * i) = InitialiseInverseDepth(camera, pixel_size_mm, uv[i], rho0, &jc, &juv);
    j_camera.middleRows<6>(6 * i) = jc;
    noise.block<6, 6>(6 * i, 6 * i) = pixel_sigma * pixel_sigma * juv * juv.transpose();
    noise(6 * i + 5, 6 * i + 5) += rho_sigma * rho_sigma;
  }
  if (!y.allFinite() || !j_camera.allFinite()) return false;
  // A new point depends on the calibration and pose only: its rows are J P[0:12, :].
  const Eigen::MatrixXd rows = j_camera * p_.topRows<12>();
  x_.conservativeResize(n + added);
  x_.tail(added) = y;
  p_.conservativeResize(n + added, n + added);
  p_.bottomLeftCorner(added, n) = rows;
  p_.topRightCorner(n, added) = rows.transpose();
  p_.bottomRightCorner(added, added) = rows.leftCols<12>() * j_camera.transpose() + noise;
  return true;
}

void SelfCalibrationEkf::Restructure(const StateRestructure& plan) {
  for (int offset : plan.converted_offsets) {
    Eigen::Matrix<double, 3, 6> j;
    const Eigen::Vector3d xyz = InverseDepthToXyz(x_.segment<6>(offset), &j);
    // P <- T P T^T with T acting on this feature's 6 rows; rows offset+3..5 become junk and
    // are dropped by the compaction below.
    const Eigen::Matrix<double, 3, Eigen::Dynamic> rows = j * p_.middleRows<6>(offset);
    p_.middleRows<3>(offset) = rows;
    const Eigen::Matrix<double, Eigen::Dynamic, 3> cols = p_.middleCols<6>(offset) * j.transpose();
    p_.middleCols<3>(offset) = cols;
    x_.segment<3>(offset) = xyz;
  }
  if (plan.trivial) return;
  const Eigen::VectorXd x = x_(plan.keep);
  const Eigen::MatrixXd p = p_(plan.keep, plan.keep);
  x_ = x;
  p_ = p;
}

}  // namespace rscalib::sog
