// SOG filter: log-space weights and SPRT against direct computations, one EKF against the
// textbook dense EKF, map restructuring against dense transforms, and a designed pruning case.
#include <cmath>
#include <random>
#include <vector>

#include <Eigen/Dense>
#include <gtest/gtest.h>

#include "rscalib/core/error.hpp"
#include "rscalib/sog/ekf.hpp"
#include "rscalib/sog/inverse_depth.hpp"
#include "rscalib/sog/mixture.hpp"
#include "rscalib/sog/sog_bank.hpp"
#include "rscalib/sog/sprt.hpp"

using namespace rscalib::sog;

namespace {

const Eigen::Vector2d kPixelMm(0.0112, 0.0112);

Vector5d PaperCalibration() {
  Vector5d c;
  c << 194.06, 160.22, 128.87, 0.06333, 0.0139;
  return c;
}

Matrix5d PaperCalibrationCovariance() {
  Vector5d s;
  s << 7.5, 10.0 / 3.0, 10.0 / 3.0, 0.02, 0.00225;
  return s.cwiseAbs2().asDiagonal();
}

MotionState StartMotion() {
  MotionState m = MotionState::Zero();
  m[3] = 1.0;
  m.segment<3>(7) << 0.2, -0.05, 0.1;
  m.segment<3>(10) << 0.05, 0.3, -0.1;
  return m;
}

Matrix13d StartMotionCovariance() {
  Matrix13d c = Matrix13d::Zero();
  c.block<6, 6>(7, 7) = 0.01 * Eigen::Matrix<double, 6, 6>::Identity();
  return c;
}

double DirectGaussian(const Eigen::VectorXd& nu, const Eigen::MatrixXd& s) {
  const double norm = std::pow(2.0 * M_PI, -0.5 * nu.size()) / std::sqrt(s.determinant());
  return norm * std::exp(-0.5 * nu.dot(s.inverse() * nu));
}

Eigen::MatrixXd RandomSpd(int n, std::mt19937& rng, double scale = 1.0) {
  std::normal_distribution<double> g(0.0, 1.0);
  Eigen::MatrixXd a(n, n);
  for (int i = 0; i < n * n; ++i) a.data()[i] = g(rng);
  return scale * (a * a.transpose() / n + 0.5 * Eigen::MatrixXd::Identity(n, n));
}

// A filter with a few features in front of the camera (pixels spread over the image),
// moved once so that the features carry parallax and cross-covariances.
SelfCalibrationEkf FilterWithFeatures(FeatureMap* map, int count = 6) {
  SelfCalibrationEkf ekf(PaperCalibration(), PaperCalibrationCovariance(), StartMotion(),
                         StartMotionCovariance());
  std::vector<Eigen::Vector2d> uv;
  for (int i = 0; i < count; ++i) uv.emplace_back(40.0 + 45.0 * i, 30.0 + 30.0 * i);
  EXPECT_TRUE(ekf.AddInverseDepthFeatures(uv, kPixelMm, 0.5, 0.5, 1.0));
  map->AddInverseDepth(count, 0);
  ProcessNoise noise;
  ekf.Predict(1.0 / 30.0, noise);
  return ekf;
}

std::vector<int> AllIndices(const FeatureMap& map) {
  std::vector<int> all(map.size());
  for (int k = 0; k < map.size(); ++k) all[k] = k;
  return all;
}

// Dense H (2k x n) from the sparse predictions.
Eigen::MatrixXd DenseH(const FeatureMap& map, const std::vector<int>& indices,
                       const std::vector<FeaturePrediction>& predictions, int n) {
  Eigen::MatrixXd h = Eigen::MatrixXd::Zero(2 * indices.size(), n);
  for (size_t j = 0; j < indices.size(); ++j) {
    const MapFeature& f = map[indices[j]];
    h.block(2 * j, 0, 2, 12) = predictions[indices[j]].d_uv_d_camera;
    h.block(2 * j, f.offset, 2, FeatureDim(f.kind)) =
        predictions[indices[j]].d_uv_d_feature.leftCols(FeatureDim(f.kind));
  }
  return h;
}

}  // namespace

// ----------------------------------------------------------------------------- weights

