// The SOG self-calibration bank (SogBank) of EKFs (ekf.cpp). docs/sog.md has the maths;
// comments here say why the code is shaped as it is.
#include "rscalib/sog/sog_bank.hpp"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <limits>
#include <random>
#include <string>
#include <thread>

#include <Eigen/Dense>

#include "rscalib/core/error.hpp"
#include "rscalib/sog/inverse_depth.hpp"
#include "rscalib/sog/measurement_model.hpp"
#include "rscalib/sog/mixture.hpp"
#include "rscalib/sog/sprt.hpp"

namespace rscalib::sog {

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

// Runs fn(i) for i in [0, count) on up to num_threads threads (the calling one included).
template <typename Fn>
void ParallelFor(int count, int num_threads, Fn&& fn) {
  const int threads = std::max(1, std::min(num_threads, count));
  if (threads == 1) {
    for (int i = 0; i < count; ++i) fn(i);
    return;
  }
  std::atomic<int> next{0};
  const auto worker = [&]() {
    for (int i = next++; i < count; i = next++) fn(i);
  };
  std::vector<std::thread> pool;
  for (int t = 1; t < threads; ++t) pool.emplace_back(worker);
  worker();
  for (std::thread& thread : pool) thread.join();
}

// Moment-matched mean and covariance (paper eq. 5) of the state block [offset, offset + Dim)
// over the filters of the bank.
template <int Dim>
void BlockMoments(const std::vector<SelfCalibrationEkf>& filters,
                  const Eigen::VectorXd& log_weights, int offset,
                  Eigen::Matrix<double, Dim, 1>* mean,
                  Eigen::Matrix<double, Dim, Dim>* covariance) {
  const size_t count = filters.size();
  std::vector<double> w(count);
  std::vector<Eigen::Matrix<double, Dim, 1>> means(count);
  std::vector<Eigen::Matrix<double, Dim, Dim>> covs(count);
  for (size_t i = 0; i < count; ++i) {
    w[i] = std::exp(log_weights[static_cast<Eigen::Index>(i)]);
    means[i] = filters[i].mean().template segment<Dim>(offset);
    covs[i] = filters[i].covariance().template block<Dim, Dim>(offset, offset);
  }
  MergeGaussians<Dim>(w, means, covs, mean, covariance);
}

}  // namespace

SogBank::SogBank(const SogOptions& options, const std::vector<Vector5d>& means,
                 const std::vector<Matrix5d>& covariances, const std::vector<double>& weights,
                 int width, int height, const Eigen::Vector2d& pixel_size_mm)
    : options_(options), width_(width), height_(height), pixel_size_mm_(pixel_size_mm) {
  const size_t count = means.size();
  if (count == 0) throw InputError("SogBank: at least one Gaussian is needed");
  if (covariances.size() != count || weights.size() != count)
    throw InputError("SogBank: means, covariances and weights must have the same length");
  if (width <= 0 || height <= 0) throw InputError("SogBank: image size must be positive");
  if (!(pixel_size_mm[0] > 0.0 && pixel_size_mm[1] > 0.0))
    throw InputError("SogBank: pixel_size_mm must be positive");
  if (!(options.pixel_sigma > 0.0)) throw InputError("SogBank: pixel_sigma must be > 0");
  if (!(options.likelihood_temperature >= 1.0))
    throw InputError("SogBank: likelihood_temperature must be >= 1");
  if (!(options.sprt_alpha > 0.0 && options.sprt_alpha < 1.0 && options.sprt_beta > 0.0 &&
        options.sprt_beta < 1.0))
    throw InputError("SogBank: sprt_alpha and sprt_beta must be in (0, 1)");
  MotionState motion = MotionState::Zero();
  motion[3] = 1.0;  // q = identity: the world frame is the first camera frame
  Matrix13d motion_cov = Matrix13d::Zero();
  motion_cov.block<3, 3>(7, 7).diagonal().setConstant(std::pow(options.initial_velocity_sigma, 2));
  motion_cov.block<3, 3>(10, 10).diagonal().setConstant(
      std::pow(options.initial_angular_velocity_sigma, 2));
  log_weights_.resize(static_cast<Eigen::Index>(count));
  for (size_t i = 0; i < count; ++i) {
    if (!means[i].allFinite() || !(means[i][0] > 0.0))
      throw InputError("SogBank: every mean needs a finite f > 0");
    const Matrix5d sym = 0.5 * (covariances[i] + covariances[i].transpose());
    if (!sym.allFinite() || Eigen::LLT<Matrix5d>(sym).info() != Eigen::Success)
      throw InputError("SogBank: covariance " + std::to_string(i) + " is not positive definite");
    if (!(weights[i] > 0.0) || !std::isfinite(weights[i]))
      throw InputError("SogBank: weights must be positive and finite");
    filters_.emplace_back(means[i], sym, motion, motion_cov);
    gaussian_ids_.push_back(static_cast<int>(i));
    initial_f_sigma_.push_back(std::sqrt(sym(0, 0)));
    log_weights_[static_cast<Eigen::Index>(i)] = std::log(weights[i]);
  }
  log_weights_.array() -= LogSumExp(log_weights_);
  sprt_statistic_ = Eigen::VectorXd::Zero(log_weights_.size());
  sprt_accepted_.assign(count, false);
  predictions_.resize(count);
}

