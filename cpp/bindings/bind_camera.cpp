// Bindings: camera models (project, Jacobians, unproject), vectorised over points.
#include <cmath>
#include <limits>
#include <optional>

#include <pybind11/eigen.h>
#include <pybind11/stl.h>

#include "bindings.hpp"
#include "rscalib/camera/camera_model.hpp"
#include "rscalib/core/error.hpp"

namespace rscalib::python {

using camera::CameraModel;
using camera::CameraModelType;

namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

// out_row = fn(in_row) for every row of a (count, In) or (In,) array -> (count, Out) or (Out,);
// rows where fn returns false are NaN. release_gil: run the loop without the GIL.
template <int In, int Out, typename Fn>
py::array_t<double> MapRows(const DoubleArray& array, const char* what, bool release_gil, Fn&& fn) {
  bool vector = false;
  const py::ssize_t count = CheckRows(array, In, what, &vector);
  py::array_t<double> out({count, py::ssize_t{Out}});
  const double* in = array.data();
  double* dst = out.mutable_data();
  {
    std::optional<py::gil_scoped_release> release;
    if (release_gil) release.emplace();
    for (py::ssize_t i = 0; i < count; ++i)
      if (!fn(in + In * i, dst + Out * i))
        for (int k = 0; k < Out; ++k) dst[Out * i + k] = kNaN;
  }
  if (vector) return out.reshape({py::ssize_t{Out}});
  return out;
}

py::array_t<double> Project(const CameraModel& cam, const DoubleArray& points) {
  return MapRows<3, 2>(points, "points", true, [&](const double* point, double* uv) {
    Eigen::Vector2d projected;
    if (!cam.Project(Eigen::Map<const Eigen::Vector3d>(point), &projected)) return false;
    Eigen::Vector2d::Map(uv) = projected;
    return true;
  });
}

py::tuple ProjectWithJacobians(const CameraModel& cam, const DoubleArray& points) {
  bool vector = false;
  const py::ssize_t count = CheckRows(points, 3, "points", &vector);
  const py::ssize_t num_params = cam.params().size();
  py::array_t<double> uv_out({count, py::ssize_t{2}});
  py::array_t<double> d_point({count, py::ssize_t{2}, py::ssize_t{3}});
  py::array_t<double> d_params({count, py::ssize_t{2}, num_params});
  const double* in = points.data();
  double* uv_dst = uv_out.mutable_data();
  double* dp_dst = d_point.mutable_data();
  double* dk_dst = d_params.mutable_data();
  {
    py::gil_scoped_release release;
    for (py::ssize_t i = 0; i < count; ++i) {
      Eigen::Vector2d uv;
      Eigen::Matrix<double, 2, 3> jp;
      Eigen::Matrix<double, 2, Eigen::Dynamic> jk;
      if (!cam.ProjectWithJacobians(Eigen::Map<const Eigen::Vector3d>(in + 3 * i), &uv, &jp, &jk)) {
        uv.setConstant(kNaN);
        jp.setConstant(kNaN);
        jk.setConstant(2, num_params, kNaN);
      }
      Eigen::Map<Eigen::Vector2d>(uv_dst + 2 * i) = uv;
      Eigen::Map<Eigen::Matrix<double, 2, 3, Eigen::RowMajor>>(dp_dst + 6 * i) = jp;
      Eigen::Map<Eigen::Matrix<double, 2, Eigen::Dynamic, Eigen::RowMajor>>(
          dk_dst + 2 * num_params * i, 2, num_params) = jk;
    }
  }
  return py::make_tuple(uv_out, d_point, d_params);
}

py::array_t<double> Unproject(const CameraModel& cam, const DoubleArray& pixels) {
  return MapRows<2, 3>(pixels, "pixels", true, [&](const double* uv, double* ray) {
    Eigen::Vector3d r;
    if (!cam.Unproject(Eigen::Map<const Eigen::Vector2d>(uv), &r)) return false;
    Eigen::Vector3d::Map(ray) = r;
    return true;
  });
}

// civera-radial only: pixel <-> pixel distortion maps.
py::array_t<double> CiveraMap(const CameraModel& cam, const DoubleArray& pixels, bool distort) {
  if (cam.type() != CameraModelType::kCiveraRadial)
    throw InputError("distort/undistort of pixels is defined for civera-radial cameras only");
  const double* params = cam.params().data();
  const double* pixel_size_mm = cam.pixel_size_mm().data();
  return MapRows<2, 2>(pixels, "pixels", false, [&](const double* in, double* out) {
    if (distort) return camera::CiveraRadial::Distort(params, pixel_size_mm, in, out);
    camera::CiveraRadial::Undistort(params, pixel_size_mm, in, out);
    return true;
  });
}

}  // namespace

