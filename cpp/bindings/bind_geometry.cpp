// Bindings: rotation vectors.
#include <pybind11/eigen.h>

#include "bindings.hpp"
#include "rscalib/geometry/rotation.hpp"

namespace rscalib::python {

void BindGeometry(py::module_& m) {
  m.def("unwrap_rotation_vectors", &geometry::UnwrapRotationVectors, py::arg("rotation_vectors"),
        "Paper eq. 22: make a (n, 3) sequence of rotation vectors continuous (2*pi per axis).");
  m.def(
      "rotation_vector_to_matrix",
      [](const Eigen::Vector3d& phi) { return geometry::RotationVectorToMatrix(phi.data()); },
      py::arg("rotation_vector"));
  m.def("rotation_matrix_to_vector", &geometry::RotationMatrixToVector, py::arg("rotation"));
}

}  // namespace rscalib::python