template <typename Fn>
void SogBank::ForEachFilter(Fn&& fn) const {
  ParallelFor(num_gaussians(), options_.num_threads, fn);
}

const SelfCalibrationEkf& SogBank::filter(int index) const {
  if (index < 0 || index >= num_gaussians()) throw InputError("SogBank: filter index out of range");
  return filters_[index];
}

Eigen::VectorXd SogBank::weights() const { return log_weights_.array().exp(); }

int SogBank::leading_gaussian() const {
  Eigen::Index best = 0;
  log_weights_.maxCoeff(&best);
  return static_cast<int>(best);
}

void SogBank::SetCameraState(const MotionState& state, const Matrix13d& covariance) {
  if (!state.allFinite() || !covariance.allFinite())
    throw InputError("SogBank: camera state must be finite");
  for (SelfCalibrationEkf& f : filters_)
    f.SetMotionState(state, 0.5 * (covariance + covariance.transpose()));
  predicted_.assign(map_.size(), false);
}

void SogBank::Predict(double dt_s) {
  if (!(dt_s >= 0.0) || !std::isfinite(dt_s)) throw InputError("SogBank: dt_s must be >= 0");
  const Eigen::Vector3d w = filters_[leading_gaussian()].mean().segment<3>(kAngularVelocity);
  accumulated_rotation_rad_ += w.norm() * dt_s;
  ForEachFilter([&](int i) { filters_[i].Predict(dt_s, options_.process); });
  predicted_.assign(map_.size(), false);
}

void SogBank::EnsurePredictions(const std::vector<int>& indices) {
  predicted_.resize(map_.size(), false);
  std::vector<int> missing;
  for (int index : indices)
    if (!predicted_[index]) missing.push_back(index);
  if (missing.empty()) return;
  ForEachFilter([&](int i) {
    predictions_[i].resize(map_.size());
    filters_[i].PredictMeasurements(map_, missing, pixel_size_mm_, options_.pixel_sigma,
                                    &predictions_[i]);
  });
  for (int index : missing) predicted_[index] = true;
}

bool SogBank::MergePrediction(int index, Eigen::Vector2d* uv, Eigen::Matrix2d* covariance) const {
  std::vector<double> w;
  std::vector<Eigen::Vector2d> means;
  std::vector<Eigen::Matrix2d> covs;
  double total = 0.0;
  for (int i = 0; i < num_gaussians(); ++i) {
    const FeaturePrediction& p = predictions_[i][index];
    if (!p.valid) continue;
    const double wi = std::exp(log_weights_[i]);
    total += wi;
    w.push_back(wi);
    means.push_back(p.uv);
    covs.push_back(p.innovation_covariance);
  }
  if (!(total >= options_.visibility_min_weight) || w.empty()) return false;
  MergeGaussians<2>(w, means, covs, uv, covariance);
  return uv->allFinite() && covariance->allFinite();
}

