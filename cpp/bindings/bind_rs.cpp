// Bindings: the rolling-shutter line-delay engine.
#include <memory>

#include <pybind11/eigen.h>
#include <pybind11/stl.h>

#include "bindings.hpp"
#include "rscalib/core/error.hpp"
#include "rscalib/rs/error_standardisation.hpp"
#include "rscalib/rs/line_delay_solver.hpp"
#include "rscalib/rs/rs_reprojection_cost.hpp"

// Options are taken by value: the solve reads its own copy without the GIL.
RSCALIB_GUARDED_CASTER(rscalib::rs::RsSolverOptions, false)
RSCALIB_GUARDED_CASTER(rscalib::rs::RsSolveSummary, false)

namespace rscalib::python {

using rs::RsObservations;
using rs::RsSolverOptions;
using rs::RsSolveSummary;

namespace {

RsObservations MakeObservations(const Eigen::VectorXd& frame_time_s, const Eigen::MatrixX2d& uv,
                                const Eigen::MatrixX3d& point_w) {
  return RsObservations{frame_time_s, uv, point_w};
}

}  // namespace

void BindRs(py::module_& m) {
  py::class_<RsSolverOptions>(m, "RsSolverOptions",
                              "Options of the line-delay solve (docs/formulation.md).")
      .def(py::init<>())
      .def_readwrite("pixel_sigma", &RsSolverOptions::pixel_sigma, "R = sigma^2 I, px")
      .def_readwrite("observation_sigma", &RsSolverOptions::observation_sigma,
                     "optional per-observation sigma (M values, px); empty: pixel_sigma for all")
      .def_readwrite("standardise_errors", &RsSolverOptions::standardise_errors)
      .def_readwrite("max_rs_gain", &RsSolverOptions::max_rs_gain)
      .def_readwrite("use_motion_prior", &RsSolverOptions::use_motion_prior)
      .def_readwrite("motion_prior_q", &RsSolverOptions::motion_prior_q, "diag(Q), 6 values")
      .def_readwrite("estimate_line_delay", &RsSolverOptions::estimate_line_delay)
      .def_readwrite("robust_loss", &RsSolverOptions::robust_loss, "none | huber | cauchy")
      .def_readwrite("robust_loss_scale", &RsSolverOptions::robust_loss_scale)
      .def_readwrite("max_iterations", &RsSolverOptions::max_iterations)
      .def_readwrite("max_outer_iterations", &RsSolverOptions::max_outer_iterations)
      .def_readwrite("function_tolerance", &RsSolverOptions::function_tolerance)
      .def_readwrite("gradient_tolerance", &RsSolverOptions::gradient_tolerance)
      .def_readwrite("parameter_tolerance", &RsSolverOptions::parameter_tolerance)
      .def_property("num_threads", &ThreadCount<RsSolverOptions>, &SetThreadCount<RsSolverOptions>)
      .def_readwrite("compute_covariance", &RsSolverOptions::compute_covariance)
      .def_readwrite("analytic_jacobian", &RsSolverOptions::analytic_jacobian,
                     "Jacobian chained through the basis weights (false: full autodiff)")
      .def_readwrite("schur_variance", &RsSolverOptions::schur_variance,
                     "sigma_d from the Schur complement (false: Ceres' covariance)")
      .def_readwrite("line_delay_score", &RsSolverOptions::line_delay_score,
                     "also each observation's score of d (summary.line_delay_score)")
      .def_readwrite("verbose", &RsSolverOptions::verbose)
      .def_readwrite("refine_intrinsics", &RsSolverOptions::refine_intrinsics,
                     "refine the camera's parameters jointly (docs/formulation.md §14)")
      .def_readwrite("intrinsics_prior_mean", &RsSolverOptions::intrinsics_prior_mean,
                     "prior mean of the camera's n parameters (its layout)")
      .def_readwrite("intrinsics_prior_covariance", &RsSolverOptions::intrinsics_prior_covariance,
                     "(n, n) prior covariance; rows of fixed parameters ignored")
      .def_readwrite("fixed_intrinsics", &RsSolverOptions::fixed_intrinsics,
                     "indices of the camera's parameters held at their starting value");

  py::class_<RsSolveSummary>(m, "RsSolveSummary")
      .def_readonly("converged", &RsSolveSummary::converged)
      .def_readonly("message", &RsSolveSummary::message)
      .def_readonly("iterations", &RsSolveSummary::iterations)
      .def_readonly("outer_iterations", &RsSolveSummary::outer_iterations)
      .def_readonly("reattached", &RsSolveSummary::reattached)
      .def_readonly("clamped_weights", &RsSolveSummary::clamped_weights)
      .def_readonly("unprojectable", &RsSolveSummary::unprojectable)
      .def_readonly("line_delay_s", &RsSolveSummary::line_delay_s)
      .def_readonly("line_delay_std_s", &RsSolveSummary::line_delay_std_s)
      .def_readonly("covariance_ok", &RsSolveSummary::covariance_ok)
      .def_readonly("line_delay_score", &RsSolveSummary::line_delay_score)
      .def_readonly("measurement_cost", &RsSolveSummary::measurement_cost)
      .def_readonly("prior_cost", &RsSolveSummary::prior_cost)
      .def_readonly("num_error_terms", &RsSolveSummary::num_error_terms)
      .def_readonly("rms_px", &RsSolveSummary::rms_px)
      .def_readonly("solve_time_s", &RsSolveSummary::solve_time_s)
      .def_readonly("covariance_time_s", &RsSolveSummary::covariance_time_s)
      .def_readonly("segment_cost", &RsSolveSummary::segment_cost)
      .def_readonly("segment_count", &RsSolveSummary::segment_count)
      .def_readonly("residual_px", &RsSolveSummary::residual_px)
      .def_readonly("image_velocity_px_s", &RsSolveSummary::image_velocity_px_s)
      .def_readonly("standardised_sq", &RsSolveSummary::standardised_sq)
      .def_readonly("observation_time_s", &RsSolveSummary::observation_time_s)
      .def_readonly("intrinsics", &RsSolveSummary::intrinsics,
                    "refined camera parameters (refine_intrinsics), else empty")
      .def_readonly("line_delay_intrinsics_covariance",
                    &RsSolveSummary::line_delay_intrinsics_covariance,
                    "(1 + n, 1 + n) covariance of [d, intrinsics] (refine_intrinsics), else empty")
      .def_readonly("intrinsics_prior_cost", &RsSolveSummary::intrinsics_prior_cost);

  m.def(
      "solve_line_delay",
      [](const Eigen::VectorXd& frame_time_s, const Eigen::MatrixX2d& uv,
         const Eigen::MatrixX3d& point_w, const camera::CameraModel& camera,
         spline::CubicBSpline& trajectory, double line_delay_s, RsSolverOptions options) {
        const RsObservations obs = MakeObservations(frame_time_s, uv, point_w);
        RsSolveSummary summary;
        {
          py::gil_scoped_release release;
          summary = rs::SolveLineDelay(obs, camera, &trajectory, &line_delay_s, options);
        }
        return summary;
      },
      py::arg("frame_time_s"), py::arg("uv"), py::arg("point_w"), py::arg("camera"),
      py::arg("trajectory"), py::arg("line_delay_s"), py::arg("options"),
      "Refines trajectory (in place) and the line delay; returns an RsSolveSummary.");

  m.def(
      "evaluate_line_delay",
      [](const Eigen::VectorXd& frame_time_s, const Eigen::MatrixX2d& uv,
         const Eigen::MatrixX3d& point_w, const camera::CameraModel& camera,
         const spline::CubicBSpline& trajectory, double line_delay_s, RsSolverOptions options) {
        const RsObservations obs = MakeObservations(frame_time_s, uv, point_w);
        py::gil_scoped_release release;
        return rs::EvaluateLineDelay(obs, camera, trajectory, line_delay_s, options);
      },
      py::arg("frame_time_s"), py::arg("uv"), py::arg("point_w"), py::arg("camera"),
      py::arg("trajectory"), py::arg("line_delay_s"), py::arg("options"),
      "Residuals and per-segment statistics at the given estimate, without solving.");

  m.def("error_noise_map", &rs::ErrorNoiseMap, py::arg("line_delay_s"),
        py::arg("image_velocity_px_s"),
        "A = I - d [[0, u_dot], [0, v_dot]] (Oth et al. 2013, eq. 15-21; docs/formulation.md §4).");

  m.def(
      "standardisation_weight",
      [](double d, const Eigen::Vector2d& velocity, double sigma, double max_gain) {
        const auto w = rs::ComputeStandardisationWeight(d, velocity, sigma, max_gain);
        return py::make_tuple(w.sqrt_information, w.clamped);
      },
      py::arg("line_delay_s"), py::arg("image_velocity_px_s"), py::arg("pixel_sigma"),
      py::arg("max_rs_gain") = 0.8, "(W, clamped) with W^T W = (A R A^T)^-1.");

  m.def(
      "evaluate_rs_cost",
      [](const spline::CubicBSpline& trajectory, int span, const camera::CameraModel& camera,
         double frame_time_s, const Eigen::Vector2d& uv, const Eigen::Vector3d& point_w,
         double line_delay_s, const Eigen::Matrix2d& sqrt_information) {
        if (trajectory.dimension() != 6) throw InputError("trajectory must be 6-D");
        if (span < 3 || span >= trajectory.num_control_points())
          throw InputError("span out of range");
        const auto basis = trajectory.PowerBasis(span);
        const rs::SpanCamera cam = rs::MakeSpanCamera(camera);
        std::unique_ptr<ceres::CostFunction> cost(
            rs::RsReprojectionCost::Create(basis, cam, frame_time_s - basis.span_start, uv.data(),
                                           point_w.data(), sqrt_information));
        const double* blocks[5];
        for (int j = 0; j < 4; ++j)
          blocks[j] = trajectory.control_points().data() + 6 * (span - 3 + j);
        blocks[4] = &line_delay_s;
        Eigen::Vector2d residual;
        Eigen::Matrix<double, 2, 6, Eigen::RowMajor> j0, j1, j2, j3;
        Eigen::Matrix<double, 2, 1> jd;
        double* jacobians[5] = {j0.data(), j1.data(), j2.data(), j3.data(), jd.data()};
        if (!cost->Evaluate(blocks, residual.data(), jacobians))
          throw InputError("the point cannot be projected at this pose");
        return py::make_tuple(residual, std::vector<Eigen::MatrixXd>{j0, j1, j2, j3, jd});
      },
      py::arg("trajectory"), py::arg("span"), py::arg("camera"), py::arg("frame_time_s"),
      py::arg("uv"), py::arg("point_w"), py::arg("line_delay_s"), py::arg("sqrt_information"),
      "Residual and autodiff Jacobians (4 x (2, 6) control points, (2, 1) line delay) of one "
      "RS reprojection cost attached to `span`.");
}

}  // namespace rscalib::python
