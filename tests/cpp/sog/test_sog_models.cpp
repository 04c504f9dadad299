// SOG self-calibration models: analytic Jacobians against central differences and against
// ceres::Jet autodiff of the templated reference functions; values against the camera model.
#include <cmath>
#include <random>
#include <string>

#include <Eigen/Dense>
#include <ceres/jet.h>
#include <gtest/gtest.h>

#include "rscalib/camera/camera_model.hpp"
#include "rscalib/geometry/rotation.hpp"
#include "rscalib/sog/inverse_depth.hpp"
#include "rscalib/sog/measurement_model.hpp"
#include "rscalib/sog/motion_model.hpp"
#include "rscalib/sog/quaternion.hpp"

using namespace rscalib::sog;

namespace {

const Eigen::Vector2d kPixelMm(0.0112, 0.0112);

// Central differences of fn: R^n -> R^m at x.
template <typename Fn>
Eigen::MatrixXd NumericJacobian(Fn&& fn, const Eigen::VectorXd& x, double h = 1e-6) {
  const Eigen::VectorXd y0 = fn(x);
  Eigen::MatrixXd j(y0.size(), x.size());
  for (Eigen::Index i = 0; i < x.size(); ++i) {
    const double step = h * std::max(1.0, std::abs(x[i]));
    Eigen::VectorXd plus = x, minus = x;
    plus[i] += step;
    minus[i] -= step;
    j.col(i) = (fn(plus) - fn(minus)) / (2.0 * step);
  }
  return j;
}

void ExpectNear(const Eigen::MatrixXd& a, const Eigen::MatrixXd& b, double relative,
                const std::string& what) {
  ASSERT_EQ(a.rows(), b.rows()) << what;
  ASSERT_EQ(a.cols(), b.cols()) << what;
  EXPECT_LE((a - b).norm(), relative * (1.0 + b.norm())) << what << "\n" << a << "\n--\n" << b;
}

Eigen::Vector4d RandomQuaternion(std::mt19937& rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  Eigen::Vector4d q(n(rng), n(rng), n(rng), n(rng));
  return q.normalized();
}

// A camera [f, Cx, Cy, k1, k2, r, q] like the paper's, with a random pose.
MeasuredCamera RandomCamera(std::mt19937& rng) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  MeasuredCamera c;
  c << 194.06 + 20 * u(rng), 160.22 + 3 * u(rng), 128.87 + 3 * u(rng), 0.06333 + 0.01 * u(rng),
      0.0139 + 0.003 * u(rng), u(rng), u(rng), u(rng), 0, 0, 0, 0;
  c.segment<4>(8) = RandomQuaternion(rng);
  return c;
}

// An inverse-depth feature in front of `camera`, through a random pixel, anchored elsewhere.
InverseDepthPoint FeatureInFront(const MeasuredCamera& camera, std::mt19937& rng) {
  std::uniform_real_distribution<double> u(20.0, 300.0), v(20.0, 220.0), depth(0.3, 2.0),
      off(-0.3, 0.3);
  const InverseDepthPoint seen =
      InitialiseInverseDepth(camera, kPixelMm, Eigen::Vector2d(u(rng), v(rng)), 1.0 / depth(rng));
  const Eigen::Vector3d point = InverseDepthToXyz(seen);
  // Re-anchor at a nearby origin so that r != (x0, y0, z0).
  InverseDepthPoint y;
  y.head<3>() = camera.segment<3>(5) + Eigen::Vector3d(off(rng), off(rng), off(rng));
  const Eigen::Vector3d ray = point - y.head<3>();
  y[3] = std::atan2(ray[0], ray[2]);
  y[4] = std::atan2(-ray[1], std::hypot(ray[0], ray[2]));
  y[5] = 1.0 / ray.norm();
  return y;
}

}  // namespace