MergedPredictions SogBank::PredictMeasurements() {
  std::vector<int> all(map_.size());
  for (int k = 0; k < map_.size(); ++k) all[k] = k;
  EnsurePredictions(all);
  MergedPredictions out;
  for (int k = 0; k < map_.size(); ++k) {
    Eigen::Vector2d uv;
    Eigen::Matrix2d cov;
    if (!MergePrediction(k, &uv, &cov)) continue;
    // Inside the image: pixel (u, v) covers [u - 1/2, u + 1/2] (docs/conventions.md).
    if (uv[0] < -0.5 || uv[1] < -0.5 || uv[0] > width_ - 0.5 || uv[1] > height_ - 0.5) continue;
    out.ids.push_back(map_[k].id);
    out.uv.push_back(uv);
    out.covariance.push_back(cov);
  }
  return out;
}

SogUpdateReport SogBank::Update(const std::vector<int64_t>& ids,
                                const std::vector<Eigen::Vector2d>& uv,
                                const std::vector<bool>& matched) {
  const size_t rows = ids.size();
  if (uv.size() != rows || matched.size() != rows)
    throw InputError("SogBank.update: ids, uv and matched must have the same length");
  std::vector<int> indices(rows);
  for (size_t r = 0; r < rows; ++r) {
    indices[r] = map_.IndexOf(ids[r]);
    if (indices[r] < 0)
      throw InputError("SogBank.update: unknown feature id " + std::to_string(ids[r]));
    for (size_t s = 0; s < r; ++s)
      if (indices[s] == indices[r]) throw InputError("SogBank.update: repeated feature id");
  }
  EnsurePredictions(indices);
  ++frame_;

  SogUpdateReport report;
  report.used.assign(rows, false);
  report.gate_chi2.assign(rows, std::numeric_limits<double>::quiet_NaN());
  // Row r's match inside the 99 % gate of its merged prediction? Records its chi2 either way.
  const auto passes_gate = [&](size_t r) {
    Eigen::Vector2d mean;
    Eigen::Matrix2d cov;
    if (!MergePrediction(indices[r], &mean, &cov)) return false;
    const Eigen::Vector2d d = uv[r] - mean;
    report.gate_chi2[r] = d.dot(cov.ldlt().solve(d));
    return !(options_.gate_chi2 > 0.0 && !(report.gate_chi2[r] <= options_.gate_chi2));
  };
  // Gate every match against the merged prediction (99 %).
  std::vector<int> gated_rows;
  for (size_t r = 0; r < rows; ++r) {
    map_[indices[r]].times_predicted += 1;
    if (!matched[r] || !uv[r].allFinite()) continue;
    if (passes_gate(r)) gated_rows.push_back(static_cast<int>(r));
  }
  // 1-point RANSAC (optional): the low-innovation inliers first, then the rest re-gated.
  std::vector<int> first_rows = gated_rows, rest_rows;
  if (options_.ransac_hypotheses > 0 && gated_rows.size() >= 3) {
    const std::vector<int> inliers = OnePointRansac(indices, gated_rows, uv);
    if (!inliers.empty()) {
      first_rows = inliers;
      std::vector<bool> is_inlier(rows, false);
      for (int r : inliers) is_inlier[r] = true;
      for (int r : gated_rows)
        if (!is_inlier[r]) rest_rows.push_back(r);
    }
  }
  report.num_low_innovation = static_cast<int>(first_rows.size());

  // Every filter is updated with the same measurements (its own H, S, gain). A filter that
  // cannot predict one of them is charged a fixed log-likelihood for it instead.
  const int n_filters = num_gaussians();
  Eigen::VectorXd log_lik = Eigen::VectorXd::Zero(n_filters);
  Eigen::VectorXd nis = Eigen::VectorXd::Zero(n_filters);
  UpdateFilters(indices, first_rows, uv, &log_lik, &nis);
  predicted_.assign(map_.size(), false);
  std::vector<int> used_rows = first_rows;
  if (!rest_rows.empty()) {
    // Rescue (Civera et al. 2010): re-predict after the low-innovation update; matches now
    // inside the 99 % gate are used in a second update (p(z1) p(z2 | z1): the log-likelihoods add).
    std::vector<int> rest_indices;
    for (int r : rest_rows) rest_indices.push_back(indices[r]);
    EnsurePredictions(rest_indices);
    std::vector<int> rescued;
    for (int r : rest_rows)
      if (passes_gate(r)) rescued.push_back(r);
    if (!rescued.empty()) {
      Eigen::VectorXd ll2 = Eigen::VectorXd::Zero(n_filters),
                      nis2 = Eigen::VectorXd::Zero(n_filters);
      UpdateFilters(indices, rescued, uv, &ll2, &nis2);
      log_lik += ll2;
      nis += nis2;
      predicted_.assign(map_.size(), false);
      used_rows.insert(used_rows.end(), rescued.begin(), rescued.end());
    }
    report.num_rescued = static_cast<int>(rescued.size());
  }
  for (int r : used_rows) {
    report.used[r] = true;
    map_[indices[r]].times_matched += 1;
    map_[indices[r]].frame_last_matched = frame_;
  }
  report.num_used = static_cast<int>(used_rows.size());
  report.log_likelihoods = log_lik;
  report.nis = nis;
  report.gaussian_ids = gaussian_ids_;

  if (!(log_lik.maxCoeff() > -kInf)) {
    // Every filter failed (nothing can be weighed): leave the bank as it is.
    report.num_gaussians = num_gaussians();
    report.pruning_active = pruning_active_;
    return report;
  }
  // Weights (eq. 2) and the SPRT (eq. 14-18), both from the weights before this frame.
  const Eigen::VectorXd tempered = log_lik / options_.likelihood_temperature;
  const Eigen::VectorXd ratios = SprtLogRatios(log_weights_, tempered);
  log_weights_ = UpdateLogWeights(log_weights_, tempered);
  std::vector<bool> remove(n_filters, false);
  for (int i = 0; i < n_filters; ++i) remove[i] = !std::isfinite(log_weights_[i]);
  if (options_.prune && n_filters > 1) {
    const int lead = leading_gaussian();
    if (!pruning_active_) {
      const double sigma_f = std::sqrt(filters_[lead].covariance()(0, 0));
      pruning_active_ =
          frame_ >= options_.guard_min_frames &&
          accumulated_rotation_rad_ >= options_.guard_min_rotation_deg * M_PI / 180.0 &&
          sigma_f <= options_.guard_f_sigma_ratio * initial_f_sigma_[lead];
    }
    if (pruning_active_) {
      const WaldBoundaries wald = MakeWaldBoundaries(options_.sprt_alpha, options_.sprt_beta);
      for (int i = 0; i < n_filters; ++i) {
        if (log_weights_[i] < options_.min_log_weight && i != lead) remove[i] = true;
        if (sprt_accepted_[i]) continue;
        sprt_statistic_[i] += ratios[i];
        if (sprt_statistic_[i] > wald.log_accept) {
          if (options_.sprt_keep_accepted) sprt_accepted_[i] = true;
          else sprt_statistic_[i] = 0.0;  // decided "keep": start a new test
        } else if (sprt_statistic_[i] < wald.log_reject && i != lead) {
          remove[i] = true;
        }
      }
      MergeConverged(&remove, &report);
    }
  }
  if (std::find(remove.begin(), remove.end(), false) == remove.end())
    remove[leading_gaussian()] = false;  // never empty the bank
  Prune(remove, &report);
  report.pruning_active = pruning_active_;
  report.num_gaussians = num_gaussians();
  ManageMap(indices, &report);
  return report;
}

