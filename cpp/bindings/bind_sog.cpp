// Bindings: the SOG self-calibration bank (engine 2). API and maths: docs/sog.md.
#include <cmath>
#include <string>
#include <vector>

#include <pybind11/eigen.h>
#include <pybind11/stl.h>

#include "bindings.hpp"
#include "rscalib/core/error.hpp"
#include "rscalib/core/memory_limit.hpp"
#include "rscalib/sog/inverse_depth.hpp"
#include "rscalib/sog/sog_bank.hpp"

// predict / update / add_features run without the GIL: calls on one bank are serialised.
RSCALIB_GUARDED_CASTER(rscalib::sog::SogBank, true)
RSCALIB_GUARDED_CASTER(rscalib::sog::SogOptions, false)
RSCALIB_GUARDED_CASTER(rscalib::sog::SogUpdateReport, false)

namespace rscalib::python {

using sog::Matrix13d;
using sog::Matrix5d;
using sog::MotionState;
using sog::SogBank;
using sog::SogOptions;
using sog::SogUpdateReport;
using sog::Vector5d;

namespace {

constexpr double kZ99 = 2.5758293035489004;  // two-sided 99 % normal quantile

std::vector<Eigen::Vector2d> Rows2(const DoubleArray& array, const char* what) {
  if (array.ndim() == 1 && array.shape(0) == 0) return {};
  bool vector = false;
  const py::ssize_t count = CheckRows(array, 2, what, &vector);
  std::vector<Eigen::Vector2d> out(count);
  for (py::ssize_t i = 0; i < count; ++i)
    out[i] = Eigen::Map<const Eigen::Vector2d>(array.data() + 2 * i);
  return out;
}

std::vector<int64_t> Ids(
    const py::array_t<int64_t, py::array::c_style | py::array::forcecast>& ids) {
  if (ids.ndim() != 1) throw InputError("ids must be a 1-D integer array");
  return std::vector<int64_t>(ids.data(), ids.data() + ids.shape(0));
}

py::array_t<int64_t> IdArray(const std::vector<int64_t>& ids) {
  py::array_t<int64_t> out(static_cast<py::ssize_t>(ids.size()));
  std::copy(ids.begin(), ids.end(), out.mutable_data());
  return out;
}

py::array_t<bool> BoolArray(const std::vector<bool>& values) {
  py::array_t<bool> out(static_cast<py::ssize_t>(values.size()));
  for (size_t i = 0; i < values.size(); ++i) out.mutable_data()[i] = values[i];
  return out;
}

py::array_t<double> Stack2x2(const std::vector<Eigen::Matrix2d>& mats) {
  py::array_t<double> out({static_cast<py::ssize_t>(mats.size()), py::ssize_t{2}, py::ssize_t{2}});
  double* dst = out.mutable_data();
  for (size_t i = 0; i < mats.size(); ++i)
    Eigen::Map<Eigen::Matrix<double, 2, 2, Eigen::RowMajor>>(dst + 4 * i) = mats[i];
  return out;
}

py::array_t<double> StackRows2(const std::vector<Eigen::Vector2d>& rows) {
  py::array_t<double> out({static_cast<py::ssize_t>(rows.size()), py::ssize_t{2}});
  double* dst = out.mutable_data();
  for (size_t i = 0; i < rows.size(); ++i) Eigen::Map<Eigen::Vector2d>(dst + 2 * i) = rows[i];
  return out;
}

std::unique_ptr<SogBank> MakeBank(const SogOptions& options, const DoubleArray& means,
                                  const DoubleArray& covariances, const DoubleArray& weights,
                                  const std::pair<int, int>& image_size,
                                  const DoubleArray& pixel_size) {
  // Counts of work per frame: refused when absurd, before a frame takes hours.
  if (options.update_iterations < 1 || options.update_iterations > 100)
    throw InputError("SogOptions.update_iterations must be 1..100, got " +
                     std::to_string(options.update_iterations));
  if (options.ransac_hypotheses < 0 || options.ransac_hypotheses > 100000)
    throw InputError("SogOptions.ransac_hypotheses must be 0..100000, got " +
                     std::to_string(options.ransac_hypotheses));
  if (means.ndim() != 2 || means.shape(1) != 5)
    throw InputError("initial_means must have shape (N, 5)");
  const py::ssize_t n = means.shape(0);
  if (covariances.ndim() != 3 || covariances.shape(0) != n || covariances.shape(1) != 5 ||
      covariances.shape(2) != 5)
    throw InputError("initial_covs must have shape (N, 5, 5)");
  if (weights.ndim() != 1 || weights.shape(0) != n)
    throw InputError("initial_weights must have shape (N,)");
  Eigen::Vector2d pixel;
  if (pixel_size.size() == 1) pixel.setConstant(pixel_size.data()[0]);
  else if (pixel_size.size() == 2) pixel << pixel_size.data()[0], pixel_size.data()[1];
  else throw InputError("pixel_size_mm must be a number or (dx, dy)");
  std::vector<Vector5d> m(n);
  std::vector<Matrix5d> c(n);
  std::vector<double> w(weights.data(), weights.data() + n);
  for (py::ssize_t i = 0; i < n; ++i) {
    m[i] = Eigen::Map<const Vector5d>(means.data() + 5 * i);
    c[i] =
        Eigen::Map<const Eigen::Matrix<double, 5, 5, Eigen::RowMajor>>(covariances.data() + 25 * i);
  }
  return std::make_unique<SogBank>(options, m, c, w, image_size.first, image_size.second, pixel);
}

py::array_t<double> FeaturePoints(const SogBank& bank, int gaussian) {
  const sog::SelfCalibrationEkf& f = bank.filter(gaussian < 0 ? bank.leading_gaussian() : gaussian);
  const auto& map = bank.map();
  py::array_t<double> out({static_cast<py::ssize_t>(map.size()), py::ssize_t{3}});
  double* dst = out.mutable_data();
  for (int k = 0; k < map.size(); ++k) {
    const auto& feature = map[k];
    Eigen::Vector3d xyz;
    if (feature.kind == sog::FeatureKind::kXyz) xyz = f.mean().segment<3>(feature.offset);
    else xyz = sog::InverseDepthToXyz(f.mean().segment<6>(feature.offset));
    Eigen::Map<Eigen::Vector3d>(dst + 3 * k) = xyz;
  }
  return out;
}

}  // namespace

void BindSog(py::module_& m) {
  py::class_<SogOptions>(m, "SogOptions", R"doc(
Options of the SOG self-calibration bank (docs/sog.md §9). SI units; pixels in px.)doc")
      .def(py::init<>())
      .def_readwrite("pixel_sigma", &SogOptions::pixel_sigma, "measurement noise std (px)")
      .def_property(
          "accel_sigma", [](const SogOptions& o) { return o.process.accel_sigma; },
          [](SogOptions& o, double v) { o.process.accel_sigma = v; },
          "linear acceleration noise std (m/s^2) of the constant-velocity model")
      .def_property(
          "angular_accel_sigma", [](const SogOptions& o) { return o.process.angular_accel_sigma; },
          [](SogOptions& o, double v) { o.process.angular_accel_sigma = v; },
          "angular acceleration noise std (rad/s^2)")
      .def_property(
          "calibration_random_walk",
          [](const SogOptions& o) { return Vector5d(o.process.calibration_random_walk); },
          [](SogOptions& o, const Vector5d& v) { o.process.calibration_random_walk = v; },
          "per-sqrt(s) random walk of (f, Cx, Cy, k1, k2); zeros = static calibration")
      .def_readwrite("initial_velocity_sigma", &SogOptions::initial_velocity_sigma, "m/s")
      .def_readwrite("initial_angular_velocity_sigma", &SogOptions::initial_angular_velocity_sigma,
                     "rad/s")
      .def_readwrite("initial_inverse_depth", &SogOptions::initial_inverse_depth,
                     "rho0 of new features (1/m)")
      .def_readwrite("initial_inverse_depth_sigma", &SogOptions::initial_inverse_depth_sigma,
                     "(1/m)")
      .def_readwrite("linearity_threshold", &SogOptions::linearity_threshold,
                     "inverse depth -> XYZ below this linearity index (<= 0: never)")
      .def_readwrite("deletion_min_predictions", &SogOptions::deletion_min_predictions)
      .def_readwrite("deletion_min_match_ratio", &SogOptions::deletion_min_match_ratio)
      .def_readwrite("max_features", &SogOptions::max_features,
                     "map cap: features matched longest ago are deleted beyond it (<= 0: no cap)")
      .def_readwrite("ransac_hypotheses", &SogOptions::ransac_hypotheses,
                     "1-point RANSAC hypotheses per frame (Civera et al. 2010; 0: off)")
      .def_readwrite("ransac_threshold_px", &SogOptions::ransac_threshold_px,
                     "1-point RANSAC: low-innovation inlier threshold (px)")
      .def_readwrite(
          "gate_chi2", &SogOptions::gate_chi2,
          "matches beyond this Mahalanobis^2 of the merged prediction are not used (<= 0: no gate)")
      .def_readwrite("visibility_min_weight", &SogOptions::visibility_min_weight)
      .def_readwrite("update_iterations", &SogOptions::update_iterations,
                     "1: EKF update; > 1: iterated EKF (relinearised at the updated mean)")
      .def_readwrite("likelihood_temperature", &SogOptions::likelihood_temperature,
                     "weights and SPRT use the innovation likelihood to the power 1/T (T >= 1)")
      .def_readwrite("unpredicted_log_likelihood", &SogOptions::unpredicted_log_likelihood)
      .def_readwrite("prune", &SogOptions::prune)
      .def_readwrite("sprt_alpha", &SogOptions::sprt_alpha, "type I error of the SPRT")
      .def_readwrite("sprt_beta", &SogOptions::sprt_beta, "type II error of the SPRT")
      .def_readwrite(
          "sprt_keep_accepted", &SogOptions::sprt_keep_accepted,
          "a Gaussian accepted by the SPRT (> A) is kept for good (else its test restarts)")
      .def_readwrite("guard_min_frames", &SogOptions::guard_min_frames)
      .def_readwrite("guard_min_rotation_deg", &SogOptions::guard_min_rotation_deg)
      .def_readwrite("guard_f_sigma_ratio", &SogOptions::guard_f_sigma_ratio)
      .def_readwrite("min_log_weight", &SogOptions::min_log_weight,
                     "while pruning, drop Gaussians with log weight below this")
      .def_readwrite(
          "merge_mahalanobis2", &SogOptions::merge_mahalanobis2,
          "while pruning, merge Gaussians whose calibrations are closer than this (<= 0: never)")
      .def_property("num_threads", &ThreadCount<SogOptions>, &SetThreadCount<SogOptions>)
      .def("__repr__", [](const SogOptions& o) {
        return "SogOptions(pixel_sigma=" + std::to_string(o.pixel_sigma) +
               ", accel_sigma=" + std::to_string(o.process.accel_sigma) +
               ", angular_accel_sigma=" + std::to_string(o.process.angular_accel_sigma) +
               ", sprt_alpha=" + std::to_string(o.sprt_alpha) +
               ", sprt_beta=" + std::to_string(o.sprt_beta) + ")";
      });

  py::class_<SogUpdateReport>(m, "SogUpdateReport", "What SogBank.update did this frame.")
      .def_property_readonly(
          "used", [](const SogUpdateReport& r) { return BoolArray(r.used); },
          "(k,) bool: matched, inside the gate and used in the update")
      .def_property_readonly(
          "gate_chi2",
          [](const SogUpdateReport& r) {
            return Eigen::VectorXd(
                Eigen::Map<const Eigen::VectorXd>(r.gate_chi2.data(), r.gate_chi2.size()));
          },
          "(k,) Mahalanobis^2 of each match w.r.t. the merged prediction (NaN if not matched)")
      .def_readonly("log_likelihoods", &SogUpdateReport::log_likelihoods)
      .def_readonly("nis", &SogUpdateReport::nis,
                    "per Gaussian: nu^T S^-1 nu (expect ~ 2 num_used)")
      .def_readonly("gaussian_ids", &SogUpdateReport::gaussian_ids)
      .def_readonly("pruned_gaussian_ids", &SogUpdateReport::pruned_gaussian_ids)
      .def_readonly("merged_gaussian_ids", &SogUpdateReport::merged_gaussian_ids)
      .def_property_readonly(
          "deleted_feature_ids",
          [](const SogUpdateReport& r) { return IdArray(r.deleted_feature_ids); })
      .def_property_readonly(
          "converted_feature_ids",
          [](const SogUpdateReport& r) { return IdArray(r.converted_feature_ids); })
      .def_readonly("num_used", &SogUpdateReport::num_used)
      .def_readonly("num_low_innovation", &SogUpdateReport::num_low_innovation,
                    "1-point RANSAC inliers (num_used without RANSAC)")
      .def_readonly("num_rescued", &SogUpdateReport::num_rescued,
                    "1-point RANSAC: matches used in the rescue update")
      .def_readonly("num_capped", &SogUpdateReport::num_capped,
                    "features deleted by the map cap (max_features)")
      .def_readonly("num_gaussians", &SogUpdateReport::num_gaussians)
      .def_readonly("pruning_active", &SogUpdateReport::pruning_active);

  py::class_<SogBank>(m, "SogBank", R"doc(
Bank of EKFs for sequential self-calibration (Civera et al. 2009; docs/sog.md).

SogBank(options, initial_means (N, 5), initial_covs (N, 5, 5), initial_weights (N,),
        image_size (width, height), pixel_size_mm)
Calibration vectors are [f, cx, cy, k1 (mm^-2), k2 (mm^-4)] (civera-radial). The world frame is
the first camera frame. Per frame: predict(dt_s); predict_measurements() for active search;
update(ids, uv, matched); add_features(uv) when the image needs more features.)doc")
      .def(py::init(&MakeBank), py::arg("options"), py::arg("initial_means"),
           py::arg("initial_covs"), py::arg("initial_weights"), py::arg("image_size"),
           py::arg("pixel_size_mm"))
      .def(
          "set_camera_state",
          [](SogBank& b, const MotionState& s, const Matrix13d& c) { b.SetCameraState(s, c); },
          py::arg("state"), py::arg("covariance"),
          "Replace [r (3), q_wc (4, w first), v (3), w (3)] and its 13x13 covariance in every "
          "filter.")
      .def(
          "predict",
          [](SogBank& b, double dt) {
            py::gil_scoped_release release;
            b.Predict(dt);
          },
          py::arg("dt_s"), "Constant-velocity prediction of every filter over dt_s seconds.")
      .def(
          "predict_measurements",
          [](SogBank& b) {
            sog::MergedPredictions p;
            {
              py::gil_scoped_release release;
              p = b.PredictMeasurements();
            }
            return py::make_tuple(IdArray(p.ids), StackRows2(p.uv), Stack2x2(p.covariance));
          },
          "-> (ids (n,), uv (n, 2), cov (n, 2, 2)): merged predicted pixels of the features "
          "visible in the image, with covariances (pixel noise included) for active search.")
      .def(
          "update",
          [](SogBank& b, const py::array_t<int64_t, py::array::c_style | py::array::forcecast>& ids,
             const DoubleArray& uv, const py::object& matched) {
            const std::vector<int64_t> id = Ids(ids);
            const std::vector<Eigen::Vector2d> z = Rows2(uv, "uv");
            std::vector<bool> mask(id.size(), true);
            if (!matched.is_none()) {
              const auto arr =
                  py::array_t<bool, py::array::c_style | py::array::forcecast>::ensure(matched);
              if (!arr || arr.ndim() != 1 || arr.shape(0) != static_cast<py::ssize_t>(id.size()))
                throw InputError("matched must be a (k,) bool array");
              for (size_t i = 0; i < id.size(); ++i) mask[i] = arr.data()[i];
            }
            py::gil_scoped_release release;
            return b.Update(id, z, mask);
          },
          py::arg("ids"), py::arg("uv"), py::arg("matched") = py::none(),
          "EKF update of every filter with the shared matches, weights, SPRT pruning, feature "
          "deletion and inverse-depth -> XYZ conversion. ids: features searched; uv (k, 2): "
          "measured pixels (ignored where not matched); matched (k,) bool (default all).")
      .def(
          "add_features",
          [](SogBank& b, const DoubleArray& uv) {
            const std::vector<Eigen::Vector2d> z = Rows2(uv, "uv");
            // Every filter keeps a dense covariance of the whole map (and builds the next one).
            const double dim = b.map().state_dim() + 6.0 * z.size();
            CheckMemory(2.0 * 8.0 * dim * dim * b.num_gaussians(),
                        "SogBank.add_features: " + std::to_string(z.size()) + " features more (" +
                            std::to_string(b.num_gaussians()) + " filters of " +
                            std::to_string(static_cast<int64_t>(dim)) + " states)");
            std::vector<int64_t> ids;
            {
              py::gil_scoped_release release;
              ids = b.AddFeatures(z);
            }
            return IdArray(ids);
          },
          py::arg("uv"), "New inverse-depth features at distorted pixels (k, 2) -> ids (k,).")
      .def(
          "remove_features",
          [](SogBank& b,
             const py::array_t<int64_t, py::array::c_style | py::array::forcecast>& ids) {
            b.RemoveFeatures(Ids(ids));
          },
          py::arg("ids"))
      .def_property_readonly(
          "options", [](const SogBank& b) { return SogOptions(b.options()); },
          "a copy (the bank's own options must not change beside an update without the GIL)")
      .def_property_readonly("image_size",
                             [](const SogBank& b) { return py::make_tuple(b.width(), b.height()); })
      .def_property_readonly("pixel_size_mm",
                             [](const SogBank& b) { return Eigen::Vector2d(b.pixel_size_mm()); })
      .def_property_readonly("num_gaussians", &SogBank::num_gaussians)
      .def_property_readonly("frame", &SogBank::frame, "number of updates so far")
      .def_property_readonly("weights", &SogBank::weights)
      .def_property_readonly("log_weights",
                             [](const SogBank& b) { return Eigen::VectorXd(b.log_weights()); })
      .def_property_readonly("gaussian_ids", &SogBank::gaussian_ids,
                             "index of each surviving Gaussian in the initial bank")
      .def_property_readonly("leading_gaussian", &SogBank::leading_gaussian)
      .def_property_readonly("pruning_active", &SogBank::pruning_active,
                             "guard released, SPRT running")
      .def_property_readonly("accumulated_rotation_rad", &SogBank::accumulated_rotation_rad)
      .def_property_readonly(
          "sprt_statistic",
          [](const SogBank& b) { return Eigen::VectorXd(b.sprt_log_statistic()); },
          "log prod L(H0)/L(H1) per Gaussian since the guard released")
      .def_property_readonly("sprt_accepted",
                             [](const SogBank& b) { return BoolArray(b.sprt_accepted()); })
      .def_property_readonly(
          "calibration_mean",
          [](const SogBank& b) {
            Vector5d mean;
            Matrix5d cov;
            b.CalibrationMoments(&mean, &cov);
            return mean;
          },
          "moment-matched [f, cx, cy, k1, k2]")
      .def_property_readonly("calibration_cov",
                             [](const SogBank& b) {
                               Vector5d mean;
                               Matrix5d cov;
                               b.CalibrationMoments(&mean, &cov);
                               return cov;
                             })
      .def(
          "calibration_bounds_99",
          [](const SogBank& b) {
            Vector5d mean;
            Matrix5d cov;
            b.CalibrationMoments(&mean, &cov);
            Eigen::Matrix<double, 5, 2> bounds;
            const Vector5d half = kZ99 * cov.diagonal().cwiseMax(0.0).cwiseSqrt();
            bounds.col(0) = mean - half;
            bounds.col(1) = mean + half;
            return bounds;
          },
          "(5, 2) [lo, hi]: mean -+ 2.576 sigma of the merged Gaussian, per parameter")
      .def_property_readonly(
          "calibration_means",
          [](const SogBank& b) {
            Eigen::Matrix<double, Eigen::Dynamic, 5, Eigen::RowMajor> out(b.num_gaussians(), 5);
            for (int i = 0; i < b.num_gaussians(); ++i)
              out.row(i) = b.filter(i).calibration().transpose();
            return out;
          },
          "(N, 5) per-filter calibration means")
      .def_property_readonly(
          "calibration_covs",
          [](const SogBank& b) {
            py::array_t<double> out(
                {static_cast<py::ssize_t>(b.num_gaussians()), py::ssize_t{5}, py::ssize_t{5}});
            for (int i = 0; i < b.num_gaussians(); ++i)
              Eigen::Map<Eigen::Matrix<double, 5, 5, Eigen::RowMajor>>(
                  out.mutable_data() + 25 * i) = b.filter(i).calibration_covariance();
            return out;
          },
          "(N, 5, 5) per-filter calibration covariances")
      .def_property_readonly(
          "camera_state",
          [](const SogBank& b) {
            MotionState mean;
            Matrix13d cov;
            b.MotionMoments(&mean, &cov);
            return mean;
          },
          "merged [r, q_wc, v, w] (13,)")
      .def_property_readonly("camera_cov",
                             [](const SogBank& b) {
                               MotionState mean;
                               Matrix13d cov;
                               b.MotionMoments(&mean, &cov);
                               return cov;
                             })
      .def(
          "state", [](const SogBank& b, int i) { return Eigen::VectorXd(b.filter(i).mean()); },
          py::arg("gaussian"),
          "full state of one filter: [f, cx, cy, k1, k2, r, q, v, w, features...]")
      .def(
          "covariance",
          [](const SogBank& b, int i) { return Eigen::MatrixXd(b.filter(i).covariance()); },
          py::arg("gaussian"))
      .def_property_readonly("num_features", [](const SogBank& b) { return b.map().size(); })
      .def_property_readonly("state_dim", [](const SogBank& b) { return b.map().state_dim(); })
      .def_property_readonly("feature_ids",
                             [](const SogBank& b) {
                               std::vector<int64_t> ids;
                               for (const auto& f : b.map().features()) ids.push_back(f.id);
                               return IdArray(ids);
                             })
      .def_property_readonly("feature_is_xyz",
                             [](const SogBank& b) {
                               std::vector<bool> xyz;
                               for (const auto& f : b.map().features())
                                 xyz.push_back(f.kind == sog::FeatureKind::kXyz);
                               return BoolArray(xyz);
                             })
      .def_property_readonly(
          "feature_offsets",
          [](const SogBank& b) {
            std::vector<int64_t> off;
            for (const auto& f : b.map().features()) off.push_back(f.offset);
            return IdArray(off);
          },
          "first state index of each feature")
      .def_property_readonly(
          "feature_match_counts",
          [](const SogBank& b) {
            Eigen::Matrix<int64_t, Eigen::Dynamic, 2, Eigen::RowMajor> out(b.map().size(), 2);
            for (int k = 0; k < b.map().size(); ++k)
              out.row(k) << b.map()[k].times_predicted, b.map()[k].times_matched;
            return out;
          },
          "(n, 2): times predicted visible (searched), times matched")
      .def("feature_points", &FeaturePoints, py::arg("gaussian") = -1,
           "(n, 3) XYZ of every map feature in one filter (default the leading one)");
}

}  // namespace rscalib::python