TEST(SogWeights, LogSpaceUpdateEqualsDirectComputation) {
  std::mt19937 rng(11);
  std::normal_distribution<double> g(0.0, 1.0);
  const int n_gaussians = 4, dim = 4;
  std::vector<double> prior = {0.1, 0.2, 0.3, 0.4};
  Eigen::VectorXd log_prior(n_gaussians), log_lik(n_gaussians), direct(n_gaussians);
  for (int i = 0; i < n_gaussians; ++i) {
    Eigen::VectorXd nu(dim);
    for (int d = 0; d < dim; ++d) nu[d] = g(rng);
    const Eigen::MatrixXd s = RandomSpd(dim, rng, 1.0 + i);
    ASSERT_TRUE(LogGaussianDensity(nu, s, &log_lik[i]));
    const double density = DirectGaussian(nu, s);
    EXPECT_NEAR(log_lik[i], std::log(density), 1e-12);
    log_prior[i] = std::log(prior[i]);
    direct[i] = prior[i] * density;
  }
  direct /= direct.sum();
  const Eigen::VectorXd updated = UpdateLogWeights(log_prior, log_lik);
  EXPECT_LT((updated.array().exp().matrix() - direct).norm(), 1e-14);
  EXPECT_NEAR(LogSumExp(updated), 0.0, 1e-14);
}

TEST(SogWeights, LogSpaceStaysFiniteFor200DimensionalInnovations) {
  // S = s^2 I in 200-D: det S = s^400 overflows (s = 10) or underflows (s = 0.01) a double,
  // so does the density; its logarithm is plain.
  const int dim = 200;
  for (double s : {0.01, 10.0}) {
    const Eigen::MatrixXd cov = s * s * Eigen::MatrixXd::Identity(dim, dim);
    EXPECT_FALSE(std::isfinite(std::log(cov.determinant())) && cov.determinant() > 0.0);
    const Eigen::VectorXd nu = Eigen::VectorXd::Constant(dim, 3.0 * s);
    double log_density = 0.0;
    ASSERT_TRUE(LogGaussianDensity(nu, cov, &log_density));
    const double expected =
        -0.5 * (dim * 9.0 + 2.0 * dim * std::log(s) + dim * std::log(2.0 * M_PI));
    EXPECT_NEAR(log_density, expected, 1e-9 * std::abs(expected));
  }
  // Weights of two filters whose likelihoods differ by e^-2000 (zero in linear space).
  Eigen::VectorXd log_prior(2), log_lik(2);
  log_prior << std::log(0.5), std::log(0.5);
  log_lik << -1000.0, -3000.0;
  const Eigen::VectorXd w = UpdateLogWeights(log_prior, log_lik);
  EXPECT_TRUE(w.allFinite());
  EXPECT_NEAR(w[0], 0.0, 1e-15);
  EXPECT_NEAR(w[1], -2000.0, 1e-9);
  // A filter with zero likelihood gets weight zero, not NaN.
  log_lik << -1000.0, -std::numeric_limits<double>::infinity();
  const Eigen::VectorXd w2 = UpdateLogWeights(log_prior, log_lik);
  EXPECT_NEAR(w2[0], 0.0, 1e-15);
  EXPECT_TRUE(std::isinf(w2[1]) && w2[1] < 0);
}

TEST(SogWeights, SprtRatiosEqualDirectComputation) {
  const std::vector<double> w = {0.5, 0.3, 0.2};
  const std::vector<double> lik = {0.02, 0.5, 0.1};
  Eigen::VectorXd log_w(3), log_lik(3);
  for (int i = 0; i < 3; ++i) {
    log_w[i] = std::log(w[i]) + 7.0;  // any normalisation
    log_lik[i] = std::log(lik[i]);
  }
  const Eigen::VectorXd ratios = SprtLogRatios(log_w, log_lik);
  for (int i = 0; i < 3; ++i) {
    double num = 0.0, den = 0.0;
    for (int j = 0; j < 3; ++j)
      if (j != i) {
        num += w[j] * lik[j];
        den += w[j];
      }
    EXPECT_NEAR(ratios[i], std::log(lik[i] / (num / den)), 1e-13) << i;
  }
  const WaldBoundaries wald = MakeWaldBoundaries(0.05, 0.1);
  EXPECT_NEAR(std::exp(wald.log_accept), 0.9 / 0.05, 1e-12);
  EXPECT_NEAR(std::exp(wald.log_reject), 0.1 / 0.95, 1e-12);
  EXPECT_EQ(SprtLogRatios(Eigen::VectorXd::Zero(1), Eigen::VectorXd::Constant(1, -5.0))[0], 0.0);
}