void BindCamera(py::module_& m) {
  py::class_<CameraModel>(m, "CameraModel", R"doc(
A camera: model name, parameters, image size (and pixel size for civera-radial).

Models and parameter layouts (docs/conventions.md):
  pinhole-radtan       [fx, fy, cx, cy, k1, k2, p1, p2, k3]   (OpenCV; 4 or 8 values also accepted)
  pinhole-equidistant  [fx, fy, cx, cy, k1, k2, k3, k4]       (OpenCV fisheye)
  civera-radial        [f, cx, cy, k1, k2] + pixel_size_mm (dx, dy)
Points are in the camera frame (x right, y down, z forward); pixels in OpenCV's convention.
Points that cannot be projected give NaN.
)doc")
      .def(py::init<const std::string&, const Eigen::VectorXd&, int, int, const Eigen::Vector2d&>(),
           py::arg("model"), py::arg("params"), py::arg("width"), py::arg("height"),
           py::arg("pixel_size_mm") = Eigen::Vector2d::Zero())
      .def_property_readonly("model", &CameraModel::name)
      .def_property_readonly("params",
                             [](const CameraModel& c) { return Eigen::VectorXd(c.params()); })
      .def_property_readonly(
          "param_names", [](const CameraModel& c) { return camera::CameraParamNames(c.type()); })
      .def_property_readonly("width", &CameraModel::width)
      .def_property_readonly("height", &CameraModel::height)
      .def_property_readonly(
          "pixel_size_mm", [](const CameraModel& c) { return Eigen::Vector2d(c.pixel_size_mm()); })
      .def("project", &Project, py::arg("points_c"), "(n, 3) camera-frame points -> (n, 2) pixels.")
      .def("project_with_jacobians", &ProjectWithJacobians, py::arg("points_c"),
           "-> (uv (n, 2), d_uv_d_point (n, 2, 3), d_uv_d_params (n, 2, num_params)).")
      .def("unproject", &Unproject, py::arg("uv"), "(n, 2) pixels -> (n, 3) rays with z = 1.")
      .def(
          "distort",
          [](const CameraModel& c, const DoubleArray& p) { return CiveraMap(c, p, true); },
          py::arg("uv_undistorted"), "civera-radial: undistorted -> distorted pixels (Newton).")
      .def(
          "undistort",
          [](const CameraModel& c, const DoubleArray& p) { return CiveraMap(c, p, false); },
          py::arg("uv_distorted"), "civera-radial: distorted -> undistorted pixels.")
      .def(py::pickle(
          [](const CameraModel& c) {
            return py::make_tuple(c.name(), Eigen::VectorXd(c.params()), c.width(), c.height(),
                                  Eigen::Vector2d(c.pixel_size_mm()));
          },
          [](const py::tuple& s) {
            const char* cls = "CameraModel";
            return CameraModel(StateItem<std::string>(s, 5, 0, cls),
                               StateItem<Eigen::VectorXd>(s, 5, 1, cls),
                               StateItem<int>(s, 5, 2, cls), StateItem<int>(s, 5, 3, cls),
                               StateItem<Eigen::Vector2d>(s, 5, 4, cls));
          }))
      .def("__repr__", [](const CameraModel& c) {
        std::string text = "CameraModel('" + c.name() + "', [";
        for (int i = 0; i < c.params().size(); ++i)
          text += (i ? ", " : "") + std::to_string(c.params()[i]);
        return text + "], " + std::to_string(c.width()) + "x" + std::to_string(c.height()) + ")";
      });
}

}  // namespace rscalib::python