void SogBank::UpdateFilters(const std::vector<int>& indices, const std::vector<int>& rows,
                            const std::vector<Eigen::Vector2d>& uv, Eigen::VectorXd* log_lik,
                            Eigen::VectorXd* nis) {
  const UpdateSettings settings{options_.pixel_sigma, options_.update_iterations, pixel_size_mm_};
  ForEachFilter([&](int i) {
    std::vector<int> idx;
    std::vector<FeaturePrediction> preds;
    std::vector<Eigen::Vector2d> z;
    int unpredicted = 0;
    for (int r : rows) {
      const FeaturePrediction& p = predictions_[i][indices[r]];
      if (!p.valid) {
        ++unpredicted;
        continue;
      }
      idx.push_back(indices[r]);
      preds.push_back(p);
      z.push_back(uv[r]);
    }
    double ll = 0.0;
    if (!filters_[i].Update(map_, idx, preds, z, settings, &ll, &(*nis)[i]) ||
        !filters_[i].IsFinite() || !(filters_[i].mean()[0] > 0.0))
      ll = -kInf;  // a diverged filter: drop it
    (*log_lik)[i] = ll + unpredicted * options_.unpredicted_log_likelihood;
  });
}

std::vector<int> SogBank::OnePointRansac(const std::vector<int>& indices,
                                         const std::vector<int>& rows,
                                         const std::vector<Eigen::Vector2d>& uv) const {
  // Hypotheses from the leading filter: the state after an EKF update with one match; its
  // support is the matches it predicts within ransac_threshold_px. Deterministic per frame.
  const int lead = leading_gaussian();
  const SelfCalibrationEkf& filter = filters_[lead];
  const Eigen::VectorXd& x = filter.mean();
  const Eigen::MatrixXd& p = filter.covariance();
  std::vector<int> candidates;
  for (int r : rows)
    if (predictions_[lead][indices[r]].valid) candidates.push_back(r);
  const int count = static_cast<int>(candidates.size());
  if (count < 3) return {};
  std::mt19937 rng(static_cast<uint32_t>(frame_) * 2654435761u + 12345u);
  std::uniform_int_distribution<int> pick(0, count - 1);
  const double threshold2 = options_.ransac_threshold_px * options_.ransac_threshold_px;
  std::vector<int> best;
  int hypotheses = options_.ransac_hypotheses;
  Eigen::VectorXd xh(x.size());
  for (int h = 0; h < hypotheses; ++h) {
    const int r = candidates[pick(rng)];
    const FeaturePrediction& pr = predictions_[lead][indices[r]];
    const MapFeature& f = map_[indices[r]];
    const int d = FeatureDim(f.kind);
    Eigen::MatrixXd pht = p.leftCols<12>() * pr.d_uv_d_camera.transpose();
    pht.noalias() += p.middleCols(f.offset, d) * pr.d_uv_d_feature.leftCols(d).transpose();
    const Eigen::Vector2d nu = uv[r] - pr.uv;
    xh = x + pht * pr.innovation_covariance.ldlt().solve(nu);
    if (!xh.allFinite()) continue;
    std::vector<int> support;
    for (int k : candidates) {
      const MapFeature& g = map_[indices[k]];
      Eigen::Vector2d predicted;
      if (!ProjectFeature<double>(xh.data(), pixel_size_mm_.data(), g.kind, xh.data() + g.offset,
                                  predicted.data()))
        continue;
      if ((uv[k] - predicted).squaredNorm() <= threshold2) support.push_back(k);
    }
    if (support.size() > best.size()) {
      best.swap(support);
      // Hypotheses for 99 % confidence of one all-inlier draw at this inlier ratio.
      const double inlier_ratio = static_cast<double>(best.size()) / count;
      if (inlier_ratio >= 1.0) break;
      const double needed = std::log(0.01) / std::log(1.0 - inlier_ratio);
      hypotheses = std::min(options_.ransac_hypotheses,
                            std::max(h + 1, static_cast<int>(std::ceil(needed))));
    }
  }
  if (best.size() < 3) return {};
  std::sort(best.begin(), best.end());
  return best;
}