TEST(SogWeights, MomentMatchingEqualsDirectComputation) {
  std::vector<double> w = {1.0, 3.0};
  std::vector<Eigen::Vector2d> m = {Eigen::Vector2d(0.0, 0.0), Eigen::Vector2d(4.0, 2.0)};
  std::vector<Eigen::Matrix2d> c = {Eigen::Matrix2d::Identity(), 2.0 * Eigen::Matrix2d::Identity()};
  Eigen::Vector2d mean;
  Eigen::Matrix2d cov;
  MergeGaussians<2>(w, m, c, &mean, &cov);
  EXPECT_LT((mean - Eigen::Vector2d(3.0, 1.5)).norm(), 1e-15);
  // 0.25 (I + d0 d0^T) + 0.75 (2I + d1 d1^T), d0 = (-3, -1.5), d1 = (1, 0.5)
  Eigen::Matrix2d expected = 0.25 * Eigen::Matrix2d::Identity() + 1.5 * Eigen::Matrix2d::Identity();
  expected += 0.25 * Eigen::Vector2d(-3, -1.5) * Eigen::RowVector2d(-3, -1.5) +
              0.75 * Eigen::Vector2d(1, 0.5) * Eigen::RowVector2d(1, 0.5);
  EXPECT_LT((cov - expected).norm(), 1e-14);
}

// ----------------------------------------------------------------------------------- EKF

TEST(SogEkf, PredictEqualsDenseFPFt) {
  FeatureMap map;
  SelfCalibrationEkf ekf = FilterWithFeatures(&map);
  const Eigen::VectorXd x0 = ekf.mean();
  const Eigen::MatrixXd p0 = ekf.covariance();
  ProcessNoise noise;
  noise.calibration_random_walk << 0.1, 0.0, 0.0, 0.0, 0.0;
  const double dt = 0.05;
  ekf.Predict(dt, noise);
  const int n = ekf.dim();
  MotionJacobian f13;
  PredictMotion(x0.segment<13>(kPosition), dt, &f13);
  Eigen::MatrixXd f = Eigen::MatrixXd::Identity(n, n);
  f.block<13, 13>(kPosition, kPosition) = f13;
  Eigen::MatrixXd q = Eigen::MatrixXd::Zero(n, n);
  q.block<13, 13>(kPosition, kPosition) = MotionProcessNoise(
      x0.segment<13>(kPosition), dt, noise.accel_sigma, noise.angular_accel_sigma);
  q(0, 0) = 0.01 * dt;
  EXPECT_LT((ekf.covariance() - (f * p0 * f.transpose() + q)).norm(), 1e-12 * p0.norm());
  EXPECT_LT(
      (ekf.mean().segment<13>(kPosition) - PredictMotion(x0.segment<13>(kPosition), dt)).norm(),
      1e-15);
  EXPECT_EQ(ekf.mean().tail(n - kCameraDim), x0.tail(n - kCameraDim));
}

