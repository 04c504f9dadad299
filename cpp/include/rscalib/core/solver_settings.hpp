#pragma once
// The Ceres settings every rscalib solve takes from its own options struct, written once: the
// sparse library (CHOLMOD when SuiteSparse is there) and the stop rules and logging.
#include <algorithm>

#include <ceres/ceres.h>

namespace rscalib {

// SuiteSparse (CHOLMOD) when Ceres was built with it, else Eigen's sparse Cholesky.
inline ceres::SparseLinearAlgebraLibraryType SparseLibrary() {
  return ceres::IsSparseLinearAlgebraLibraryTypeAvailable(ceres::SUITE_SPARSE)
             ? ceres::SUITE_SPARSE
             : ceres::EIGEN_SPARSE;
}

// Options: any struct with max_iterations, function_tolerance, gradient_tolerance,
// parameter_tolerance, num_threads and verbose (RsSolverOptions, LinearInterpOptions,
// BundleOptions).
template <typename Options>
void SetStopAndLogging(const Options& options, ceres::Solver::Options* solver) {
  solver->max_num_iterations = options.max_iterations;
  solver->function_tolerance = options.function_tolerance;
  solver->gradient_tolerance = options.gradient_tolerance;
  solver->parameter_tolerance = options.parameter_tolerance;
  solver->num_threads = std::max(1, options.num_threads);
  solver->minimizer_progress_to_stdout = options.verbose;
  solver->logging_type = options.verbose ? ceres::PER_MINIMIZER_ITERATION : ceres::SILENT;
}

}  // namespace rscalib
