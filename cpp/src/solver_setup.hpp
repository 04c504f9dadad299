// Private to the solvers (not installed): the Ceres set-up both line-delay solvers share.
// `Options` is any options struct with the fields used below (LineDelayOptions, LinearInterpOptions).
#pragma once

#include <algorithm>
#include <memory>
#include <string>

#include <ceres/ceres.h>

namespace rscalib::detail {

// "huber" / "cauchy" with its scale in standardised units; nullptr (plain least squares) otherwise.
inline std::unique_ptr<ceres::LossFunction> MakeRobustLoss(const std::string& name, double scale) {
  if (name == "huber") return std::make_unique<ceres::HuberLoss>(scale);
  if (name == "cauchy") return std::make_unique<ceres::CauchyLoss>(scale);
  return nullptr;
}

// DogLeg on sparse normal equations (CHOLMOD when SuiteSparse is there), tolerances from `options`.
template <typename Options>
ceres::Solver::Options MakeSolverOptions(const Options& options) {
  ceres::Solver::Options solver_options;
  solver_options.trust_region_strategy_type = ceres::DOGLEG;
  solver_options.linear_solver_type = ceres::SPARSE_NORMAL_CHOLESKY;
  solver_options.sparse_linear_algebra_library_type =
      ceres::IsSparseLinearAlgebraLibraryTypeAvailable(ceres::SUITE_SPARSE) ? ceres::SUITE_SPARSE
                                                                           : ceres::EIGEN_SPARSE;
  solver_options.num_threads = std::max(1, options.num_threads);
  solver_options.max_num_iterations = options.max_iterations;
  solver_options.function_tolerance = options.function_tolerance;
  solver_options.gradient_tolerance = options.gradient_tolerance;
  solver_options.parameter_tolerance = options.parameter_tolerance;
  solver_options.minimizer_progress_to_stdout = options.verbose;
  solver_options.logging_type = options.verbose ? ceres::PER_MINIMIZER_ITERATION : ceres::SILENT;
  return solver_options;
}

}  // namespace rscalib::detail