TEST(SogEkf, UpdateEqualsDenseTextbookEkf) {
  FeatureMap map;
  SelfCalibrationEkf ekf = FilterWithFeatures(&map);
  const std::vector<int> all = AllIndices(map);
  std::vector<FeaturePrediction> predictions(map.size());
  ekf.PredictMeasurements(map, all, kPixelMm, 0.7, &predictions);
  std::vector<int> used = {0, 2, 3, 5};
  std::vector<FeaturePrediction> used_pred;
  std::vector<Eigen::Vector2d> z;
  for (int k : used) {
    ASSERT_TRUE(predictions[k].valid);
    used_pred.push_back(predictions[k]);
    z.push_back(predictions[k].uv + Eigen::Vector2d(0.8, -0.5));
  }
  const int n = ekf.dim();
  const Eigen::MatrixXd h = DenseH(map, used, predictions, n);
  const Eigen::MatrixXd p0 = ekf.covariance();
  const Eigen::VectorXd x0 = ekf.mean();
  const Eigen::MatrixXd s = h * p0 * h.transpose() + 0.49 * Eigen::MatrixXd::Identity(8, 8);
  Eigen::VectorXd nu(8);
  for (size_t j = 0; j < used.size(); ++j) nu.segment<2>(2 * j) = z[j] - used_pred[j].uv;
  // The per-feature 2x2 blocks of S are what active search uses.
  for (size_t j = 0; j < used.size(); ++j)
    EXPECT_LT((s.block<2, 2>(2 * j, 2 * j) - used_pred[j].innovation_covariance).norm(), 1e-9);
  const Eigen::MatrixXd k = p0 * h.transpose() * s.inverse();
  Eigen::VectorXd x1 = x0 + k * nu;
  Eigen::MatrixXd p1 = p0 - k * s * k.transpose();
  // Quaternion renormalisation, as the filter does it.
  const Eigen::Vector4d q = x1.segment<4>(kQuaternion);
  Eigen::MatrixXd jn = Eigen::MatrixXd::Identity(n, n);
  jn.block<4, 4>(kQuaternion, kQuaternion) =
      (Eigen::Matrix4d::Identity() - q.normalized() * q.normalized().transpose()) / q.norm();
  x1.segment<4>(kQuaternion) = q.normalized();
  p1 = jn * p1 * jn.transpose();

  UpdateSettings settings;
  settings.pixel_sigma = 0.7;
  double log_lik = 0.0, nis = 0.0;
  ASSERT_TRUE(ekf.Update(map, used, used_pred, z, settings, &log_lik, &nis));
  EXPECT_LT((ekf.mean() - x1).norm(), 1e-10 * (1 + x1.norm()));
  EXPECT_LT((ekf.covariance() - p1).norm(), 1e-10 * p1.norm());
  EXPECT_LT((ekf.covariance() - ekf.covariance().transpose()).norm(), 1e-15 * p1.norm());
  EXPECT_NEAR(log_lik, std::log(DirectGaussian(nu, s)), 1e-9);
  EXPECT_NEAR(nis, nu.dot(s.inverse() * nu), 1e-9);
}

TEST(SogEkf, IteratedUpdateEqualsDenseGaussNewton) {
  // Iterated EKF = Gauss-Newton on |x - x0|^2_{P^-1} + |z - h(x)|^2_{R^-1}:
  //   x_{i+1} = x0 + P H_i^T (H_i P H_i^T + R)^-1 (z - h(x_i) - H_i (x0 - x_i)),
  // then P -= K S K^T at the last linearisation. Reference: dense matrices.
  FeatureMap map;
  SelfCalibrationEkf ekf = FilterWithFeatures(&map);
  const std::vector<int> all = AllIndices(map);
  std::vector<FeaturePrediction> predictions(map.size());
  ekf.PredictMeasurements(map, all, kPixelMm, 0.5, &predictions);
  std::vector<Eigen::Vector2d> z;
  for (int k : all)
    z.push_back(predictions[k].uv + Eigen::Vector2d(3.0 * std::cos(k), 3.0 * std::sin(k)));
  const int n = ekf.dim(), m = 2 * map.size();
  const Eigen::VectorXd x0 = ekf.mean();
  const Eigen::MatrixXd p0 = ekf.covariance();
  const Eigen::MatrixXd r = 0.25 * Eigen::MatrixXd::Identity(m, m);
  const int iterations = 4;
  Eigen::VectorXd x = x0;
  Eigen::MatrixXd h(m, n);
  Eigen::VectorXd hx(m);
  const auto linearise = [&](const Eigen::VectorXd& at) {
    std::vector<FeaturePrediction> lin(map.size());
    for (int k : all) {
      const MapFeature& f = map[k];
      ASSERT_TRUE(ProjectFeatureWithJacobians(at.head<12>(), kPixelMm, f.kind, at.data() + f.offset,
                                              &lin[k].uv, &lin[k].d_uv_d_camera,
                                              &lin[k].d_uv_d_feature));
      hx.segment<2>(2 * k) = lin[k].uv;
    }
    h = DenseH(map, all, lin, n);
  };
  Eigen::VectorXd zz(m);
  for (int k : all) zz.segment<2>(2 * k) = z[k];
  linearise(x);
  for (int it = 1; it < iterations; ++it) {
    const Eigen::MatrixXd s = h * p0 * h.transpose() + r;
    x = x0 + p0 * h.transpose() * s.ldlt().solve(zz - hx - h * (x0 - x));
    linearise(x);
  }
  const Eigen::MatrixXd s = h * p0 * h.transpose() + r;
  const Eigen::MatrixXd k = p0 * h.transpose() * s.inverse();
  Eigen::VectorXd x1 = x0 + k * (zz - hx - h * (x0 - x));
  Eigen::MatrixXd p1 = p0 - k * s * k.transpose();
  const Eigen::Vector4d q = x1.segment<4>(kQuaternion);
  Eigen::MatrixXd jn = Eigen::MatrixXd::Identity(n, n);
  jn.block<4, 4>(kQuaternion, kQuaternion) =
      (Eigen::Matrix4d::Identity() - q.normalized() * q.normalized().transpose()) / q.norm();
  x1.segment<4>(kQuaternion) = q.normalized();
  p1 = jn * p1 * jn.transpose();

  UpdateSettings settings;
  settings.pixel_sigma = 0.5;
  settings.iterations = iterations;
  settings.pixel_size_mm = kPixelMm;
  std::vector<FeaturePrediction> used(predictions.begin(), predictions.end());
  double log_lik = 0.0;
  ASSERT_TRUE(ekf.Update(map, all, used, z, settings, &log_lik));
  EXPECT_LT((ekf.mean() - x1).norm(), 1e-9 * (1 + x1.norm()));
  EXPECT_LT((ekf.covariance() - p1).norm(), 1e-9 * p1.norm());
  // Relinearising moved the estimate: the test exercises more than one iteration.
  SelfCalibrationEkf plain = FilterWithFeatures(&map);
  settings.iterations = 1;
  ASSERT_TRUE(plain.Update(map, all, used, z, settings, &log_lik));
  EXPECT_GT((plain.mean() - x1).norm(), 1e-6);
}