TEST(SogQuaternion, ProductMatricesAndRotation) {
  std::mt19937 rng(1);
  for (int trial = 0; trial < 10; ++trial) {
    const Eigen::Vector4d p = RandomQuaternion(rng), q = RandomQuaternion(rng);
    const Eigen::Vector4d pq = QuaternionProduct<double>(p, q);
    EXPECT_LT((QuaternionLeftMatrix(p) * q - pq).norm(), 1e-14);
    EXPECT_LT((QuaternionRightMatrix(q) * p - pq).norm(), 1e-14);
    // R(p ⊗ q) = R(p) R(q), and R of a unit quaternion is a rotation.
    EXPECT_LT((QuaternionToRotation<double>(pq) -
               QuaternionToRotation<double>(p) * QuaternionToRotation<double>(q))
                  .norm(),
              1e-13);
    const Eigen::Matrix3d r = QuaternionToRotation<double>(p);
    EXPECT_LT((r * r.transpose() - Eigen::Matrix3d::Identity()).norm(), 1e-13);
    EXPECT_NEAR(r.determinant(), 1.0, 1e-13);
  }
}

TEST(SogQuaternion, RotatedVectorJacobianMatchesFiniteDifferences) {
  std::mt19937 rng(2);
  for (bool transpose : {false, true}) {
    for (int trial = 0; trial < 10; ++trial) {
      const Eigen::Vector4d q = RandomQuaternion(rng) * 1.1;  // not unit on purpose
      const Eigen::Vector3d a = Eigen::Vector3d::Random();
      const auto fn = [&](const Eigen::VectorXd& qq) -> Eigen::VectorXd {
        const Eigen::Matrix3d r = QuaternionToRotation<double>(Eigen::Vector4d(qq));
        return transpose ? Eigen::Vector3d(r.transpose() * a) : Eigen::Vector3d(r * a);
      };
      ExpectNear(DRotatedDQuaternion(q, a, transpose), NumericJacobian(fn, q), 1e-8, "d_Ra_d_q");
    }
  }
}

TEST(SogQuaternion, RotationVectorExponentialAndJacobian) {
  for (double scale : {0.0, 1e-9, 1e-5, 1e-3, 0.3, 2.0}) {
    const Eigen::Vector3d a = scale * Eigen::Vector3d(0.3, -0.5, 0.8).normalized();
    Eigen::Matrix<double, 4, 3> d;
    const Eigen::Vector4d q = RotationVectorToQuaternion(a, &d);
    EXPECT_NEAR(q.norm(), 1.0, 1e-14);
    // Against Ceres' angle-axis (a different implementation of the same map).
    const Eigen::Matrix3d expected = rscalib::geometry::RotationVectorToMatrix(a.data());
    EXPECT_LT((QuaternionToRotation<double>(q) - expected).norm(), 1e-12) << scale;
    const auto fn = [](const Eigen::VectorXd& x) -> Eigen::VectorXd {
      return RotationVectorToQuaternion(Eigen::Vector3d(x));
    };
    Eigen::VectorXd x = a;
    ExpectNear(d, NumericJacobian(fn, x, 1e-7), 1e-7, "d_q_d_a at |a| = " + std::to_string(scale));
  }
}

TEST(SogMotionModel, JacobiansMatchFiniteDifferences) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int trial = 0; trial < 10; ++trial) {
    MotionState x;
    x << u(rng), u(rng), u(rng), 0, 0, 0, 0, u(rng), u(rng), u(rng), 2 * u(rng), 2 * u(rng),
        2 * u(rng);
    x.segment<4>(3) = RandomQuaternion(rng);
    if (trial == 0) x.tail<3>().setZero();  // the series branch of the exponential
    const double dt = 1.0 / 30.0;
    MotionJacobian f;
    Eigen::Matrix<double, 13, 6> g;
    PredictMotion(x, dt, &f, &g);
    const auto fn = [dt](const Eigen::VectorXd& s) -> Eigen::VectorXd {
      return PredictMotion(MotionState(s), dt);
    };
    ExpectNear(f, NumericJacobian(fn, x), 1e-7, "d_out_d_state");
    // The impulses (V, W) enter exactly like a change of (v, w) before the step.
    const auto fn_impulse = [&](const Eigen::VectorXd& n) -> Eigen::VectorXd {
      MotionState s = x;
      s.segment<6>(7) += n;
      return PredictMotion(s, dt);
    };
    ExpectNear(g, NumericJacobian(fn_impulse, Eigen::VectorXd::Zero(6)), 1e-7, "d_out_d_impulse");
  }
}