void SogBank::MergeConverged(std::vector<bool>* remove, SogUpdateReport* report) {
  // Gaussians accepted by the SPRT are never pruned; two that have converged to the same
  // calibration are one hypothesis: keep the heavier filter with the summed weight.
  if (!(options_.merge_mahalanobis2 > 0.0)) return;
  std::vector<int> order(num_gaussians());
  for (int i = 0; i < num_gaussians(); ++i) order[i] = i;
  std::sort(order.begin(), order.end(),
            [&](int a, int b) { return log_weights_[a] > log_weights_[b]; });
  for (size_t a = 0; a < order.size(); ++a) {
    const int i = order[a];
    if ((*remove)[i]) continue;
    for (size_t b = a + 1; b < order.size(); ++b) {
      const int j = order[b];
      if ((*remove)[j]) continue;
      const Vector5d d = filters_[i].calibration() - filters_[j].calibration();
      const Matrix5d c =
          filters_[i].calibration_covariance() + filters_[j].calibration_covariance();
      const Eigen::LDLT<Matrix5d> ldlt(c);
      if (ldlt.info() != Eigen::Success || !(d.dot(ldlt.solve(d)) < options_.merge_mahalanobis2))
        continue;
      (*remove)[j] = true;
      const double hi = std::max(log_weights_[i], log_weights_[j]);
      log_weights_[i] =
          hi + std::log(std::exp(log_weights_[i] - hi) + std::exp(log_weights_[j] - hi));
      log_weights_[j] = -kInf;
      report->merged_gaussian_ids.push_back(gaussian_ids_[j]);
    }
  }
}