TEST(SogEkf, AddingFeaturesEqualsDenseJacobianPropagation) {
  FeatureMap map;
  SelfCalibrationEkf ekf = FilterWithFeatures(&map, 3);
  const Eigen::VectorXd x0 = ekf.mean();
  const Eigen::MatrixXd p0 = ekf.covariance();
  const int n = ekf.dim();
  const std::vector<Eigen::Vector2d> uv = {Eigen::Vector2d(100.0, 60.0),
                                           Eigen::Vector2d(250.0, 200.0)};
  const double rho0 = 0.4, rho_sigma = 0.6, pixel_sigma = 0.8;
  ASSERT_TRUE(ekf.AddInverseDepthFeatures(uv, kPixelMm, rho0, rho_sigma, pixel_sigma));
  // Dense: y_new = g(x_camera, uv, rho); P_aug = J [P 0 0; 0 R 0; 0 0 s^2] J^T.
  const int m = n + 4 + 2;
  Eigen::MatrixXd prior = Eigen::MatrixXd::Zero(m, m);
  prior.topLeftCorner(n, n) = p0;
  prior.block<4, 4>(n, n) = pixel_sigma * pixel_sigma * Eigen::Matrix4d::Identity();
  prior.bottomRightCorner<2, 2>() = rho_sigma * rho_sigma * Eigen::Matrix2d::Identity();
  Eigen::MatrixXd j = Eigen::MatrixXd::Zero(n + 12, m);
  j.topLeftCorner(n, n).setIdentity();
  for (int i = 0; i < 2; ++i) {
    Eigen::Matrix<double, 6, 12> jc;
    Eigen::Matrix<double, 6, 2> juv;
    const InverseDepthPoint y =
        InitialiseInverseDepth(x0.head<12>(), kPixelMm, uv[i], rho0, &jc, &juv);
    EXPECT_LT((ekf.mean().segment<6>(n + 6 * i) - y).norm(), 1e-15);
    j.block<6, 12>(n + 6 * i, 0) = jc;
    j.block<6, 2>(n + 6 * i, n + 2 * i) = juv;
    j(n + 6 * i + 5, n + 4 + i) = 1.0;
  }
  const Eigen::MatrixXd expected = j * prior * j.transpose();
  EXPECT_LT((ekf.covariance() - expected).norm(), 1e-12 * expected.norm());
  EXPECT_EQ(ekf.mean().head(n), x0);
}

