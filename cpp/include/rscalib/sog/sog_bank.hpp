#pragma once
// The Sum-of-Gaussians bank (docs/sog.md): N EKFs over the same map, advanced together with
// shared measurements, weighted by their innovation likelihoods (log space), pruned by
// Wald's SPRT behind an observability guard, merged by moment matching for output and for
// active search. One call per stage of a frame: Predict, PredictMeasurements (for the front
// end's search), Update (EKF updates, weights, pruning, map management), AddFeatures.
#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "rscalib/sog/ekf.hpp"
#include "rscalib/sog/feature_map.hpp"

namespace rscalib::sog {

struct SogOptions {
  // Noise. pixel_sigma: measurement noise R = sigma^2 I (px). Larger than the matching noise
  // (~3x on simulated data): it also covers the EKFs' early linearisation errors.
  double pixel_sigma = 1.5;
  ProcessNoise process;
  // First camera (= world frame): r = 0, q = 1 exactly; v, w zero-mean with these sigmas.
  double initial_velocity_sigma = 0.5;          // m/s
  double initial_angular_velocity_sigma = 0.5;  // rad/s
  // New features: inverse depth rho0 +- sigma (1/m). 0.5 +- 0.5 puts a new point beyond
  // 0.67 m with 95 % probability, "2 m or farther" for an indoor scene (docs/sog.md §9).
  double initial_inverse_depth = 0.5;
  double initial_inverse_depth_sigma = 0.5;
  // Map management. Inverse depth -> XYZ once the linearity index is below the threshold in
  // every filter (<= 0: never). A feature searched more than deletion_min_predictions times
  // and found in fewer than deletion_min_match_ratio of them is deleted.
  double linearity_threshold = 0.1;
  int deletion_min_predictions = 5;
  double deletion_min_match_ratio = 0.5;
  // Map cap (bounded memory and time; docs/sog.md §8): after every update the map holds at
  // most max_features features; beyond that the features matched longest ago are deleted,
  // those not searched in this frame (out of view) first. AddFeatures may exceed the cap
  // until the next update by what it adds. <= 0: no cap.
  int max_features = 100;
  // 1-point RANSAC (Civera, Grasa, Davison, Montiel, JFR 2010): ransac_hypotheses > 0 picks
  // the matches consistent with a one-match update of the leading filter within
  // ransac_threshold_px ("low-innovation inliers"), updates every filter with them, then
  // re-predicts the rest and also uses those inside the 99 % gate ("rescued"). 0: off.
  int ransac_hypotheses = 0;
  double ransac_threshold_px = 2.0;
  // Active search: a match farther than gate_chi2 (Mahalanobis^2 under the merged predicted
  // Gaussian) is treated as not found (<= 0: no gate). A feature is predicted visible when
  // filters holding at least visibility_min_weight of the weight project it.
  double gate_chi2 = 9.21;  // 99 %, 2 dof
  double visibility_min_weight = 0.5;
  // Measurement updates per frame: 1 = EKF, > 1 = iterated EKF (relinearised).
  int update_iterations = 1;
  // Weights and SPRT use N(nu; 0, S)^(1/T): T > 1 tempers the evidence of hundreds of
  // innovations that are not independent (linearisation errors are shared across features).
  double likelihood_temperature = 1.0;
  // Log-likelihood charged to a filter per used measurement it cannot predict (behind it).
  double unpredicted_log_likelihood = -50.0;
  // Pruning (SPRT, paper eq. 14-18). Type I / II error probabilities alpha, beta. A Gaussian
  // whose statistic exceeds A is kept for good (sprt_keep_accepted; else its test restarts).
  bool prune = true;
  double sprt_alpha = 0.05;
  double sprt_beta = 0.1;
  bool sprt_keep_accepted = true;
  // Guard: no pruning (and no SPRT accumulation) until the calibration is observable, i.e.
  // after guard_min_frames updates, once the camera has turned by guard_min_rotation_deg in
  // total (no rotation, no focal length: a translating camera cannot self-calibrate) and
  // once the leading Gaussian's sigma_f has shrunk to guard_f_sigma_ratio of its initial value.
  int guard_min_frames = 10;
  double guard_min_rotation_deg = 0.0;
  double guard_f_sigma_ratio = 0.5;
  // While pruning, two Gaussians whose calibrations are closer than this squared
  // Mahalanobis distance (w.r.t. the sum of their covariances) are merged (<= 0: never),
  // and Gaussians with a weight below exp(min_log_weight) are dropped (also when accepted).
  double merge_mahalanobis2 = 1.0;
  double min_log_weight = -13.8;  // 1e-6
  // Threads over the filters of the bank (1 = serial).
  int num_threads = 2;
};

// Merged (moment-matched) predicted measurements of the features visible in the bank.
struct MergedPredictions {
  std::vector<int64_t> ids;
  std::vector<Eigen::Vector2d> uv;
  std::vector<Eigen::Matrix2d> covariance;  // includes pixel noise
};

struct SogUpdateReport {
  std::vector<bool> used;           // per input row: matched, inside the gate, used
  std::vector<double> gate_chi2;    // per input row: Mahalanobis^2 to the merged prediction
  Eigen::VectorXd log_likelihoods;  // per Gaussian (before pruning), log N(nu; 0, S)
  Eigen::VectorXd nis;              // per Gaussian, nu^T S^-1 nu (expect ~ 2 num_used)
  std::vector<int> gaussian_ids;    // ids of those Gaussians
  std::vector<int> pruned_gaussian_ids;
  std::vector<int> merged_gaussian_ids;  // removed as duplicates of a heavier Gaussian
  std::vector<int64_t> deleted_feature_ids;
  std::vector<int64_t> converted_feature_ids;
  int num_used = 0;
  int num_low_innovation = 0;  // 1-point RANSAC: inliers of the best hypothesis (else num_used)
  int num_rescued = 0;         // 1-point RANSAC: used in the second (rescue) update
  int num_capped = 0;          // features deleted by the map cap (max_features)
  int num_gaussians = 0;       // after pruning
  bool pruning_active = false;
};

class SogBank {
 public:
  // means (N, 5) [f, Cx, Cy, k1, k2], covariances (N, 5x5), weights (N, > 0, any scale);
  // image size in px; pixel_size_mm (dx, dy). Throws InputError on bad input.
  SogBank(const SogOptions& options, const std::vector<Vector5d>& means,
          const std::vector<Matrix5d>& covariances, const std::vector<double>& weights, int width,
          int height, const Eigen::Vector2d& pixel_size_mm);