void SogBank::Prune(const std::vector<bool>& remove, SogUpdateReport* report) {
  if (std::find(remove.begin(), remove.end(), true) == remove.end()) return;
  std::vector<SelfCalibrationEkf> filters;
  std::vector<int> ids;
  std::vector<double> sigma0;
  std::vector<double> log_w, stat;
  std::vector<bool> accepted;
  std::vector<std::vector<FeaturePrediction>> predictions;
  for (int i = 0; i < num_gaussians(); ++i) {
    if (remove[i]) {
      const auto& merged = report->merged_gaussian_ids;
      if (std::find(merged.begin(), merged.end(), gaussian_ids_[i]) == merged.end())
        report->pruned_gaussian_ids.push_back(gaussian_ids_[i]);
      continue;
    }
    filters.push_back(std::move(filters_[i]));
    ids.push_back(gaussian_ids_[i]);
    sigma0.push_back(initial_f_sigma_[i]);
    log_w.push_back(log_weights_[i]);
    stat.push_back(sprt_statistic_[i]);
    accepted.push_back(sprt_accepted_[i]);
    predictions.push_back(std::move(predictions_[i]));
  }
  filters_.swap(filters);
  gaussian_ids_.swap(ids);
  initial_f_sigma_.swap(sigma0);
  log_weights_ = Eigen::Map<Eigen::VectorXd>(log_w.data(), static_cast<Eigen::Index>(log_w.size()));
  log_weights_.array() -= LogSumExp(log_weights_);
  sprt_statistic_ =
      Eigen::Map<Eigen::VectorXd>(stat.data(), static_cast<Eigen::Index>(stat.size()));
  sprt_accepted_.swap(accepted);
  predictions_.swap(predictions);
}