TEST(SogEkf, RestructureEqualsDenseTransform) {
  FeatureMap map;
  SelfCalibrationEkf ekf = FilterWithFeatures(&map, 4);
  const Eigen::VectorXd x0 = ekf.mean();
  const Eigen::MatrixXd p0 = ekf.covariance();
  // Remove feature 1, convert features 0 and 3 to XYZ.
  const std::vector<bool> remove = {false, true, false, false};
  const std::vector<bool> convert = {true, false, false, true};
  const StateRestructure plan = map.Plan(remove, convert);
  ekf.Restructure(plan);
  const int n0 = static_cast<int>(x0.size());
  Eigen::MatrixXd t = Eigen::MatrixXd::Zero(kCameraDim + 3 + 6 + 3, n0);
  t.topLeftCorner<kCameraDim, kCameraDim>().setIdentity();
  Eigen::VectorXd expected_x(kCameraDim + 12);
  expected_x.head<kCameraDim>() = x0.head<kCameraDim>();
  Eigen::Matrix<double, 3, 6> j0, j3;
  expected_x.segment<3>(kCameraDim) = InverseDepthToXyz(x0.segment<6>(map[0].offset), &j0);
  t.block<3, 6>(kCameraDim, map[0].offset) = j0;
  expected_x.segment<6>(kCameraDim + 3) = x0.segment<6>(map[2].offset);
  t.block<6, 6>(kCameraDim + 3, map[2].offset).setIdentity();
  expected_x.segment<3>(kCameraDim + 9) = InverseDepthToXyz(x0.segment<6>(map[3].offset), &j3);
  t.block<3, 6>(kCameraDim + 9, map[3].offset) = j3;
  EXPECT_LT((ekf.mean() - expected_x).norm(), 1e-14 * expected_x.norm());
  EXPECT_LT((ekf.covariance() - t * p0 * t.transpose()).norm(), 1e-12 * p0.norm());
  map.Apply(remove, convert);
  EXPECT_EQ(map.size(), 3);
  EXPECT_EQ(map.state_dim(), kCameraDim + 12);
  EXPECT_EQ(map[0].kind, FeatureKind::kXyz);
  EXPECT_EQ(map[1].offset, kCameraDim + 3);
  EXPECT_EQ(map[2].offset, kCameraDim + 9);
  EXPECT_EQ(map.IndexOf(1), -1);
  EXPECT_EQ(map.IndexOf(3), 2);
}

TEST(SogBank, MergedPredictionsAreMomentMatchedFilterPredictions) {
  SogOptions options;
  options.num_threads = 2;
  std::vector<Vector5d> means(3, PaperCalibration());
  means[1][0] = 170.0;
  means[2][0] = 230.0;
  const std::vector<Matrix5d> covs(3, PaperCalibrationCovariance());
  SogBank bank(options, means, covs, {0.2, 0.5, 0.3}, 320, 240, kPixelMm);
  bank.SetCameraState(StartMotion(), StartMotionCovariance());
  const std::vector<int64_t> ids = bank.AddFeatures(
      {Eigen::Vector2d(100, 80), Eigen::Vector2d(200, 150), Eigen::Vector2d(160, 120)});
  ASSERT_EQ(ids.size(), 3u);
  bank.Predict(1.0 / 30.0);
  const MergedPredictions merged = bank.PredictMeasurements();
  ASSERT_EQ(merged.ids.size(), 3u);
  const Eigen::VectorXd w = bank.weights();
  for (size_t k = 0; k < merged.ids.size(); ++k) {
    const int index = bank.map().IndexOf(merged.ids[k]);
    std::vector<FeaturePrediction> per(bank.map().size());
    Eigen::Vector2d mean = Eigen::Vector2d::Zero();
    std::vector<Eigen::Vector2d> uv;
    std::vector<Eigen::Matrix2d> s;
    for (int i = 0; i < 3; ++i) {
      bank.filter(i).PredictMeasurements(bank.map(), {index}, kPixelMm, options.pixel_sigma, &per);
      uv.push_back(per[index].uv);
      s.push_back(per[index].innovation_covariance);
      mean += w[i] * uv.back();
    }
    Eigen::Matrix2d cov = Eigen::Matrix2d::Zero();
    for (int i = 0; i < 3; ++i) cov += w[i] * (s[i] + (uv[i] - mean) * (uv[i] - mean).transpose());
    EXPECT_LT((merged.uv[k] - mean).norm(), 1e-9);
    EXPECT_LT((merged.covariance[k] - cov).norm(), 1e-9 * cov.norm());
  }
}

