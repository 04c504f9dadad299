#pragma once
// One EKF of the bank (docs/sog.md §2-5): monocular inverse-depth SLAM whose state also holds
// the calibration (f, Cx, Cy, k1, k2). The map structure (which feature sits where) is the
// bank's shared FeatureMap; this class owns only numbers: mean and covariance.
#include <vector>

#include <Eigen/Core>

#include "rscalib/sog/feature_map.hpp"
#include "rscalib/sog/measurement_model.hpp"
#include "rscalib/sog/motion_model.hpp"
#include "rscalib/sog/state_layout.hpp"

namespace rscalib::sog {

using Vector5d = Eigen::Matrix<double, 5, 1>;
using Matrix5d = Eigen::Matrix<double, 5, 5>;
using Matrix13d = Eigen::Matrix<double, 13, 13>;

struct ProcessNoise {
  double accel_sigma = 3.0;                             // m/s^2
  double angular_accel_sigma = 4.5;                     // rad/s^2
  Vector5d calibration_random_walk = Vector5d::Zero();  // per sqrt(s); 0 = static calibration
};

// One feature's predicted measurement in one filter: uv = h(x), its Jacobian blocks and the
// innovation covariance S = H P H^T + sigma^2 I.
struct FeaturePrediction {
  bool valid = false;
  Eigen::Vector2d uv = Eigen::Vector2d::Zero();
  Eigen::Matrix<double, 2, kMeasuredCameraDim> d_uv_d_camera = Eigen::Matrix<double, 2, 12>::Zero();
  Eigen::Matrix<double, 2, 6> d_uv_d_feature = Eigen::Matrix<double, 2, 6>::Zero();
  Eigen::Matrix2d innovation_covariance = Eigen::Matrix2d::Identity();
};

struct UpdateSettings {
  double pixel_sigma = 1.0;  // R = sigma^2 I
  int iterations = 1;        // 1: EKF; > 1: iterated EKF (relinearise at the updated mean)
  Eigen::Vector2d pixel_size_mm = Eigen::Vector2d::Constant(0.0112);
};

class SelfCalibrationEkf {
 public:
  // A filter with no features: calibration prior, and the 13-D motion state [r, q, v, w].
  SelfCalibrationEkf(const Vector5d& calibration, const Matrix5d& calibration_covariance,
                     const MotionState& motion, const Matrix13d& motion_covariance);

  const Eigen::VectorXd& mean() const { return x_; }
  const Eigen::MatrixXd& covariance() const { return p_; }
  // For tests and for resetting the camera; keep the sizes.
  Eigen::VectorXd& mutable_mean() { return x_; }
  Eigen::MatrixXd& mutable_covariance() { return p_; }
  int dim() const { return static_cast<int>(x_.size()); }
  Vector5d calibration() const { return x_.head<5>(); }
  Matrix5d calibration_covariance() const { return p_.topLeftCorner<5, 5>(); }
  MeasuredCamera measured_camera() const { return x_.head<kMeasuredCameraDim>(); }
  bool IsFinite() const { return x_.allFinite() && p_.diagonal().allFinite(); }

  // Constant-velocity step of dt seconds: O(n) in the map size.
  void Predict(double dt_s, const ProcessNoise& noise);

  // Predicted measurements of the map features `indices`.
  void PredictMeasurements(const FeatureMap& map, const std::vector<int>& indices,
                           const Eigen::Vector2d& pixel_size_mm, double pixel_sigma,
                           std::vector<FeaturePrediction>* predictions) const;

  // (Iterated) EKF update with measurements z[k] of map feature indices[k], whose (valid)
  // predictions at the current mean are predictions[k]. *log_likelihood = log N(nu; 0, S) and
  // *nis = nu^T S^-1 nu of the stacked innovation, at the prior mean. False (and no change)
  // if S is not positive definite.
  bool Update(const FeatureMap& map, const std::vector<int>& indices,
              const std::vector<FeaturePrediction>& predictions,
              const std::vector<Eigen::Vector2d>& z, const UpdateSettings& settings,
              double* log_likelihood, double* nis = nullptr);

  // Appends one inverse-depth feature per distorted pixel, initialised from this filter's
  // calibration and pose at inverse depth rho0 +- rho_sigma, with pixel noise pixel_sigma.
  // False (nothing added) if a pixel cannot be back-projected (degenerate calibration).
  bool AddInverseDepthFeatures(const std::vector<Eigen::Vector2d>& uv,
                               const Eigen::Vector2d& pixel_size_mm, double rho0, double rho_sigma,
                               double pixel_sigma);

  // Converts and removes features as planned by FeatureMap::Plan.
  void Restructure(const StateRestructure& plan);

  // Replaces [r, q, v, w] and its covariance (cross-covariances with it are zeroed).
  void SetMotionState(const MotionState& motion, const Matrix13d& covariance);

 private:
  void NormaliseQuaternion();

  Eigen::VectorXd x_;
  Eigen::MatrixXd p_;
};

}  // namespace rscalib::sog