TEST(SogMotionModel, ConstantVelocityKinematicsAndNoise) {
  MotionState x = MotionState::Zero();
  x[3] = 1.0;
  x.segment<3>(7) << 0.3, -0.1, 0.2;
  x.segment<3>(10) << 0.0, 0.6, 0.0;  // yaw rate about camera y
  MotionState y = x;
  for (int i = 0; i < 30; ++i) y = PredictMotion(y, 1.0 / 30.0);
  EXPECT_LT((y.head<3>() - x.segment<3>(7)).norm(), 1e-12);  // 1 s at v
  const Eigen::Vector3d expected_phi(0.0, 0.6, 0.0);         // 1 s at w
  const Eigen::Vector4d q = y.segment<4>(3);
  EXPECT_NEAR(2.0 * std::atan2(q.tail<3>().norm(), q[0]), 0.6, 1e-12);
  EXPECT_NEAR(q[2] / q.tail<3>().norm(), 1.0, 1e-12);
  const Eigen::Matrix<double, 13, 13> noise = MotionProcessNoise(x, 0.1, 2.0, 3.0);
  EXPECT_NEAR(noise(7, 7), 0.04, 1e-15);    // (sa dt)^2
  EXPECT_NEAR(noise(10, 10), 0.09, 1e-15);  // (salpha dt)^2
  EXPECT_NEAR(noise(0, 0), 0.04 * 0.01, 1e-15);
  EXPECT_NEAR(noise(0, 7), 0.04 * 0.1, 1e-15);
  EXPECT_LT((noise - noise.transpose()).norm(), 1e-18);
}

TEST(SogInverseDepth, ConversionJacobianAndLinearityIndex) {
  InverseDepthPoint y;
  y << 0.1, -0.2, 0.3, 0.4, -0.3, 0.7;
  Eigen::Matrix<double, 3, 6> j;
  const Eigen::Vector3d x = InverseDepthToXyz(y, &j);
  const Eigen::Vector3d m(std::cos(-0.3) * std::sin(0.4), -std::sin(-0.3),
                          std::cos(-0.3) * std::cos(0.4));
  EXPECT_LT((x - (y.head<3>() + m / 0.7)).norm(), 1e-15);
  const auto fn = [](const Eigen::VectorXd& s) -> Eigen::VectorXd {
    return InverseDepthToXyz(InverseDepthPoint(s));
  };
  ExpectNear(j, NumericJacobian(fn, y), 1e-8, "d_xyz_d_y");
  // Camera at the anchor: alpha = 0, d = 1/rho, so L = 4 sigma_rho / rho.
  EXPECT_NEAR(LinearityIndex(y, 0.01, y.head<3>()), 4 * 0.1 / 0.7, 1e-12);
  // Seen from the side at 90 degrees: cos(alpha) = 0.
  const Eigen::Vector3d side = x + m.cross(Eigen::Vector3d::UnitY()).normalized();
  EXPECT_NEAR(LinearityIndex(y, 0.01, side), 0.0, 1e-12);
  y[5] = -0.1;
  EXPECT_TRUE(std::isinf(LinearityIndex(y, 0.01, Eigen::Vector3d::Zero())));
}