void SogBank::ManageMap(const std::vector<int>& searched, SogUpdateReport* report) {
  const int count = map_.size();
  std::vector<bool> remove(count, false), convert(count, false);
  for (int k = 0; k < count; ++k) {
    const MapFeature& f = map_[k];
    remove[k] = f.times_predicted > options_.deletion_min_predictions &&
                f.times_matched < options_.deletion_min_match_ratio * f.times_predicted;
  }
  if (options_.linearity_threshold > 0.0) {
    // Converted when linear enough in every filter, so the map structure stays shared.
    std::vector<std::vector<double>> index(num_gaussians(), std::vector<double>(count, kInf));
    ForEachFilter([&](int i) {
      const SelfCalibrationEkf& filter = filters_[i];
      const Eigen::Vector3d r = filter.mean().segment<3>(kPosition);
      for (int k = 0; k < count; ++k) {
        const MapFeature& f = map_[k];
        if (remove[k] || f.kind != FeatureKind::kInverseDepth) continue;
        const int rho = f.offset + 5;
        index[i][k] =
            LinearityIndex(filter.mean().segment<6>(f.offset), filter.covariance()(rho, rho), r);
      }
    });
    for (int k = 0; k < count; ++k) {
      if (remove[k] || map_[k].kind != FeatureKind::kInverseDepth) continue;
      double worst = 0.0;
      for (int i = 0; i < num_gaussians(); ++i) worst = std::max(worst, index[i][k]);
      convert[k] = worst < options_.linearity_threshold;
    }
  }
  if (options_.max_features > 0) {
    // The cap: delete the features matched longest ago, those not searched this frame first.
    std::vector<bool> was_searched(count, false);
    for (int k : searched) was_searched[k] = true;
    std::vector<int> kept;
    for (int k = 0; k < count; ++k)
      if (!remove[k]) kept.push_back(k);
    const int excess = static_cast<int>(kept.size()) - options_.max_features;
    if (excess > 0) {
      const auto recency = [&](int k) {
        return std::max(map_[k].frame_last_matched, map_[k].frame_added);
      };
      std::stable_sort(kept.begin(), kept.end(), [&](int a, int b) {
        if (was_searched[a] != was_searched[b]) return !was_searched[a];
        return recency(a) < recency(b);
      });
      for (int j = 0; j < excess; ++j) remove[kept[j]] = true;
      report->num_capped = excess;
    }
  }
  for (int k = 0; k < count; ++k) {
    if (remove[k]) report->deleted_feature_ids.push_back(map_[k].id);
    else if (convert[k]) report->converted_feature_ids.push_back(map_[k].id);
  }
  Restructure(remove, convert);
}

void SogBank::Restructure(const std::vector<bool>& remove, const std::vector<bool>& convert) {
  const StateRestructure plan = map_.Plan(remove, convert);
  if (plan.trivial) return;
  ForEachFilter([&](int i) { filters_[i].Restructure(plan); });
  map_.Apply(remove, convert);
  for (auto& p : predictions_) p.clear();
  predicted_.assign(map_.size(), false);
}

std::vector<int64_t> SogBank::AddFeatures(const std::vector<Eigen::Vector2d>& uv) {
  for (const Eigen::Vector2d& p : uv)
    if (!p.allFinite()) throw InputError("SogBank.add_features: pixels must be finite");
  if (uv.empty()) return {};
  std::vector<char> ok(num_gaussians(), 1);
  ForEachFilter([&](int i) {
    ok[i] = filters_[i].AddInverseDepthFeatures(uv, pixel_size_mm_, options_.initial_inverse_depth,
                                                options_.initial_inverse_depth_sigma,
                                                options_.pixel_sigma);
  });
  if (std::find(ok.begin(), ok.end(), 0) != ok.end())
    throw InputError("SogBank.add_features: a filter could not back-project the pixels");
  const std::vector<int64_t> ids = map_.AddInverseDepth(static_cast<int>(uv.size()), frame_);
  predicted_.resize(map_.size(), false);
  for (auto& p : predictions_) p.resize(map_.size());
  return ids;
}

void SogBank::RemoveFeatures(const std::vector<int64_t>& ids) {
  std::vector<bool> remove(map_.size(), false), convert(map_.size(), false);
  for (int64_t id : ids) {
    const int k = map_.IndexOf(id);
    if (k < 0)
      throw InputError("SogBank.remove_features: unknown feature id " + std::to_string(id));
    remove[k] = true;
  }
  Restructure(remove, convert);
}

void SogBank::CalibrationMoments(Vector5d* mean, Matrix5d* covariance) const {
  BlockMoments<kCalibrationDim>(filters_, log_weights_, kCalibration, mean, covariance);
}

void SogBank::MotionMoments(MotionState* mean, Matrix13d* covariance) const {
  BlockMoments<kMotionDim>(filters_, log_weights_, kPosition, mean, covariance);
}

}  // namespace rscalib::sog