TEST(SogBank, RejectsBadInput) {
  SogOptions options;
  const std::vector<Vector5d> means(1, PaperCalibration());
  const std::vector<Matrix5d> covs(1, PaperCalibrationCovariance());
  EXPECT_THROW(SogBank(options, means, covs, {1.0, 2.0}, 320, 240, kPixelMm), rscalib::InputError);
  EXPECT_THROW(SogBank(options, means, covs, {1.0}, 0, 240, kPixelMm), rscalib::InputError);
  EXPECT_THROW(SogBank(options, means, covs, {1.0}, 320, 240, Eigen::Vector2d::Zero()),
               rscalib::InputError);
  EXPECT_THROW(SogBank(options, means, {Matrix5d::Zero()}, {1.0}, 320, 240, kPixelMm),
               rscalib::InputError);
  SogBank bank(options, means, covs, {1.0}, 320, 240, kPixelMm);
  EXPECT_THROW(bank.Update({42}, {Eigen::Vector2d(1, 1)}, {true}), rscalib::InputError);
  EXPECT_THROW(bank.Predict(-1.0), rscalib::InputError);
  EXPECT_THROW(bank.RemoveFeatures({7}), rscalib::InputError);
}

TEST(SogBank, MapCapDeletesTheFeaturesMatchedLongestAgoUnsearchedFirst) {
  SogOptions options;
  options.max_features = 4;
  options.linearity_threshold = 0.0;
  const std::vector<Vector5d> means(1, PaperCalibration());
  const std::vector<Matrix5d> covs(1, PaperCalibrationCovariance());
  SogBank bank(options, means, covs, {1.0}, 320, 240, kPixelMm);
  bank.SetCameraState(StartMotion(), StartMotionCovariance());
  const std::vector<int64_t> old_ids = bank.AddFeatures(
      {Eigen::Vector2d(100, 80), Eigen::Vector2d(200, 150), Eigen::Vector2d(160, 120)});
  SogUpdateReport report = bank.Update({}, {}, {});
  EXPECT_EQ(report.num_capped, 0);
  const std::vector<int64_t> new_ids = bank.AddFeatures(
      {Eigen::Vector2d(60, 60), Eigen::Vector2d(250, 60), Eigen::Vector2d(60, 200)});
  EXPECT_EQ(bank.map().size(), 6);
  bank.Predict(1.0 / 30.0);
  // Feature old_ids[2] is searched (not found); old_ids[0..1] are not searched: they go first.
  report = bank.Update({old_ids[2]}, {Eigen::Vector2d(0, 0)}, {false});
  EXPECT_EQ(report.num_capped, 2);
  EXPECT_EQ(bank.map().size(), 4);
  EXPECT_EQ(bank.map().IndexOf(old_ids[0]), -1);
  EXPECT_EQ(bank.map().IndexOf(old_ids[1]), -1);
  EXPECT_GE(bank.map().IndexOf(old_ids[2]), 0);
  for (int64_t id : new_ids) EXPECT_GE(bank.map().IndexOf(id), 0);
  EXPECT_EQ(report.deleted_feature_ids.size(), 2u);
}

TEST(SogBank, OnePointRansacRejectsAGrossOutlierAndKeepsTheInliers) {
  SogOptions options;
  options.ransac_hypotheses = 30;
  options.linearity_threshold = 0.0;
  const std::vector<Vector5d> means(1, PaperCalibration());
  const std::vector<Matrix5d> covs(1, PaperCalibrationCovariance());
  SogBank bank(options, means, covs, {1.0}, 320, 240, kPixelMm);
  bank.SetCameraState(StartMotion(), StartMotionCovariance());
  std::vector<Eigen::Vector2d> uv;
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < 3; ++j) uv.emplace_back(60.0 + 60.0 * i, 50.0 + 60.0 * j);
  bank.AddFeatures(uv);
  bank.Update({}, {}, {});
  bank.Predict(1.0 / 30.0);
  const MergedPredictions merged = bank.PredictMeasurements();
  ASSERT_EQ(merged.ids.size(), uv.size());
  std::vector<Eigen::Vector2d> z = merged.uv;
  for (auto& p : z) p += Eigen::Vector2d(0.5, -0.3);  // a common shift: consistent with one motion
  z[4] += Eigen::Vector2d(6.0, 5.0);                  // one wrong match, inside the wide gate
  const SogUpdateReport report =
      bank.Update(merged.ids, z, std::vector<bool>(merged.ids.size(), true));
  EXPECT_EQ(report.num_low_innovation, static_cast<int>(uv.size()) - 1);
  EXPECT_FALSE(report.used[4]);
  EXPECT_EQ(report.num_used, static_cast<int>(uv.size()) - 1);
}
