// Bindings: cubic B-spline, spline fitting and poses of a pose spline.
#include <limits>
#include <string>

#include <pybind11/eigen.h>
#include <pybind11/stl.h>

#include "bindings.hpp"
#include "rscalib/core/error.hpp"
#include "rscalib/core/memory_limit.hpp"
#include "rscalib/spline/cubic_bspline.hpp"
#include "rscalib/spline/pose_spline.hpp"
#include "rscalib/spline/spline_fit.hpp"

namespace rscalib::python {

using spline::ControlPoints;
using spline::CubicBSpline;

namespace {

// Elements of a numpy array (before any conversion); 1 for anything else.
py::ssize_t CountOf(const py::object& values) {
  return py::isinstance<py::array>(values) ? py::reinterpret_borrow<py::array>(values).size() : 1;
}

// Evaluates at a scalar (returns (N,)) or at an array of times (returns (m, N)).
py::array_t<double> Evaluate(const CubicBSpline& curve, const py::object& t, int derivative) {
  const bool scalar = py::isinstance<py::float_>(t) || py::isinstance<py::int_>(t);
  // the result's size from the array as given, before converting it (a broadcast array is a copy)
  CheckMemory(8.0 * static_cast<double>(CountOf(t)) * (curve.dimension() + 1),
              "evaluate at " + std::to_string(CountOf(t)) + " times (t)");
  DoubleArray times = DoubleArray::ensure(t);
  if (!times) throw InputError("t must be a number or an array of numbers");
  const py::ssize_t count = times.size();
  if (count > std::numeric_limits<int>::max()) throw InputError("t: too many times to evaluate");
  py::array_t<double> out({count, static_cast<py::ssize_t>(curve.dimension())});
  const double* in = times.data();
  double* dst = out.mutable_data();
  {
    py::gil_scoped_release release;
    curve.EvaluateMany(in, static_cast<int>(count), derivative, dst);
  }
  if (scalar) return out.reshape({static_cast<py::ssize_t>(curve.dimension())});
  return out;
}

}  // namespace

void BindSpline(py::module_& m) {
  py::class_<CubicBSpline>(m, "BSpline", R"doc(
Non-uniform cubic (order 4) B-spline x(t) in R^N with clamped ends.

knots: n + 4 non-decreasing values with 4 equal knots at each end; control_points: (n, N).
Segment s is [breakpoints[s], breakpoints[s+1]); span = segment + 3 in the knot vector.
)doc")
      .def(py::init([](const std::vector<double>& knots, const ControlPoints& control_points) {
             return CubicBSpline(knots, control_points);
           }),
           py::arg("knots"), py::arg("control_points"))
      .def_static("uniform", &CubicBSpline::Uniform, py::arg("t_begin"), py::arg("t_end"),
                  py::arg("num_segments"), py::arg("dimension"),
                  "Uniform segments on [t_begin, t_end], control points zero.")
      .def_static("clamped_knots", &CubicBSpline::ClampedKnots, py::arg("breakpoints"),
                  "Clamped knot vector from strictly increasing breakpoints.")
      .def_property_readonly("dimension", &CubicBSpline::dimension)
      .def_property_readonly("num_control_points", &CubicBSpline::num_control_points)
      .def_property_readonly("num_segments", &CubicBSpline::num_segments)
      .def_property_readonly("t_begin", &CubicBSpline::t_begin)
      .def_property_readonly("t_end", &CubicBSpline::t_end)
      .def_property_readonly("knots",
                             [](const CubicBSpline& s) {
                               return py::array_t<double>(
                                   static_cast<py::ssize_t>(s.knots().size()), s.knots().data());
                             })
      .def_property_readonly("breakpoints",
                             [](const CubicBSpline& s) {
                               const auto b = s.Breakpoints();
                               return py::array_t<double>(static_cast<py::ssize_t>(b.size()),
                                                          b.data());
                             })
      .def_property(
          "control_points", [](const CubicBSpline& s) { return ControlPoints(s.control_points()); },
          [](CubicBSpline& s, const ControlPoints& c) {
            if (c.rows() != s.num_control_points() || c.cols() != s.dimension())
              throw InputError(
                  "control_points must keep the shape (num_control_points, dimension)");
            s.mutable_control_points() = c;
          },
          "(n, N) control points (a copy; assign to change them).")
      .def("evaluate", &Evaluate, py::arg("t"), py::arg("derivative") = 0,
           "Value or derivative (0..3) at a time (-> (N,)) or at an array of times (-> (m, N)).")
      .def("span_at", &CubicBSpline::SpanAt, py::arg("t"))
      .def("segment_at", &CubicBSpline::SegmentAt, py::arg("t"))
      .def(
          "basis",
          [](const CubicBSpline& s, double t) {
            const int span = s.SpanAt(t);
            const spline::SpanPowerBasis basis = s.PowerBasis(span);
            double weights[3][4];
            spline::EvaluateSpanBasis(basis, t, 2, weights);
            Eigen::Matrix<double, 3, 4, Eigen::RowMajor> w;
            for (int k = 0; k < 3; ++k)
              for (int j = 0; j < 4; ++j) w(k, j) = weights[k][j];
            return py::make_tuple(span, w);
          },
          py::arg("t"),
          "(span, weights): weights[k, j] = d^k w_j/dt^k of control point span-3+j, k = 0..2.")
      .def("insert_knot", &CubicBSpline::InsertKnot, py::arg("t"),
           "Boehm knot insertion: one more control point, the curve unchanged.")
      .def("copy", [](const CubicBSpline& s) { return CubicBSpline(s); })
      .def("__copy__", [](const CubicBSpline& s) { return CubicBSpline(s); })
      .def("__deepcopy__", [](const CubicBSpline& s, py::dict) { return CubicBSpline(s); })
      .def(py::pickle(
          [](const CubicBSpline& s) {
            return py::make_tuple(s.knots(), ControlPoints(s.control_points()));
          },
          [](const py::tuple& state) {
            return CubicBSpline(StateItem<std::vector<double>>(state, 2, 0, "BSpline"),
                                StateItem<ControlPoints>(state, 2, 1, "BSpline"));
          }))
      .def("__repr__", [](const CubicBSpline& s) {
        return "BSpline(dimension=" + std::to_string(s.dimension()) +
               ", segments=" + std::to_string(s.num_segments()) + ", domain=[" +
               std::to_string(s.t_begin()) + ", " + std::to_string(s.t_end()) + "] s)";
      });

  m.def(
      "fit_bspline",
      [](const std::vector<double>& knots, const Eigen::VectorXd& times,
         const Eigen::MatrixXd& samples, const std::vector<double>& acceleration_weight,
         const std::vector<double>& sample_weight) {
        spline::SplineFitOptions options;
        options.acceleration_weight = acceleration_weight;
        options.sample_weight = sample_weight;
        py::gil_scoped_release release;
        return spline::FitCubicBSpline(knots, times, samples, options);
      },
      py::arg("knots"), py::arg("times"), py::arg("samples"),
      py::arg("acceleration_weight") = std::vector<double>{},
      py::arg("sample_weight") = std::vector<double>{},
      R"doc(Least-squares cubic B-spline through (times, samples (m, N)) on the given knots:
min sum_s w_s |x(t_s) - y_s|^2 + sum_d lambda_d * integral (x_d'')^2 dt.
acceleration_weight: [] (none), [lambda] or one lambda per dimension.)doc");

  m.def(
      "poses_at",
      [](const CubicBSpline& pose_spline, const py::object& times_in) {
        spline::CheckPoseSpline(pose_spline);
        // R (9), p (3), the spline's state (6) and the times (1) per time, refused before any of it
        // is allocated (a broadcast array of times is copied when converted)
        CheckMemory(8.0 * 19.0 * static_cast<double>(CountOf(times_in)),
                    "poses_at: " + std::to_string(CountOf(times_in)) + " times");
        const DoubleArray times = DoubleArray::ensure(times_in);
        if (!times) throw InputError("times must be an array of numbers");
        const py::ssize_t count = times.size();
        if (count > std::numeric_limits<int>::max() / 6) throw InputError("times: too many times");
        py::array_t<double> rotations({count, py::ssize_t{3}, py::ssize_t{3}});
        py::array_t<double> translations({count, py::ssize_t{3}});
        std::vector<double> states(static_cast<size_t>(count) * 6);
        const double* t = times.data();
        double* r = rotations.mutable_data();
        double* p = translations.mutable_data();
        {
          py::gil_scoped_release release;
          pose_spline.EvaluateMany(t, static_cast<int>(count), 0, states.data());
          for (py::ssize_t i = 0; i < count; ++i) {
            const Eigen::Map<const Eigen::Matrix<double, 6, 1>> state(states.data() + 6 * i);
            const geometry::Pose pose = geometry::PoseFromState(state);
            Eigen::Map<Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(r + 9 * i) = pose.rotation_cw;
            Eigen::Map<Eigen::Vector3d>(p + 3 * i) = pose.translation_cw;
          }
        }
        return py::make_tuple(rotations, translations);
      },
      py::arg("pose_spline"), py::arg("times"),
      "T_cw(t) of a 6-D pose spline [p; phi] at many times: (R (m, 3, 3), p (m, 3)), "
      "x_c = R x_w + p.");
}

}  // namespace rscalib::python
