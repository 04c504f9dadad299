#include "solver_common.hpp"

#include <iostream>
#include <memory>
#include <optional>
#include <unordered_map>
#include <utility>
#include <vector>

#include <Eigen/SparseCholesky>
#include <Eigen/SparseCore>

#include "rscalib/core/error.hpp"
#include "rscalib/core/parallel_ranges.hpp"
#include "rscalib/rs/error_standardisation.hpp"

namespace rscalib::rs::detail {

namespace {

using Clock = std::chrono::steady_clock;

double Seconds(Clock::time_point since) {
  return std::chrono::duration<double>(Clock::now() - since).count();
}

// "huber" / "cauchy" with its scale in standardised units; nullptr (plain least squares)
// otherwise.
std::unique_ptr<ceres::LossFunction> MakeRobustLoss(const std::string& name, double scale) {
  if (name == "huber") return std::make_unique<ceres::HuberLoss>(scale);
  if (name == "cauchy") return std::make_unique<ceres::CauchyLoss>(scale);
  return nullptr;
}

// J^T J (num_cols square) of the residual blocks without their loss, columns of each parameter
// block from first_column; an empty matrix when a block cannot be evaluated. Plain least squares
// without manifolds (SchurVariance checks): each block's cost function is evaluated directly, so
// num_threads threads can share the blocks. The products are placed in one triplet list in block
// order whatever the thread count, flushed into the sum every kTripletsPerFlush (bounded memory on
// long videos) at the same blocks: the same matrix to the bit for every thread count.
Eigen::SparseMatrix<double> NormalMatrix(const ceres::Problem& problem,
                                         const std::vector<ceres::ResidualBlockId>& residual_blocks,
                                         const std::unordered_map<const double*, int>& first_column,
                                         int num_cols, int num_threads) {
  using RowMajor = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
  constexpr size_t kTripletsPerFlush = size_t{1} << 22;
  Eigen::SparseMatrix<double> h(num_cols, num_cols);
  // Each block's width (its parameters' columns): where its width^2 triplets go.
  const size_t num_blocks = residual_blocks.size();
  std::vector<size_t> width(num_blocks, 0);
  {
    std::vector<double*> parameters;
    for (size_t k = 0; k < num_blocks; ++k) {
      problem.GetParameterBlocksForResidualBlock(residual_blocks[k], &parameters);
      for (double* block : parameters) width[k] += problem.ParameterBlockSize(block);
    }
  }
  std::vector<Eigen::Triplet<double>> triplets;
  std::vector<char> failed(num_blocks, 0);
  size_t begin = 0;
  while (begin < num_blocks) {
    // A round: the blocks up to the one whose triplets reach the flush size (as one pass would).
    size_t end = begin, count = 0;
    std::vector<size_t> offset;
    while (end < num_blocks && count < kTripletsPerFlush) {
      offset.push_back(count);
      count += width[end] * width[end];
      ++end;
    }
    triplets.resize(count);
    ParallelRanges(end - begin, num_threads, 64, [&](size_t first, size_t last) {
      std::vector<double*> parameters;
      std::vector<RowMajor> jacobians;
      std::vector<double*> jacobian_ptrs;
      std::vector<double> residuals;
      std::vector<int> columns;
      RowMajor stacked, jtj;
      for (size_t k = begin + first; k < begin + last; ++k) {
        const ceres::ResidualBlockId id = residual_blocks[k];
        problem.GetParameterBlocksForResidualBlock(id, &parameters);
        const ceres::CostFunction* cost = problem.GetCostFunctionForResidualBlock(id);
        const int rows = cost->num_residuals();
        jacobians.resize(parameters.size());
        jacobian_ptrs.resize(parameters.size());
        columns.clear();
        for (size_t b = 0; b < parameters.size(); ++b) {
          const int size = problem.ParameterBlockSize(parameters[b]);
          jacobians[b].resize(rows, size);
          jacobian_ptrs[b] = jacobians[b].data();
          const int first_col = first_column.at(parameters[b]);
          for (int c = 0; c < size; ++c) columns.push_back(first_col + c);
        }
        residuals.resize(rows);
        if (!cost->Evaluate(parameters.data(), residuals.data(), jacobian_ptrs.data())) {
          failed[k] = 1;
          continue;
        }
        const int cols = static_cast<int>(columns.size());
        stacked.resize(rows, cols);
        for (size_t b = 0, col = 0; b < parameters.size(); col += jacobians[b].cols(), ++b)
          stacked.middleCols(static_cast<Eigen::Index>(col), jacobians[b].cols()) = jacobians[b];
        jtj.noalias() = stacked.transpose() * stacked;
        Eigen::Triplet<double>* out = triplets.data() + offset[k - begin];
        for (int i = 0; i < cols; ++i)
          for (int j = 0; j < cols; ++j) *out++ = {columns[i], columns[j], jtj(i, j)};
      }
    });
    for (size_t k = begin; k < end; ++k)
      if (failed[k]) return {};
    Eigen::SparseMatrix<double> part(num_cols, num_cols);
    part.setFromTriplets(triplets.begin(), triplets.end());
    h += part;
    begin = end;
  }
  return h;
}

// Variance of the 1-D parameter block `parameter` of `problem` at its current value (Ceres'
// Covariance, sparse QR: it copes with the gauge freedoms of a trajectory). nullopt when
// Ceres cannot compute it or the result is not a finite non-negative number.
std::optional<double> ScalarVariance(ceres::Problem* problem, const double* parameter,
                                     int num_threads) {
  ceres::Covariance::Options covariance_options;
  covariance_options.num_threads = std::max(1, num_threads);
  covariance_options.algorithm_type = ceres::SPARSE_QR;
  ceres::Covariance covariance(covariance_options);
  const std::vector<std::pair<const double*, const double*>> blocks = {{parameter, parameter}};
  if (!covariance.Compute(blocks, problem)) return std::nullopt;
  double variance = 0.0;
  covariance.GetCovarianceBlock(parameter, parameter, &variance);
  if (!(variance >= 0.0) || !std::isfinite(variance)) return std::nullopt;
  return variance;
}

// Covariance of [d, blocks...] (ambient sizes, in order): Ceres' Covariance, sparse QR.
// nullopt when Ceres cannot compute it or it is not finite.
std::optional<Eigen::MatrixXd> JointCovariance(
    ceres::Problem* problem, const double* line_delay,
    const std::vector<std::pair<const double*, int>>& blocks, int num_threads) {
  ceres::Covariance::Options covariance_options;
  covariance_options.num_threads = std::max(1, num_threads);
  covariance_options.algorithm_type = ceres::SPARSE_QR;
  ceres::Covariance covariance(covariance_options);
  std::vector<const double*> all = {line_delay};
  std::vector<int> sizes = {1};
  for (const auto& [block, size] : blocks) {
    all.push_back(block);
    sizes.push_back(size);
  }
  std::vector<std::pair<const double*, const double*>> pairs;
  for (size_t i = 0; i < all.size(); ++i)
    for (size_t j = i; j < all.size(); ++j) pairs.emplace_back(all[i], all[j]);
  if (!covariance.Compute(pairs, problem)) return std::nullopt;
  int total = 0;
  for (int size : sizes) total += size;
  Eigen::MatrixXd out(total, total);
  int row = 0;
  for (size_t i = 0; i < all.size(); ++i) {
    int col = row;
    for (size_t j = i; j < all.size(); ++j) {
      Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> block(sizes[i],
                                                                                   sizes[j]);
      covariance.GetCovarianceBlock(all[i], all[j], block.data());
      out.block(row, col, sizes[i], sizes[j]) = block;
      out.block(col, row, sizes[j], sizes[i]) = block.transpose();
      col += sizes[j];
    }
    row += sizes[i];
  }
  if (!out.allFinite() || !(out(0, 0) >= 0.0)) return std::nullopt;
  return out;
}

}  // namespace

std::optional<double> SchurVariance(
    ceres::Problem* problem, double* line_delay, int num_threads,
    const std::unordered_map<ceres::ResidualBlockId, std::vector<int>>* block_observations,
    int num_observations, Eigen::MatrixX2d* score) {
  // Columns: d first, then the other blocks in the problem's order.
  std::vector<double*> all_blocks;
  problem->GetParameterBlocks(&all_blocks);
  std::vector<double*> blocks = {line_delay};
  int num_cols = 1;
  for (double* block : all_blocks) {
    if (block == line_delay) continue;
    if (problem->IsParameterBlockConstant(block)) return std::nullopt;
    blocks.push_back(block);
    num_cols += problem->ParameterBlockTangentSize(block);
  }
  if (problem->ParameterBlockTangentSize(line_delay) != 1) return std::nullopt;
  std::vector<ceres::ResidualBlockId> residual_blocks;
  problem->GetResidualBlocks(&residual_blocks);

  // H = J^T J from each residual block's own Jacobian (a few dense blocks): cheaper than
  // Ceres' CRS Jacobian and a sparse-sparse product, and the whole Jacobian is never held.
  using SparseMatrix = Eigen::SparseMatrix<double>;
  std::unordered_map<const double*, int> first_column;
  {
    int column = 0;
    for (double* block : blocks) {
      if (problem->ParameterBlockSize(block) != problem->ParameterBlockTangentSize(block))
        return std::nullopt;  // a manifold: Ceres' covariance handles it
      first_column[block] = column;
      column += problem->ParameterBlockSize(block);
    }
  }
  SparseMatrix h = NormalMatrix(*problem, residual_blocks, first_column, num_cols, num_threads);
  if (h.rows() != num_cols) return std::nullopt;
  ceres::Problem::EvaluateOptions evaluate_options;
  evaluate_options.parameter_blocks = blocks;
  evaluate_options.num_threads = std::max(1, num_threads);
  constexpr size_t kChunk = 16384;

  const Eigen::Index n = num_cols - 1;
  const double h_dd = h.coeff(0, 0);
  const SparseMatrix h_cc = h.block(1, 1, n, n);
  const Eigen::VectorXd h_cd = Eigen::VectorXd(h.col(0)).tail(n);
  const Eigen::VectorXd diagonal = h_cc.diagonal();
  if (!(h_dd > 0.0) || !(diagonal.array() > 0.0).all() || !h.coeffs().allFinite())
    return std::nullopt;
  // Jacobi scaling: metres, radians and s/row differ by orders of magnitude.
  const Eigen::VectorXd scale = diagonal.cwiseSqrt().cwiseInverse();
  const SparseMatrix scaled = scale.asDiagonal() * h_cc * scale.asDiagonal();
  const Eigen::SimplicialLDLT<SparseMatrix> ldlt(scaled);
  if (ldlt.info() != Eigen::Success) return std::nullopt;
  const Eigen::VectorXd pivots = ldlt.vectorD();
  if (!(pivots.minCoeff() > 1e-14 * pivots.maxCoeff())) return std::nullopt;
  const Eigen::VectorXd scaled_h_cd = scale.cwiseProduct(h_cd);
  const double schur = h_dd - scaled_h_cd.dot(ldlt.solve(scaled_h_cd));
  // Not determined (or lost to rounding): let the rank-revealing path decide.
  if (!(schur > 1e-14 * h_dd) || !std::isfinite(schur)) return std::nullopt;
  if (block_observations != nullptr && score != nullptr) {
    // g = H^{-1} e_d = [1; -H_cc^{-1} h_cd] / schur; a second pass over the Jacobian (chunked
    // as above, so memory stays bounded) gives each row's (J_i g) r_i.
    Eigen::VectorXd g(num_cols);
    g(0) = 1.0;
    g.tail(n) = -scale.cwiseProduct(ldlt.solve(scaled_h_cd));
    g /= schur;
    score->setZero(num_observations, 2);
    for (size_t begin = 0; begin < residual_blocks.size(); begin += kChunk) {
      const size_t end = std::min(residual_blocks.size(), begin + kChunk);
      evaluate_options.residual_blocks.assign(residual_blocks.begin() + begin,
                                              residual_blocks.begin() + end);
      std::vector<double> residuals;
      ceres::CRSMatrix jacobian;
      if (!problem->Evaluate(evaluate_options, nullptr, &residuals, nullptr, &jacobian)) {
        score->resize(0, 2);
        break;
      }
      const Eigen::Map<const Eigen::SparseMatrix<double, Eigen::RowMajor>> j(
          jacobian.num_rows, jacobian.num_cols, static_cast<Eigen::Index>(jacobian.values.size()),
          jacobian.rows.data(), jacobian.cols.data(), jacobian.values.data());
      const Eigen::VectorXd influence = j * g;
      int row = 0;
      for (size_t b = begin; b < end; ++b) {
        const int rows =
            problem->GetCostFunctionForResidualBlock(residual_blocks[b])->num_residuals();
        const auto found = block_observations->find(residual_blocks[b]);
        if (found != block_observations->end()) {
          for (size_t k = 0; k < found->second.size() && 2 * static_cast<int>(k) + 1 < rows; ++k) {
            const int obs = found->second[k];
            if (obs < 0 || obs >= num_observations) continue;
            for (int c = 0; c < 2; ++c)
              (*score)(obs, c) += influence(row + 2 * k + c) * residuals[row + 2 * k + c];
          }
        }
        row += rows;
      }
    }
  }
  return 1.0 / schur;
}

void ValidateNoiseOptions(double pixel_sigma, double max_rs_gain) {
  if (!(pixel_sigma > 0.0)) throw InputError("pixel_sigma must be positive");
  if (!(max_rs_gain > 0.0 && max_rs_gain < 1.0)) throw InputError("max_rs_gain must be in (0, 1)");
}

void ValidateRobustLoss(const std::string& robust_loss) {
  if (robust_loss != "none" && robust_loss != "huber" && robust_loss != "cauchy")
    throw InputError("robust_loss must be none, huber or cauchy");
}

void SetWeightedError(const Eigen::Vector2d& measured_uv, const Eigen::Vector2d& predicted_uv,
                      const Eigen::Vector2d& image_velocity_px_s, double line_delay_s,
                      bool standardise_errors, double pixel_sigma, double max_rs_gain,
                      WeightedError* error) {
  error->ok = std::isfinite(predicted_uv[0]) && std::isfinite(predicted_uv[1]);
  if (!error->ok) return;
  error->residual_px = measured_uv - predicted_uv;
  error->image_velocity_px_s = image_velocity_px_s;
  if (standardise_errors) {
    const StandardisationWeight w =
        ComputeStandardisationWeight(line_delay_s, image_velocity_px_s, pixel_sigma, max_rs_gain);
    error->sqrt_information = w.sqrt_information;
    error->clamped = w.clamped;
  } else {
    error->sqrt_information = Eigen::Matrix2d::Identity() / pixel_sigma;
  }
}

SolveResult SolveWithCovariance(const SolveSettings& settings, double* line_delay_s,
                                Clock::time_point started, const Relinearise& relinearise,
                                const AddResiduals& add_residuals) {
  const std::unique_ptr<ceres::LossFunction> loss =
      MakeRobustLoss(settings.robust_loss, settings.robust_loss_scale);

  SolveResult result;
  std::unique_ptr<ceres::Problem> problem;
  double d_at_build = std::numeric_limits<double>::quiet_NaN();
  for (int outer = 0; outer < std::max(1, settings.max_outer_iterations); ++outer) {
    const bool changed = relinearise();
    const bool d_settled =
        !settings.wait_for_line_delay ||
        std::abs(*line_delay_s - d_at_build) <= 1e-3 * std::max(std::abs(*line_delay_s), 1e-9);
    if (outer > 0 && !changed && d_settled) break;
    d_at_build = *line_delay_s;

    ceres::Problem::Options problem_options;
    problem_options.loss_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
    problem = std::make_unique<ceres::Problem>(problem_options);
    problem->AddParameterBlock(line_delay_s, 1);
    add_residuals(problem.get(), loss.get());
    if (!settings.estimate_line_delay) problem->SetParameterBlockConstant(line_delay_s);

    if (settings.solver.max_num_iterations <= 0) {  // evaluation / covariance only
      result.converged = true;
      result.message = "not solved (max_iterations = 0)";
      result.outer_iterations = outer + 1;
      break;
    }
    ceres::Solver::Summary ceres_summary;
    ceres::Solve(settings.solver, problem.get(), &ceres_summary);
    if (settings.solver.minimizer_progress_to_stdout)
      std::cerr << ceres_summary.FullReport() << "\n";
    result.iterations += static_cast<int>(ceres_summary.iterations.size());
    result.outer_iterations = outer + 1;
    result.converged = ceres_summary.termination_type == ceres::CONVERGENCE;
    result.message = ceres_summary.message;
    if (ceres_summary.termination_type == ceres::FAILURE)
      throw InputError(settings.failure_message + ceres_summary.message);
  }
  result.solve_time_s = Seconds(started);
  result.line_delay_s = *line_delay_s;

  if (settings.compute_covariance && settings.estimate_line_delay && problem) {
    const auto covariance_started = Clock::now();
    if (!settings.joint_covariance_blocks.empty()) {
      if (const auto joint =
              JointCovariance(problem.get(), line_delay_s, settings.joint_covariance_blocks,
                              settings.num_threads)) {
        result.joint_covariance = *joint;
        result.line_delay_std_s = std::sqrt((*joint)(0, 0));
        result.covariance_ok = true;
      }
    } else {
      std::optional<double> variance;
      if (settings.schur_variance && !loss)
        variance = SchurVariance(problem.get(), line_delay_s, settings.num_threads,
                                 settings.block_observations, settings.num_observations,
                                 &result.line_delay_score);
      if (!variance) variance = ScalarVariance(problem.get(), line_delay_s, settings.num_threads);
      if (variance) {
        result.line_delay_std_s = std::sqrt(*variance);
        result.covariance_ok = true;
      }
    }
    result.covariance_time_s = Seconds(covariance_started);
  } else if (!settings.estimate_line_delay) {
    result.line_delay_std_s = 0.0;
  }
  return result;
}

}  // namespace rscalib::rs::detail