  // Replaces the camera's motion state [r, q, v, w] (13) and covariance in every filter.
  void SetCameraState(const MotionState& state, const Matrix13d& covariance);

  void Predict(double dt_s);
  MergedPredictions PredictMeasurements();
  // ids: features searched this frame (normally those of PredictMeasurements); uv: their
  // measured pixels (rows of unmatched features are ignored); matched: found or not.
  SogUpdateReport Update(const std::vector<int64_t>& ids, const std::vector<Eigen::Vector2d>& uv,
                         const std::vector<bool>& matched);
  // New inverse-depth features at distorted pixels; returns their ids.
  std::vector<int64_t> AddFeatures(const std::vector<Eigen::Vector2d>& uv);
  void RemoveFeatures(const std::vector<int64_t>& ids);

  // ---- state
  const SogOptions& options() const { return options_; }
  int width() const { return width_; }
  int height() const { return height_; }
  const Eigen::Vector2d& pixel_size_mm() const { return pixel_size_mm_; }
  int num_gaussians() const { return static_cast<int>(filters_.size()); }
  int frame() const { return frame_; }
  const FeatureMap& map() const { return map_; }
  const SelfCalibrationEkf& filter(int index) const;
  const std::vector<int>& gaussian_ids() const { return gaussian_ids_; }
  const Eigen::VectorXd& log_weights() const { return log_weights_; }
  Eigen::VectorXd weights() const;
  int leading_gaussian() const;
  bool pruning_active() const { return pruning_active_; }
  // Rotation of the leading filter's camera accumulated over the predictions (rad).
  double accumulated_rotation_rad() const { return accumulated_rotation_rad_; }
  const Eigen::VectorXd& sprt_log_statistic() const { return sprt_statistic_; }
  const std::vector<bool>& sprt_accepted() const { return sprt_accepted_; }
  // Moment-matched calibration [f, Cx, Cy, k1, k2] and its covariance (paper eq. 5).
  void CalibrationMoments(Vector5d* mean, Matrix5d* covariance) const;
  // Moment-matched motion state [r, q, v, w] and its covariance.
  void MotionMoments(MotionState* mean, Matrix13d* covariance) const;

 private:
  template <typename Fn>
  void ForEachFilter(Fn&& fn) const;
  void EnsurePredictions(const std::vector<int>& indices);
  bool MergePrediction(int index, Eigen::Vector2d* uv, Eigen::Matrix2d* covariance) const;
  void MergeConverged(std::vector<bool>* remove, SogUpdateReport* report);
  void Prune(const std::vector<bool>& remove, SogUpdateReport* report);
  void ManageMap(const std::vector<int>& searched, SogUpdateReport* report);
  std::vector<int> OnePointRansac(const std::vector<int>& indices, const std::vector<int>& rows,
                                  const std::vector<Eigen::Vector2d>& uv) const;
  void UpdateFilters(const std::vector<int>& indices, const std::vector<int>& rows,
                     const std::vector<Eigen::Vector2d>& uv, Eigen::VectorXd* log_lik,
                     Eigen::VectorXd* nis);
  void Restructure(const std::vector<bool>& remove, const std::vector<bool>& convert);

  SogOptions options_;
  int width_, height_;
  Eigen::Vector2d pixel_size_mm_;
  FeatureMap map_;
  std::vector<SelfCalibrationEkf> filters_;
  std::vector<int> gaussian_ids_;
  std::vector<double> initial_f_sigma_;
  Eigen::VectorXd log_weights_;
  Eigen::VectorXd sprt_statistic_;
  std::vector<bool> sprt_accepted_;
  bool pruning_active_ = false;
  double accumulated_rotation_rad_ = 0.0;
  int frame_ = 0;
  // predictions_[filter][feature index]; computed[feature index] says which are current.
  std::vector<std::vector<FeaturePrediction>> predictions_;
  std::vector<bool> predicted_;
};

}  // namespace rscalib::sog
