#include "rscalib/bundle/global_covariance.hpp"

#include <algorithm>
#include <cmath>
#include <string>
#include <unordered_map>
#include <utility>

#include <Eigen/Dense>
#include <Eigen/OrderingMethods>
#include <Eigen/SparseCholesky>

#include "rscalib/core/error.hpp"
#include "rscalib/core/memory_limit.hpp"

namespace rscalib::bundle {

namespace {

using Matrix3d = Eigen::Matrix3d;
using Matrix63 = Eigen::Matrix<double, 6, 3>;
using Matrix66 = Eigen::Matrix<double, 6, 6>;
using MatrixG3 = Eigen::Matrix<double, Eigen::Dynamic, 3, 0, kMaxGlobals, 3>;

// Pseudo-inverse of a symmetric positive semi-definite matrix, Jacobi-scaled first; directions
// with eigenvalues under `relative` times the largest are left out. Returns the rank.
template <typename Matrix>
int PseudoInverse(const Matrix& a, double relative, Eigen::MatrixXd* inverse) {
  const Eigen::Index n = a.rows();
  Eigen::VectorXd scale(n);
  for (Eigen::Index i = 0; i < n; ++i) scale[i] = a(i, i) > 0.0 ? 1.0 / std::sqrt(a(i, i)) : 0.0;
  const Eigen::MatrixXd scaled = scale.asDiagonal() * a * scale.asDiagonal();
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eigen(scaled);
  const Eigen::VectorXd& values = eigen.eigenvalues();
  const double largest = n > 0 ? values.cwiseAbs().maxCoeff() : 0.0;
  Eigen::VectorXd inverse_values = Eigen::VectorXd::Zero(n);
  int rank = 0;
  for (Eigen::Index i = 0; i < n; ++i) {
    if (values[i] > relative * largest && values[i] > 0.0) {
      inverse_values[i] = 1.0 / values[i];
      ++rank;
    }
  }
  *inverse =
      scale.asDiagonal() *
      (eigen.eigenvectors() * inverse_values.asDiagonal() * eigen.eigenvectors().transpose()) *
      scale.asDiagonal();
  return rank;
}

// Inverse of a symmetric matrix: Cholesky of its Jacobi-scaled form, else the pseudo-inverse.
bool SymmetricInverse(const Eigen::MatrixXd& a, Eigen::MatrixXd* inverse) {
  const Eigen::Index n = a.rows();
  Eigen::VectorXd scale(n);
  bool positive = true;
  for (Eigen::Index i = 0; i < n; ++i) {
    positive = positive && a(i, i) > 0.0;
    scale[i] = a(i, i) > 0.0 ? 1.0 / std::sqrt(a(i, i)) : 0.0;
  }
  if (positive) {
    const Eigen::MatrixXd scaled = scale.asDiagonal() * a * scale.asDiagonal();
    Eigen::LLT<Eigen::MatrixXd> llt(scaled);
    // a Cholesky that succeeds on a nearly singular matrix still loses every digit: refuse
    // condition numbers a double cannot hold
    if (llt.info() == Eigen::Success) {
      const Eigen::VectorXd diagonal = llt.matrixL().toDenseMatrix().diagonal();
      if (diagonal.minCoeff() > 1e-7 * diagonal.maxCoeff()) {
        *inverse =
            scale.asDiagonal() * llt.solve(Eigen::MatrixXd::Identity(n, n)) * scale.asDiagonal();
        return true;
      }
    }
  }
  return PseudoInverse(a, 1e-14, inverse) == n;
}

uint64_t PairKey(int a, int b) {
  return (static_cast<uint64_t>(static_cast<uint32_t>(a)) << 32) | static_cast<uint32_t>(b);
}

// Clustered sum: sum_c s_c s_c^T G / (G - 1) over the clusters with observations.
Eigen::MatrixXd ClusterSum(const Eigen::MatrixXd& sums, const std::vector<bool>& present,
                           int* count) {
  const Eigen::Index g = sums.cols();
  Eigen::MatrixXd out = Eigen::MatrixXd::Zero(g, g);
  int clusters = 0;
  for (Eigen::Index c = 0; c < sums.rows(); ++c) {
    if (!present[c]) continue;
    out.noalias() += sums.row(c).transpose() * sums.row(c);
    ++clusters;
  }
  *count = clusters;
  if (clusters > 1) out *= static_cast<double>(clusters) / (clusters - 1);
  return out;
}

Eigen::MatrixXd ClipPositiveSemiDefinite(const Eigen::MatrixXd& a) {
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eigen(0.5 * (a + a.transpose()));
  const Eigen::VectorXd values = eigen.eigenvalues().cwiseMax(0.0);
  return eigen.eigenvectors() * values.asDiagonal() * eigen.eigenvectors().transpose();
}

}  // namespace

GlobalCovariances ComputeGlobalCovariances(const UnknownLayout& layout,
                                           const std::vector<ObservationLinearisation>& obs,
                                           const std::vector<GlobalPrior>& priors,
                                           int dense_pose_limit) {
  const int ng = layout.num_globals;
  const int num_keyframes = static_cast<int>(layout.pose_size.size());
  if (ng < 1 || ng > kMaxGlobals)
    throw InputError("covariance: the number of globals must be 1.." + std::to_string(kMaxGlobals) +
                     ", got " + std::to_string(ng));
  std::vector<int> pose_offset(num_keyframes + 1, 0);
  for (int k = 0; k < num_keyframes; ++k) {
    const int size = layout.pose_size[k];
    if (size < 0 || size > 6) throw InputError("covariance: a pose has 0..6 tangent dimensions");
    pose_offset[k + 1] = pose_offset[k] + size;
  }
  const int np = pose_offset[num_keyframes];
  CheckMemory(8.0 * (3.0 * ng * np + 36.0 * obs.size() + 64.0 * layout.num_points),
              "the bundle adjustment's covariance");
  for (const auto& o : obs) {
    if (o.point < 0 || o.point >= layout.num_points || o.keyframe < 0 ||
        o.keyframe >= num_keyframes || o.d_r_d_globals.cols() != ng)
      throw InputError("covariance: an observation's point, keyframe or size is out of range");
    for (int s = 0; s < 2; ++s)
      if (o.pose[s] < -1 || o.pose[s] >= num_keyframes)
        throw InputError("covariance: an observation's pose index is out of range");
  }
  for (const auto& prior : priors)
    if (prior.global < 0 || prior.global >= ng)
      throw InputError("covariance: a prior's global index is out of range");

  // The observations of each point (counting sort).
  std::vector<int> start(layout.num_points + 1, 0);
  for (const auto& o : obs) ++start[o.point + 1];
  for (int i = 0; i < layout.num_points; ++i) start[i + 1] += start[i];
  std::vector<int> by_point(obs.size());
  {
    std::vector<int> fill(start.begin(), start.end() - 1);
    for (size_t j = 0; j < obs.size(); ++j) by_point[fill[obs[j].point]++] = static_cast<int>(j);
  }

  // H over [globals; poses], with the points' blocks kept apart: S = H_AA first.
  Eigen::MatrixXd s_gg = Eigen::MatrixXd::Zero(ng, ng);
  Eigen::MatrixXd s_gp = Eigen::MatrixXd::Zero(ng, np);
  std::unordered_map<uint64_t, Matrix66> s_pp;  // blocks (k, l), k <= l
  const auto pose_block = [&](int k, int l) -> Matrix66& {
    auto [it, inserted] = s_pp.try_emplace(PairKey(k, l));
    if (inserted) it->second.setZero();
    return it->second;
  };
  double weighted_sq = 0.0;
  for (const auto& o : obs) {
    const Eigen::MatrixXd jg = o.d_r_d_globals;
    s_gg.noalias() += jg.transpose() * o.weight * jg;
    weighted_sq += o.weight * o.residual.squaredNorm();
    for (int s = 0; s < 2; ++s) {
      const int k = o.pose[s];
      if (k < 0 || layout.pose_size[k] == 0) continue;
      const int tk = layout.pose_size[k];
      s_gp.middleCols(pose_offset[k], tk).noalias() +=
          jg.transpose() * o.weight * o.d_r_d_pose[s].leftCols(tk);
      for (int t = 0; t < 2; ++t) {
        const int l = o.pose[t];
        if (l < k || (l == k && t < s) || layout.pose_size[l] == 0) continue;
        pose_block(k, l).topLeftCorner(tk, layout.pose_size[l]).noalias() +=
            o.d_r_d_pose[s].leftCols(tk).transpose() * o.weight *
            o.d_r_d_pose[t].leftCols(layout.pose_size[l]);
      }
    }
  }
  for (const auto& prior : priors) s_gg(prior.global, prior.global) += prior.information;

  // Eliminate each point: S -= W C^+ W^T, W = H_{A, point}.
  std::vector<Matrix3d> point_inverse(layout.num_points, Matrix3d::Zero());
  std::vector<MatrixG3> point_wg(layout.num_points);
  std::vector<std::vector<std::pair<int, Matrix63>>> point_wp(layout.num_points);
  for (int i = 0; i < layout.num_points; ++i) {
    Matrix3d c = Matrix3d::Zero();
    MatrixG3 wg = MatrixG3::Zero(ng, 3);
    auto& wp = point_wp[i];
    const auto touched = [&](int k) -> Matrix63& {
      for (auto& entry : wp)
        if (entry.first == k) return entry.second;
      wp.emplace_back(k, Matrix63::Zero());
      return wp.back().second;
    };
    for (int j = start[i]; j < start[i + 1]; ++j) {
      const auto& o = obs[by_point[j]];
      const Eigen::Matrix<double, 2, 3> jp = o.d_r_d_point;
      c.noalias() += jp.transpose() * o.weight * jp;
      wg.noalias() += o.d_r_d_globals.transpose() * o.weight * jp;
      for (int s = 0; s < 2; ++s) {
        const int k = o.pose[s];
        if (k < 0 || layout.pose_size[k] == 0) continue;
        const int tk = layout.pose_size[k];
        touched(k).topRows(tk).noalias() +=
            o.d_r_d_pose[s].leftCols(tk).transpose() * o.weight * jp;
      }
    }
    if (start[i + 1] == start[i]) continue;
    Eigen::MatrixXd c_inverse;
    PseudoInverse(c, 1e-12, &c_inverse);
    point_inverse[i] = c_inverse;
    point_wg[i] = wg;
    const MatrixG3 wg_c = wg * point_inverse[i];
    s_gg.noalias() -= wg_c * wg.transpose();
    for (const auto& [k, wk] : wp) {
      const int tk = layout.pose_size[k];
      s_gp.middleCols(pose_offset[k], tk).noalias() -= wg_c * wk.topRows(tk).transpose();
      const Matrix63 wk_c = wk * point_inverse[i];
      for (const auto& [l, wl] : wp) {
        if (l < k) continue;
        pose_block(k, l).noalias() -= wk_c * wl.transpose();
      }
    }
  }

  GlobalCovariances out;
  int observed_points = 0;
  for (int i = 0; i < layout.num_points; ++i) observed_points += start[i + 1] > start[i] ? 1 : 0;
  out.dof = std::max(1, 2 * static_cast<int>(obs.size()) - ng - np - 3 * observed_points);
  const double sigma2 = weighted_sq / out.dof;
  out.sigma_px = std::sqrt(sigma2);

  // Eliminate the poses: Y = S_pp^-1 S_pg, M = S_gg - S_gp Y, [H^-1]_gg = M^-1.
  Eigen::MatrixXd y(np, ng);
  if (np > 0) {
    std::vector<Eigen::Triplet<double>> triplets;
    triplets.reserve(s_pp.size() * 36 * 2);
    for (const auto& [key, block] : s_pp) {
      const int k = static_cast<int>(key >> 32), l = static_cast<int>(key & 0xffffffffu);
      for (int r = 0; r < layout.pose_size[k]; ++r)
        for (int c = 0; c < layout.pose_size[l]; ++c) {
          if (k == l && c < r) continue;  // the lower triangle of a diagonal block
          triplets.emplace_back(pose_offset[l] + c, pose_offset[k] + r, block(r, c));
        }
    }
    Eigen::SparseMatrix<double> lower(np, np);
    lower.setFromTriplets(triplets.begin(), triplets.end());
    Eigen::VectorXd scale(np);
    bool positive = true;
    for (int i = 0; i < np; ++i) {
      const double d = lower.coeff(i, i);
      positive = positive && d > 0.0;
      scale[i] = d > 0.0 ? 1.0 / std::sqrt(d) : 0.0;
    }
    bool solved = false;
    // the conditioning guard of SymmetricInverse: a tiny pivot of L D L^T is a direction the data
    // barely fixes (a pose without enough points), whose solve would lose every digit
    const auto pivots_ok = [](const Eigen::VectorXd& pivots) {
      return pivots.minCoeff() > 1e-14 * pivots.maxCoeff();
    };
    const Eigen::MatrixXd rhs = scale.asDiagonal() * s_gp.transpose();
    const double density = 2.0 * lower.nonZeros() / (static_cast<double>(np) * np);
    if (positive && density > 0.05 && np <= dense_pose_limit) {
      // long tracks link most keyframes: a blocked dense Cholesky is faster than a simplicial one
      const Eigen::MatrixXd lower_dense =
          scale.asDiagonal() * Eigen::MatrixXd(lower) * scale.asDiagonal();
      Eigen::LLT<Eigen::MatrixXd, Eigen::Lower> llt(lower_dense);
      if (llt.info() == Eigen::Success && pivots_ok(llt.matrixLLT().diagonal().cwiseAbs2())) {
        y = scale.asDiagonal() * llt.solve(rhs);
        solved = y.allFinite();
      }
    } else if (positive) {
      const Eigen::SparseMatrix<double> scaled = scale.asDiagonal() * lower * scale.asDiagonal();
      Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>, Eigen::Lower, Eigen::AMDOrdering<int>>
          ldlt(scaled);
      if (ldlt.info() == Eigen::Success && pivots_ok(ldlt.vectorD())) {
        y = scale.asDiagonal() * ldlt.solve(rhs);
        solved = y.allFinite();
      }
    }
    if (!solved) {  // a pose the data does not fix: the dense pseudo-inverse
      CheckMemory(8.0 * 3.0 * np * np, "the bundle adjustment's covariance (dense poses)");
      const Eigen::MatrixXd lower_dense = Eigen::MatrixXd(lower);
      const Eigen::MatrixXd dense = lower_dense.selfadjointView<Eigen::Lower>();
      Eigen::MatrixXd dense_inverse;
      PseudoInverse(dense, 1e-14, &dense_inverse);
      y = dense_inverse * s_gp.transpose();
      out.full_rank = false;
    }
  }
  const Eigen::MatrixXd m = s_gg - s_gp * y;
  Eigen::MatrixXd z_g;
  if (!SymmetricInverse(0.5 * (m + m.transpose()), &z_g)) out.full_rank = false;
  out.inverse_normal = z_g;
  out.model = sigma2 * z_g;
  const Eigen::MatrixXd z_p = -y * z_g;  // the poses' rows of H^-1 E_g

  // Each observation's influence on the globals: (H^-1 E_g)^T J_o^T w_o r_o.
  Eigen::MatrixXd per_track = Eigen::MatrixXd::Zero(layout.num_points, ng);
  Eigen::MatrixXd per_keyframe = Eigen::MatrixXd::Zero(num_keyframes, ng);
  Eigen::MatrixXd per_observation = Eigen::MatrixXd::Zero(ng, ng);
  std::vector<bool> track_present(layout.num_points, false);
  std::vector<bool> keyframe_present(num_keyframes, false);
  Eigen::VectorXd total = Eigen::VectorXd::Zero(ng);
  for (int i = 0; i < layout.num_points; ++i) {
    if (start[i + 1] == start[i]) continue;
    // the point's rows of H^-1 E_g: -C^+ (W_g^T Z_g + sum_k W_k^T Z_k)
    Eigen::Matrix<double, 3, Eigen::Dynamic> coupling = point_wg[i].transpose() * z_g;
    for (const auto& [k, wk] : point_wp[i])
      coupling.noalias() += wk.topRows(layout.pose_size[k]).transpose() *
                            z_p.middleRows(pose_offset[k], layout.pose_size[k]);
    const Eigen::Matrix<double, 3, Eigen::Dynamic> z_point = -point_inverse[i] * coupling;
    for (int j = start[i]; j < start[i + 1]; ++j) {
      const auto& o = obs[by_point[j]];
      const Eigen::Vector2d wr = o.weight * o.residual;
      Eigen::VectorXd influence = z_g.transpose() * (o.d_r_d_globals.transpose() * wr);
      for (int s = 0; s < 2; ++s) {
        const int k = o.pose[s];
        if (k < 0 || layout.pose_size[k] == 0) continue;
        const int tk = layout.pose_size[k];
        influence.noalias() += z_p.middleRows(pose_offset[k], tk).transpose() *
                               (o.d_r_d_pose[s].leftCols(tk).transpose() * wr);
      }
      influence.noalias() += z_point.transpose() * (o.d_r_d_point.transpose() * wr);
      per_track.row(i) += influence.transpose();
      per_keyframe.row(o.keyframe) += influence.transpose();
      per_observation.noalias() += influence * influence.transpose();
      track_present[i] = true;
      keyframe_present[o.keyframe] = true;
      total += influence;
    }
  }
  out.step = -total;
  Eigen::MatrixXd prior_part = Eigen::MatrixXd::Zero(ng, ng);
  for (const auto& prior : priors) {
    const Eigen::VectorXd row = z_g.row(prior.global).transpose();
    prior_part.noalias() += prior.score_variance * row * row.transpose();
  }
  out.by_track = ClusterSum(per_track, track_present, &out.num_tracks) + prior_part;
  const Eigen::MatrixXd by_keyframe =
      ClusterSum(per_keyframe, keyframe_present, &out.num_keyframes);
  out.two_way = ClipPositiveSemiDefinite(out.by_track + by_keyframe - per_observation);
  return out;
}

}  // namespace rscalib::bundle
