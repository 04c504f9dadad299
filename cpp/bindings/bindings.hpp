#pragma once
// One binding file per area; module.cpp calls each Bind*.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

namespace rscalib::python {

namespace py = pybind11;
using DoubleArray = py::array_t<double, py::array::c_style | py::array::forcecast>;

void BindSpline(py::module_& m);
void BindGeometry(py::module_& m);
void BindCamera(py::module_& m);
void BindRs(py::module_& m);
void BindRsLinear(py::module_& m);
void BindSog(py::module_& m);

// Rows of a (count, width) or (width,) array; throws InputError on other shapes.
// Sets *was_vector when the input was 1-D so results can be returned 1-D too.
py::ssize_t CheckRows(const DoubleArray& array, py::ssize_t width, const char* what,
                      bool* was_vector);

}  // namespace rscalib::python
