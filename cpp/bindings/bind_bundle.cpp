// Bindings: the self-calibration bundle adjustment (docs/sog.md §23). NumPy arrays in, a
// BundleResult out; the solve runs without the GIL.
#include <limits>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <pybind11/eigen.h>
#include <pybind11/stl.h>

#include "bindings.hpp"
#include "rscalib/bundle/bundle_problem.hpp"
#include "rscalib/core/error.hpp"

// Options are taken by value: the solve reads its own copy without the GIL.
RSCALIB_GUARDED_CASTER(rscalib::bundle::BundleOptions, false)
RSCALIB_GUARDED_CASTER(rscalib::bundle::BundleResult, false)

namespace rscalib::python {

using bundle::BundleData;
using bundle::BundleOptions;
using bundle::BundleResult;

namespace {

// A (count, width) float array as a row-major Eigen matrix; InputError on another shape.
template <int Width>
Eigen::Matrix<double, Eigen::Dynamic, Width, Width == 1 ? Eigen::ColMajor : Eigen::RowMajor> Rows(
    const DoubleArray& array, const char* what) {
  bool vector = false;
  const py::ssize_t count = CheckRows(array, Width, what, &vector);
  Eigen::Matrix<double, Eigen::Dynamic, Width, Width == 1 ? Eigen::ColMajor : Eigen::RowMajor> out(
      count, Width);
  std::copy(array.data(), array.data() + count * Width, out.data());
  return out;
}

// A 1-D integer array (any integer dtype) as Eigen::VectorXi; InputError otherwise.
Eigen::VectorXi Indices(const py::array& array, const char* what) {
  const char kind = array.dtype().kind();
  if ((kind != 'i' && kind != 'u') || array.ndim() != 1)
    throw InputError(std::string(what) + " must be a 1-D array of integers");
  const auto values =
      py::array_t<int64_t, py::array::c_style | py::array::forcecast>::ensure(array);
  Eigen::VectorXi out(values.shape(0));
  for (py::ssize_t i = 0; i < values.shape(0); ++i) {
    const int64_t v = values.data()[i];
    if (v < std::numeric_limits<int>::min() || v > std::numeric_limits<int>::max())
      throw InputError(std::string(what) + "[" + std::to_string(i) + "] = " + std::to_string(v) +
                       " is out of range");
    out[i] = static_cast<int>(v);
  }
  return out;
}

BundleResult Solve(const camera::CameraModel& camera, const DoubleArray& keyframe_poses,
                   const py::array& observation_keyframe, const py::array& observation_point,
                   const DoubleArray& uv_px, const DoubleArray& image_velocity_px_s,
                   const py::array& point_anchor, const DoubleArray& points,
                   const std::optional<std::vector<bool>>& free_intrinsics, double line_delay_s,
                   bool estimate_line_delay,
                   const std::optional<std::pair<double, double>>& line_delay_prior,
                   double reference_row, BundleOptions options) {
  BundleData data;
  data.keyframe_poses = Rows<6>(keyframe_poses, "keyframe_poses");
  data.observations.keyframe = Indices(observation_keyframe, "observation_keyframe");
  data.observations.point = Indices(observation_point, "observation_point");
  data.observations.uv_px = Rows<2>(uv_px, "uv_px");
  data.observations.image_velocity_px_s = Rows<2>(image_velocity_px_s, "image_velocity_px_s");
  data.point_anchor = Indices(point_anchor, "point_anchor");
  data.points = Rows<3>(points, "points");
  if (free_intrinsics) {
    data.free_intrinsics.resize(static_cast<Eigen::Index>(free_intrinsics->size()));
    for (size_t i = 0; i < free_intrinsics->size(); ++i)
      data.free_intrinsics[static_cast<Eigen::Index>(i)] = (*free_intrinsics)[i];
  }
  data.line_delay.value_s = line_delay_s;
  if (line_delay_prior) {
    data.line_delay.mode = bundle::LineDelayMode::kPrior;
    data.line_delay.prior_mean_s = line_delay_prior->first;
    data.line_delay.prior_sigma_s = line_delay_prior->second;
  } else if (estimate_line_delay) {
    data.line_delay.mode = bundle::LineDelayMode::kEstimated;
  }
  data.reference_row = reference_row;
  py::gil_scoped_release release;
  return bundle::SolveBundle(camera, data, options);
}

}  // namespace

void BindBundle(py::module_& m) {
  py::class_<BundleOptions>(m, "BundleOptions",
                            "Options of the self-calibration bundle adjustment (docs/sog.md §23).")
      .def(py::init<>())
      .def_readwrite("robust_loss", &BundleOptions::robust_loss,
                     "none | huber | cauchy | soft_l1 (Ceres' losses of |r|^2 per observation)")
      .def_readwrite("robust_loss_scale_px", &BundleOptions::robust_loss_scale_px,
                     "where the loss leaves its quadratic part, px")
      .def_readwrite("max_iterations", &BundleOptions::max_iterations)
      .def_readwrite("function_tolerance", &BundleOptions::function_tolerance)
      .def_readwrite("gradient_tolerance", &BundleOptions::gradient_tolerance)
      .def_readwrite("parameter_tolerance", &BundleOptions::parameter_tolerance)
      .def_property("num_threads", &ThreadCount<BundleOptions>, &SetThreadCount<BundleOptions>)
      .def_readwrite("linear_solver", &BundleOptions::linear_solver,
                     "sparse_schur (SuiteSparse) | dense_schur | iterative_schur")
      .def_readwrite("near_limit", &BundleOptions::near_limit,
                     "a point stays farther from its anchor than near_limit x the median start "
                     "depth (<= 0: no bound)")
      .def_readwrite("beyond_infinity_limit", &BundleOptions::beyond_infinity_limit,
                     "rho >= -beyond_infinity_limit x the median start rho (< 0: no bound)")
      .def_readwrite("free_points_first", &BundleOptions::free_points_first,
                     "solve with the points free first; points ending outside the bounds are "
                     "dropped while few, else solved again with Ceres' bounds")
      .def_readwrite("max_out_of_range_share", &BundleOptions::max_out_of_range_share,
                     "the share of the points a free solve may drop for leaving the bounds")
      .def_readwrite("scale_keyframe", &BundleOptions::scale_keyframe,
                     "the keyframe whose distance from the first is held; -1: the farthest")
      .def_readwrite("prior_pixel_sigma_px", &BundleOptions::prior_pixel_sigma_px,
                     "the pixel noise a line-delay prior is weighed against, px")
      .def_readwrite("max_free_iterations", &BundleOptions::max_free_iterations,
                     "the free solve's iterations at most (0: no cap of its own); then on bounded")
      .def_readwrite("compute_covariance", &BundleOptions::compute_covariance)
      .def_readwrite("verbose", &BundleOptions::verbose, "Ceres' iteration log to stdout");

  py::class_<BundleResult>(m, "BundleResult",
                           "The adjusted camera, line delay, poses and points; Ceres' summary; the "
                           "covariances of the globals (camera parameters, then the line delay in "
                           "s/row; zero rows where held).")
      .def_readonly("camera_params", &BundleResult::camera_params)
      .def_readonly("line_delay_s", &BundleResult::line_delay_s)
      .def_readonly("keyframe_poses", &BundleResult::keyframe_poses, "(K, 6) [p; phi] T_cw")
      .def_readonly("points", &BundleResult::points, "(P, 3) (a, b, rho) in their anchors")
      .def_readonly("residuals_px", &BundleResult::residuals_px,
                    "(N, 2) uv - prediction; NaN where not used")
      .def_readonly("used", &BundleResult::used, "(N) false: dropped at the start")
      .def_readonly("inlier", &BundleResult::inlier, "(N) |r| <= the loss scale")
      .def_readonly("dropped_observations", &BundleResult::dropped_observations)
      .def_readonly("dropped_points", &BundleResult::dropped_points)
      .def_readonly("scale_keyframe", &BundleResult::scale_keyframe)
      .def_readonly("points_beyond_infinity", &BundleResult::points_beyond_infinity)
      .def_readonly("points_at_bounds", &BundleResult::points_at_bounds,
                    "points whose rho ended at a bound (near_limit, beyond_infinity_limit)")
      .def_readonly("points_out_of_range", &BundleResult::points_out_of_range,
                    "points dropped for ending outside the bounds in the free solve")
      .def_readonly("solved_with_bounds", &BundleResult::solved_with_bounds,
                    "Ceres' bounds gave the result (too many points left the range)")
      .def_readonly("termination", &BundleResult::termination)
      .def_readonly("converged", &BundleResult::converged)
      .def_readonly("iterations", &BundleResult::iterations)
      .def_readonly("initial_cost", &BundleResult::initial_cost)
      .def_readonly("final_cost", &BundleResult::final_cost)
      .def_readonly("message", &BundleResult::message)
      .def_readonly("solve_time_s", &BundleResult::solve_time_s)
      .def_readonly("covariance_time_s", &BundleResult::covariance_time_s)
      .def_readonly("sigma_px", &BundleResult::sigma_px)
      .def_readonly("rms_px", &BundleResult::rms_px)
      .def_readonly("dof", &BundleResult::dof)
      .def_readonly("covariance_ok", &BundleResult::covariance_ok)
      .def_readonly("covariance_model", &BundleResult::covariance_model)
      .def_readonly("covariance_tracks", &BundleResult::covariance_tracks)
      .def_readonly("covariance_two_way", &BundleResult::covariance_two_way)
      .def_readonly("remaining_step", &BundleResult::remaining_step)
      .def_readonly("step_sigma", &BundleResult::step_sigma);

  m.def("solve_bundle", &Solve, py::arg("camera"), py::arg("keyframe_poses"),
        py::arg("observation_keyframe"), py::arg("observation_point"), py::arg("uv_px"),
        py::arg("image_velocity_px_s"), py::arg("point_anchor"), py::arg("points"),
        py::arg("free_intrinsics") = py::none(), py::arg("line_delay_s") = 0.0,
        py::arg("estimate_line_delay") = false, py::arg("line_delay_prior") = py::none(),
        py::arg("reference_row") = 0.0, py::arg_v("options", BundleOptions(), "BundleOptions()"),
        "The self-calibration bundle adjustment (docs/sog.md §23): keyframe_poses (K, 6) [p; phi] "
        "T_cw; per observation its keyframe, point, uv_px (N, 2) and image_velocity_px_s (N, 2); "
        "per point its anchor keyframe and (a, b, rho) (P, 3). free_intrinsics: per camera "
        "parameter (None: all). The line delay (s/row) is held at line_delay_s, estimated from "
        "it (estimate_line_delay), or estimated with a Gaussian prior (mean_s, sigma_s). "
        "reference_row: v_ref of the rolling-shutter shift. Returns a BundleResult.");
}

}  // namespace rscalib::python
