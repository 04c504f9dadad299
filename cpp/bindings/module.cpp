// rscalib._core: the C++ core of rscalib (private; use the rscalib package).
#include <string>

#include "bindings.hpp"
#include "rscalib/core/error.hpp"

namespace rscalib::python {

py::ssize_t CheckRows(const DoubleArray& array, py::ssize_t width, const char* what,
                      bool* was_vector) {
  *was_vector = array.ndim() == 1;
  if (array.ndim() == 1 && array.shape(0) == width) return 1;
  if (array.ndim() == 2 && array.shape(1) == width) return array.shape(0);
  throw InputError(std::string(what) + " must have shape (n, " + std::to_string(width) + ") or (" +
                   std::to_string(width) + ",)");
}

}  // namespace rscalib::python

PYBIND11_MODULE(_core, m) {
  namespace py = pybind11;
  m.doc() =
      "C++ core of rscalib: B-spline trajectories, camera models, the rolling-shutter solver and "
      "the SOG filter bank.";
  m.attr("__version__") = RSCALIB_VERSION;
  py::register_exception<rscalib::InputError>(m, "InputError", PyExc_ValueError);
  rscalib::python::BindSpline(m);
  rscalib::python::BindGeometry(m);
  rscalib::python::BindCamera(m);
  rscalib::python::BindRs(m);
  rscalib::python::BindRsLinear(m);
  rscalib::python::BindSog(m);
}