TEST(SogMeasurement, ValueMatchesCameraModelAndJet) {
  std::mt19937 rng(4);
  for (int trial = 0; trial < 20; ++trial) {
    const MeasuredCamera camera = RandomCamera(rng);
    const InverseDepthPoint y = FeatureInFront(camera, rng);
    const Eigen::Vector3d xyz = InverseDepthToXyz(y);
    Eigen::Vector2d uv_id, uv_xyz, uv_ref, uv_template;
    ASSERT_TRUE(ProjectFeatureWithJacobians(camera, kPixelMm, FeatureKind::kInverseDepth, y.data(),
                                            &uv_id, nullptr, nullptr));
    ASSERT_TRUE(ProjectFeatureWithJacobians(camera, kPixelMm, FeatureKind::kXyz, xyz.data(),
                                            &uv_xyz, nullptr, nullptr));
    ASSERT_TRUE(ProjectFeature(camera.data(), kPixelMm.data(), FeatureKind::kInverseDepth, y.data(),
                               uv_template.data()));
    // Independent path: world -> camera by conventions.md, then the camera model.
    const Eigen::Matrix3d r_wc =
        QuaternionToRotation<double>(Eigen::Vector4d(camera.segment<4>(8)));
    const Eigen::Vector3d point_c = r_wc.transpose() * (xyz - camera.segment<3>(5));
    const rscalib::camera::CameraModel model("civera-radial", camera.head<5>(), 320, 240, kPixelMm);
    ASSERT_TRUE(model.Project(point_c, &uv_ref));
    EXPECT_LT((uv_id - uv_ref).norm(), 1e-9);
    EXPECT_LT((uv_xyz - uv_ref).norm(), 1e-9);
    EXPECT_LT((uv_template - uv_ref).norm(), 1e-9);
  }
}

TEST(SogMeasurement, JacobiansMatchFiniteDifferencesAndAutodiff) {
  std::mt19937 rng(5);
  using Jet = ceres::Jet<double, 18>;
  for (FeatureKind kind : {FeatureKind::kInverseDepth, FeatureKind::kXyz}) {
    const int d = FeatureDim(kind);
    for (int trial = 0; trial < 20; ++trial) {
      const MeasuredCamera camera = RandomCamera(rng);
      const InverseDepthPoint id = FeatureInFront(camera, rng);
      Eigen::VectorXd feature = id;
      if (kind == FeatureKind::kXyz) feature = InverseDepthToXyz(id);
      Eigen::Vector2d uv;
      Eigen::Matrix<double, 2, 12> d_uv_d_camera;
      Eigen::Matrix<double, 2, 6> d_uv_d_feature;
      ASSERT_TRUE(ProjectFeatureWithJacobians(camera, kPixelMm, kind, feature.data(), &uv,
                                              &d_uv_d_camera, &d_uv_d_feature));
      // Central differences.
      const auto by_camera = [&](const Eigen::VectorXd& c) -> Eigen::VectorXd {
        Eigen::Vector2d out;
        EXPECT_TRUE(ProjectFeature(c.data(), kPixelMm.data(), kind, feature.data(), out.data()));
        return out;
      };
      const auto by_feature = [&](const Eigen::VectorXd& f) -> Eigen::VectorXd {
        Eigen::Vector2d out;
        EXPECT_TRUE(ProjectFeature(camera.data(), kPixelMm.data(), kind, f.data(), out.data()));
        return out;
      };
      const Eigen::VectorXd cam = camera;
      ExpectNear(d_uv_d_camera, NumericJacobian(by_camera, cam), 1e-6, "d_uv_d_camera");
      ExpectNear(d_uv_d_feature.leftCols(d), NumericJacobian(by_feature, feature), 1e-6,
                 "d_uv_d_feature");
      // Forward-mode autodiff of the templated reference (exact to rounding).
      Jet cj[12], fj[6], uvj[2];
      for (int i = 0; i < 12; ++i) cj[i] = Jet(camera[i], i);
      for (int i = 0; i < d; ++i) fj[i] = Jet(feature[i], 12 + i);
      ASSERT_TRUE(ProjectFeature(cj, kPixelMm.data(), kind, fj, uvj));
      for (int row = 0; row < 2; ++row) {
        EXPECT_NEAR(uvj[row].a, uv[row], 1e-9);
        for (int i = 0; i < 12; ++i)
          EXPECT_NEAR(uvj[row].v[i], d_uv_d_camera(row, i),
                      1e-8 * (1 + std::abs(d_uv_d_camera(row, i))));
        for (int i = 0; i < d; ++i)
          EXPECT_NEAR(uvj[row].v[12 + i], d_uv_d_feature(row, i),
                      1e-8 * (1 + std::abs(d_uv_d_feature(row, i))));
      }
    }
  }
}

