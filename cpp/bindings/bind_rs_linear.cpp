// Bindings: the linear-interpolation baseline of the line-delay engine (Hedborg et al. 2012).
#include <pybind11/eigen.h>
#include <pybind11/stl.h>

#include "bindings.hpp"
#include "rscalib/rs/linear_interp_solver.hpp"

// Options are taken by value: the solve reads its own copy without the GIL.
RSCALIB_GUARDED_CASTER(rscalib::rs::LinearInterpOptions, false)
RSCALIB_GUARDED_CASTER(rscalib::rs::LinearInterpSummary, false)

namespace rscalib::python {

using rs::LinearInterpOptions;
using rs::LinearInterpSummary;

void BindRsLinear(py::module_& m) {
  py::class_<LinearInterpOptions>(m, "LinearInterpOptions",
                                  "Options of the linear-interpolation line-delay solve.")
      .def(py::init<>())
      .def_readwrite("pixel_sigma", &LinearInterpOptions::pixel_sigma, "R = sigma^2 I, px")
      .def_readwrite("standardise_errors", &LinearInterpOptions::standardise_errors,
                     "A R A^T weights (default False: plain error / sigma)")
      .def_readwrite("max_rs_gain", &LinearInterpOptions::max_rs_gain)
      .def_readwrite("max_frame_interval_s", &LinearInterpOptions::max_frame_interval_s,
                     "frames further apart are not interpolated between; 0: 1.5 x median")
      .def_readwrite("estimate_line_delay", &LinearInterpOptions::estimate_line_delay)
      .def_readwrite("robust_loss", &LinearInterpOptions::robust_loss, "none | huber | cauchy")
      .def_readwrite("robust_loss_scale", &LinearInterpOptions::robust_loss_scale)
      .def_readwrite("max_iterations", &LinearInterpOptions::max_iterations)
      .def_readwrite("max_outer_iterations", &LinearInterpOptions::max_outer_iterations)
      .def_readwrite("function_tolerance", &LinearInterpOptions::function_tolerance)
      .def_readwrite("gradient_tolerance", &LinearInterpOptions::gradient_tolerance)
      .def_readwrite("parameter_tolerance", &LinearInterpOptions::parameter_tolerance)
      .def_property("num_threads", &ThreadCount<LinearInterpOptions>,
                    &SetThreadCount<LinearInterpOptions>)
      .def_readwrite("compute_covariance", &LinearInterpOptions::compute_covariance)
      .def_readwrite("verbose", &LinearInterpOptions::verbose);

  py::class_<LinearInterpSummary>(m, "LinearInterpSummary")
      .def_readonly("converged", &LinearInterpSummary::converged)
      .def_readonly("message", &LinearInterpSummary::message)
      .def_readonly("iterations", &LinearInterpSummary::iterations)
      .def_readonly("outer_iterations", &LinearInterpSummary::outer_iterations)
      .def_readonly("line_delay_s", &LinearInterpSummary::line_delay_s)
      .def_readonly("line_delay_std_s", &LinearInterpSummary::line_delay_std_s)
      .def_readonly("covariance_ok", &LinearInterpSummary::covariance_ok)
      .def_readonly("measurement_cost", &LinearInterpSummary::measurement_cost)
      .def_readonly("num_error_terms", &LinearInterpSummary::num_error_terms)
      .def_readonly("rms_px", &LinearInterpSummary::rms_px)
      .def_readonly("isolated", &LinearInterpSummary::isolated)
      .def_readonly("extrapolated", &LinearInterpSummary::extrapolated)
      .def_readonly("unprojectable", &LinearInterpSummary::unprojectable)
      .def_readonly("clamped_weights", &LinearInterpSummary::clamped_weights)
      .def_readonly("num_chains", &LinearInterpSummary::num_chains)
      .def_readonly("max_frame_interval_s", &LinearInterpSummary::max_frame_interval_s)
      .def_readonly("solve_time_s", &LinearInterpSummary::solve_time_s)
      .def_readonly("covariance_time_s", &LinearInterpSummary::covariance_time_s)
      .def_readonly("pair_first", &LinearInterpSummary::pair_first)
      .def_readonly("residual_px", &LinearInterpSummary::residual_px)
      .def_readonly("image_velocity_px_s", &LinearInterpSummary::image_velocity_px_s)
      .def_readonly("standardised_sq", &LinearInterpSummary::standardised_sq)
      .def_readonly("observation_time_s", &LinearInterpSummary::observation_time_s);

  m.def(
      "solve_line_delay_linear",
      [](const Eigen::VectorXi& frame_index, const Eigen::MatrixX2d& uv,
         const Eigen::MatrixX3d& point_w, const Eigen::VectorXd& frame_time_s,
         const camera::CameraModel& camera, rs::FramePoseMatrix frame_poses, double line_delay_s,
         LinearInterpOptions options) {
        const rs::LinearInterpObservations obs{frame_index, uv, point_w};
        LinearInterpSummary summary;
        {
          py::gil_scoped_release release;
          summary = rs::SolveLineDelayLinear(obs, frame_time_s, camera, &frame_poses, &line_delay_s,
                                             options);
        }
        return py::make_tuple(summary, frame_poses);
      },
      py::arg("frame_index"), py::arg("uv"), py::arg("point_w"), py::arg("frame_time_s"),
      py::arg("camera"), py::arg("frame_poses"), py::arg("line_delay_s"), py::arg("options"),
      "Per-frame poses (F, 6) [p; phi] T_cw at the frames' row-0 times, and the line delay, "
      "with linear/SLERP interpolation between consecutive frames. Returns (summary, poses).");

  m.def("linear_interp_pose_state", &rs::LinearInterpPoseState, py::arg("pose_a"),
        py::arg("pose_b"), py::arg("s"),
        "T_cw [p; phi] at parameter s between poses a and b: centre linear, rotation SLERP.");
}

}  // namespace rscalib::python
