// rscalib._core: the C++ core of rscalib (private; use the rscalib package).
#include <memory>
#include <mutex>
#include <string>
#include <unordered_map>
#include <utility>

#include <glog/logging.h>

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

int CheckedThreadCount(int num_threads) {
  if (num_threads < 1 || num_threads > kMaxThreads)
    throw InputError("num_threads must be 1.." + std::to_string(kMaxThreads) + ", got " +
                     std::to_string(num_threads));
  return num_threads;
}

namespace {

struct LockEntry {
  std::recursive_mutex mutex;
  int users = 0;  // ObjectLocks holding or waiting for `mutex`; the entry goes at 0
};

// Entries of the objects in use. Leaked on purpose: threads may outlive static destruction.
std::mutex& RegistryMutex() {
  static auto* mutex = new std::mutex;
  return *mutex;
}
std::unordered_map<const void*, std::unique_ptr<LockEntry>>& Registry() {
  static auto* registry = new std::unordered_map<const void*, std::unique_ptr<LockEntry>>;
  return *registry;
}

}  // namespace

ObjectLock::ObjectLock(const void* object) : object_(object) {
  LockEntry* entry = nullptr;
  {
    std::lock_guard<std::mutex> guard(RegistryMutex());
    auto& slot = Registry()[object];
    if (!slot) slot = std::make_unique<LockEntry>();
    ++slot->users;
    entry = slot.get();
  }
  if (!entry->mutex.try_lock()) {
    py::gil_scoped_release release;
    entry->mutex.lock();
  }
  entry_ = entry;
}

ObjectLock::ObjectLock(ObjectLock&& other) noexcept
    : object_(std::exchange(other.object_, nullptr)),
      entry_(std::exchange(other.entry_, nullptr)) {}

ObjectLock& ObjectLock::operator=(ObjectLock&& other) noexcept {
  if (this != &other) {
    Release();
    object_ = std::exchange(other.object_, nullptr);
    entry_ = std::exchange(other.entry_, nullptr);
  }
  return *this;
}

ObjectLock::~ObjectLock() { Release(); }

void ObjectLock::Release() noexcept {
  if (entry_ == nullptr) return;
  auto* entry = static_cast<LockEntry*>(entry_);
  entry->mutex.unlock();
  std::lock_guard<std::mutex> guard(RegistryMutex());
  if (--entry->users == 0) Registry().erase(object_);
  entry_ = nullptr;
  object_ = nullptr;
}

void RefuseUninitialised(py::handle src, const std::type_info& type) {
  const py::detail::type_info* info = py::detail::get_type_info(type);
  if (info == nullptr || !src || !PyObject_TypeCheck(src.ptr(), info->type)) return;
  auto* instance = reinterpret_cast<py::detail::instance*>(src.ptr());
  const py::detail::value_and_holder object = instance->get_value_and_holder(info, false);
  if (object.inst != nullptr && object.value_ptr() != nullptr) return;
  const std::string name = info->type->tp_name;
  throw py::type_error(name +
                       " object is not initialised (made by __new__ without __init__); "
                       "create it with " +
                       name + "(...)");
}

}  // namespace rscalib::python

PYBIND11_MODULE(_core, m) {
  namespace py = pybind11;
  m.doc() =
      "C++ core of rscalib: B-spline trajectories, camera models, the rolling-shutter solver and "
      "the SOG filter bank and the self-calibration bundle adjustment.";
  m.attr("__version__") = RSCALIB_VERSION;
  py::register_exception<rscalib::InputError>(m, "InputError", PyExc_ValueError);
  // Ceres' warnings (e.g. "Jacobian matrix is rank deficient" from a covariance the solver then
  // reports as unavailable) would reach the user's terminal as glog lines; the core reports every
  // such outcome itself. Errors still print.
  FLAGS_minloglevel = google::GLOG_ERROR;
  rscalib::python::BindSpline(m);
  rscalib::python::BindGeometry(m);
  rscalib::python::BindCamera(m);
  rscalib::python::BindRs(m);
  rscalib::python::BindRsLinear(m);
  rscalib::python::BindSog(m);
  rscalib::python::BindBundle(m);
}