TEST(SogMeasurement, BehindTheCameraHasNoProjection) {
  MeasuredCamera camera;
  camera << 194.06, 160.22, 128.87, 0.06333, 0.0139, 0, 0, 0, 1, 0, 0, 0;
  const Eigen::Vector3d behind(0.1, 0.2, -1.0);
  Eigen::Vector2d uv;
  EXPECT_FALSE(ProjectFeatureWithJacobians(camera, kPixelMm, FeatureKind::kXyz, behind.data(), &uv,
                                           nullptr, nullptr));
}

TEST(SogInverseDepth, InitialisationReprojectsAndJacobiansMatch) {
  std::mt19937 rng(6);
  std::uniform_real_distribution<double> u(5.0, 315.0), v(5.0, 235.0);
  for (int trial = 0; trial < 20; ++trial) {
    const MeasuredCamera camera = RandomCamera(rng);
    const Eigen::Vector2d pixel(u(rng), v(rng));
    Eigen::Matrix<double, 6, 12> d_y_d_camera;
    Eigen::Matrix<double, 6, 2> d_y_d_uv;
    const InverseDepthPoint y =
        InitialiseInverseDepth(camera, kPixelMm, pixel, 0.5, &d_y_d_camera, &d_y_d_uv);
    EXPECT_LT((y.head<3>() - camera.segment<3>(5)).norm(), 1e-15);
    EXPECT_EQ(y[5], 0.5);
    // Any depth along the ray projects back onto the pixel.
    for (double rho : {0.01, 0.5, 3.0}) {
      InverseDepthPoint yy = y;
      yy[5] = rho;
      Eigen::Vector2d back;
      ASSERT_TRUE(ProjectFeatureWithJacobians(camera, kPixelMm, FeatureKind::kInverseDepth,
                                              yy.data(), &back, nullptr, nullptr));
      EXPECT_LT((back - pixel).norm(), 1e-9);
    }
    const auto by_camera = [&](const Eigen::VectorXd& c) -> Eigen::VectorXd {
      return InitialiseInverseDepth(MeasuredCamera(c), kPixelMm, pixel, 0.5);
    };
    const auto by_pixel = [&](const Eigen::VectorXd& p) -> Eigen::VectorXd {
      return InitialiseInverseDepth(camera, kPixelMm, Eigen::Vector2d(p), 0.5);
    };
    const Eigen::VectorXd cam = camera, pix = pixel;
    ExpectNear(d_y_d_camera, NumericJacobian(by_camera, cam), 1e-6, "d_y_d_camera");
    ExpectNear(d_y_d_uv, NumericJacobian(by_pixel, pix), 1e-6, "d_y_d_uv");
  }
}

TEST(SogDistortion, OffsetJacobiansMatchFiniteDifferences) {
  const double k1 = 0.06333, k2 = 0.0139;
  for (const Eigen::Vector2d& offset :
       {Eigen::Vector2d(0.0, 0.0), Eigen::Vector2d(120.0, -80.0), Eigen::Vector2d(-30.0, 5.0)}) {
    Eigen::Vector2d out;
    Eigen::Matrix2d d_off, d_k;
    ASSERT_TRUE(DistortOffset(offset, k1, k2, kPixelMm, &out, &d_off, &d_k));
    const auto by_offset = [&](const Eigen::VectorXd& o) -> Eigen::VectorXd {
      Eigen::Vector2d r;
      DistortOffset(Eigen::Vector2d(o), k1, k2, kPixelMm, &r);
      return r;
    };
    const auto by_k = [&](const Eigen::VectorXd& k) -> Eigen::VectorXd {
      Eigen::Vector2d r;
      DistortOffset(offset, k[0], k[1], kPixelMm, &r);
      return r;
    };
    ExpectNear(d_off, NumericJacobian(by_offset, Eigen::VectorXd(offset)), 1e-7, "d_offset");
    ExpectNear(d_k, NumericJacobian(by_k, Eigen::Vector2d(k1, k2), 1e-8), 1e-6, "d_k");
  }
}
