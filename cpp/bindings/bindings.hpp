#pragma once
// One binding file per area; module.cpp calls each Bind*.
#include <string>
#include <typeinfo>

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include "rscalib/camera/camera_model.hpp"
#include "rscalib/spline/cubic_bspline.hpp"

namespace rscalib::python {

namespace py = pybind11;
using DoubleArray = py::array_t<double, py::array::c_style | py::array::forcecast>;

void BindSpline(py::module_& m);
void BindGeometry(py::module_& m);
void BindCamera(py::module_& m);
void BindRs(py::module_& m);
void BindRsLinear(py::module_& m);
void BindSog(py::module_& m);
void BindBundle(py::module_& m);

// Rows of a (count, width) or (width,) array; throws InputError on other shapes.
// Sets *was_vector when the input was 1-D so results can be returned 1-D too.
py::ssize_t CheckRows(const DoubleArray& array, py::ssize_t width, const char* what,
                      bool* was_vector);

// Item `index` of the pickled state of a `cls` object (a tuple of `size` items), as T; TypeError
// naming the class when the tuple has another size or the item another type.
template <typename T>
T StateItem(const py::tuple& state, size_t size, size_t index, const char* cls) {
  if (state.size() != size)
    throw py::type_error(std::string(cls) + " state must be a tuple of " + std::to_string(size) +
                         " items, got " + std::to_string(state.size()));
  try {
    return state[index].cast<T>();
  } catch (const py::cast_error&) {
    throw py::type_error(std::string(cls) + " state item " + std::to_string(index) +
                         " has the wrong type");
  }
}

// num_threads of the options structs: pools of that many threads are made, so absurd counts are
// refused (2**31 - 1 made Ceres throw std::bad_alloc).
constexpr int kMaxThreads = 1024;
int CheckedThreadCount(int num_threads);
template <typename Options>
int ThreadCount(const Options& options) {
  return options.num_threads;
}
template <typename Options>
void SetThreadCount(Options& options, int num_threads) {
  options.num_threads = CheckedThreadCount(num_threads);
}

// Holds the mutex of one C++ object (one mutex per object in use, recursive). If another thread
// holds it, waits with the GIL released, so the holder can finish (it may need the GIL back).
class ObjectLock {
 public:
  ObjectLock() = default;
  explicit ObjectLock(const void* object);
  ObjectLock(ObjectLock&& other) noexcept;
  ObjectLock& operator=(ObjectLock&& other) noexcept;
  ObjectLock(const ObjectLock&) = delete;
  ObjectLock& operator=(const ObjectLock&) = delete;
  ~ObjectLock();

 private:
  void Release() noexcept;
  const void* object_ = nullptr;
  void* entry_ = nullptr;
};

// Throws TypeError if `src` is an instance of the bound class `type` whose C++ object was never
// constructed (made by Cls.__new__(Cls) without __init__); pybind11 would hand it raw memory.
void RefuseUninitialised(py::handle src, const std::type_info& type);

// The caster of every bound class (RSCALIB_GUARDED_CASTER): refuses uninitialised instances and,
// for kSerialise classes, holds the object's lock from argument loading until the call returns, so
// methods that release the GIL never run beside another call on the same object. At most one
// kSerialise object may be an argument of one function (else two threads could each hold one and
// wait for the other). A class bound without it fails tests/python/core/test_bindings_safety.py.
template <typename T, bool kSerialise>
class GuardedCaster : public py::detail::type_caster_base<T> {
 public:
  bool load(py::handle src, bool convert) {
    RefuseUninitialised(src, typeid(T));
    if (!py::detail::type_caster_base<T>::load(src, convert)) return false;
    if constexpr (kSerialise) {
      if (this->value != nullptr) lock_ = ObjectLock(this->value);
    }
    return true;
  }

 private:
  ObjectLock lock_;
};

}  // namespace rscalib::python

// Use at global scope, before the class appears in any binding of the translation unit.
#define RSCALIB_GUARDED_CASTER(Type, kSerialise)                                        \
  namespace pybind11::detail {                                                          \
  template <>                                                                           \
  class type_caster<Type> : public rscalib::python::GuardedCaster<Type, kSerialise> {}; \
  }

// Immutable from Python: concurrent const calls without the GIL are safe, no lock.
RSCALIB_GUARDED_CASTER(rscalib::camera::CameraModel, false)
// insert_knot and the control_points setter mutate it; solve_line_delay refines it without the GIL.
RSCALIB_GUARDED_CASTER(rscalib::spline::CubicBSpline, true)
