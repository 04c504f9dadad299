// ComputeGlobalCovariances on random linearisations against a direct dense computation: H
// assembled and inverted whole, each observation's influence from the dense inverse, the clusters
// summed directly. Covers the dense and the sparse factorisation of the poses, a 5-dimensional
// (scale gauge) pose, held poses, an anchor observation without poses and a prior on a global.
#include <random>
#include <vector>

#include <Eigen/Dense>
#include <gtest/gtest.h>

#include "rscalib/bundle/global_covariance.hpp"
#include "rscalib/core/error.hpp"

namespace rscalib::bundle {
namespace {

struct RandomProblem {
  UnknownLayout layout;
  std::vector<ObservationLinearisation> obs;
  std::vector<GlobalPrior> priors;
};

RandomProblem MakeRandomProblem(unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> normal(0.0, 1.0);
  std::uniform_int_distribution<int> keyframe_of(0, 7);
  RandomProblem p;
  p.layout.num_globals = 6;
  p.layout.pose_size = {0, 6, 5, 6, 0, 6, 6, 6};  // keyframes 0 and 4 held, 2 the scale gauge
  p.layout.num_points = 25;
  for (int i = 0; i < p.layout.num_points; ++i) {
    const int anchor = keyframe_of(rng);
    for (int view = 0; view < 5; ++view) {
      ObservationLinearisation o;
      o.point = i;
      o.keyframe = view == 0 ? anchor : keyframe_of(rng);
      if (view > 0 && o.keyframe != anchor) {
        o.pose[0] = p.layout.pose_size[anchor] > 0 ? anchor : -1;
        o.pose[1] = p.layout.pose_size[o.keyframe] > 0 ? o.keyframe : -1;
      } else {
        o.keyframe = anchor;  // seen in its anchor: no pose
      }
      o.residual = Eigen::Vector2d(normal(rng), normal(rng));
      o.weight = 0.3 + 0.7 * std::abs(normal(rng)) / (1.0 + std::abs(normal(rng)));
      o.d_r_d_globals.resize(2, 6);
      for (int r = 0; r < 2; ++r) {
        for (int c = 0; c < 6; ++c) o.d_r_d_globals(r, c) = normal(rng);
        for (int c = 0; c < 6; ++c) o.d_r_d_pose[0](r, c) = normal(rng);
        for (int c = 0; c < 6; ++c) o.d_r_d_pose[1](r, c) = normal(rng);
        for (int c = 0; c < 3; ++c) o.d_r_d_point(r, c) = normal(rng);
      }
      p.obs.push_back(o);
    }
  }
  p.priors.push_back({5, 4.0, 0.7});
  return p;
}

struct Dense {
  Eigen::MatrixXd model, by_track, two_way;
  Eigen::VectorXd step;
  double sigma = 0.0;
};

Dense DenseCovariances(const RandomProblem& p) {
  const auto& layout = p.layout;
  const int ng = layout.num_globals;
  std::vector<int> offset(layout.pose_size.size() + 1, ng);
  for (size_t k = 0; k < layout.pose_size.size(); ++k)
    offset[k + 1] = offset[k] + layout.pose_size[k];
  const int point_offset = offset.back();
  const int n = point_offset + 3 * layout.num_points;
  const int rows = 2 * static_cast<int>(p.obs.size());
  Eigen::MatrixXd jacobian = Eigen::MatrixXd::Zero(rows, n);
  Eigen::VectorXd residual(rows), weight(rows);
  for (size_t o = 0; o < p.obs.size(); ++o) {
    const auto& ob = p.obs[o];
    jacobian.block(2 * o, 0, 2, ng) = ob.d_r_d_globals;
    for (int s = 0; s < 2; ++s)
      if (ob.pose[s] >= 0)
        jacobian.block(2 * o, offset[ob.pose[s]], 2, layout.pose_size[ob.pose[s]]) +=
            ob.d_r_d_pose[s].leftCols(layout.pose_size[ob.pose[s]]);
    jacobian.block(2 * o, point_offset + 3 * ob.point, 2, 3) = ob.d_r_d_point;
    residual.segment(2 * o, 2) = ob.residual;
    weight.segment(2 * o, 2).setConstant(ob.weight);
  }
  Eigen::MatrixXd normal = jacobian.transpose() * weight.asDiagonal() * jacobian;
  for (const auto& prior : p.priors) normal(prior.global, prior.global) += prior.information;
  const Eigen::MatrixXd inverse = normal.inverse();
  Dense d;
  const double sigma2 = residual.cwiseAbs2().dot(weight) / (rows - n);
  d.sigma = std::sqrt(sigma2);
  d.model = sigma2 * inverse.topLeftCorner(ng, ng);
  Eigen::MatrixXd per_track = Eigen::MatrixXd::Zero(layout.num_points, ng);
  Eigen::MatrixXd per_keyframe = Eigen::MatrixXd::Zero(layout.pose_size.size(), ng);
  Eigen::MatrixXd per_observation = Eigen::MatrixXd::Zero(ng, ng);
  d.step = Eigen::VectorXd::Zero(ng);
  for (size_t o = 0; o < p.obs.size(); ++o) {
    const Eigen::VectorXd score =
        jacobian.middleRows(2 * o, 2).transpose() * (p.obs[o].weight * p.obs[o].residual);
    const Eigen::VectorXd influence = (inverse * score).head(ng);
    per_track.row(p.obs[o].point) += influence.transpose();
    per_keyframe.row(p.obs[o].keyframe) += influence.transpose();
    per_observation += influence * influence.transpose();
    d.step -= influence;
  }
  const auto clustered = [](const Eigen::MatrixXd& sums) {
    int count = 0;
    Eigen::MatrixXd out = Eigen::MatrixXd::Zero(sums.cols(), sums.cols());
    for (Eigen::Index c = 0; c < sums.rows(); ++c) {
      if (sums.row(c).squaredNorm() == 0.0) continue;
      out += sums.row(c).transpose() * sums.row(c);
      ++count;
    }
    return Eigen::MatrixXd(out * count / (count - 1.0));
  };
  Eigen::MatrixXd prior_part = Eigen::MatrixXd::Zero(ng, ng);
  for (const auto& prior : p.priors)
    prior_part += prior.score_variance * inverse.col(prior.global).head(ng) *
                  inverse.col(prior.global).head(ng).transpose();
  d.by_track = clustered(per_track) + prior_part;
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eigen(d.by_track + clustered(per_keyframe) -
                                                       per_observation);
  d.two_way = eigen.eigenvectors() * eigen.eigenvalues().cwiseMax(0.0).asDiagonal() *
              eigen.eigenvectors().transpose();
  return d;
}

void ExpectClose(const Eigen::MatrixXd& actual, const Eigen::MatrixXd& expected, const char* what) {
  ASSERT_EQ(actual.rows(), expected.rows()) << what;
  const double scale = expected.cwiseAbs().maxCoeff();
  EXPECT_LT((actual - expected).cwiseAbs().maxCoeff(), 1e-9 * scale) << what;
}

TEST(GlobalCovariance, MatchesADenseComputationWithDenseAndSparsePoses) {
  for (unsigned seed : {1u, 2u, 3u}) {
    const RandomProblem p = MakeRandomProblem(seed);
    const Dense expected = DenseCovariances(p);
    for (int dense_pose_limit : {6000, 0}) {  // the poses factorised densely, then sparsely
      const GlobalCovariances cov =
          ComputeGlobalCovariances(p.layout, p.obs, p.priors, dense_pose_limit);
      EXPECT_TRUE(cov.full_rank);
      ExpectClose(cov.model, expected.model, "model");
      ExpectClose(cov.by_track, expected.by_track, "by track");
      ExpectClose(cov.two_way, expected.two_way, "two-way");
      ExpectClose(cov.step, expected.step, "step");
      EXPECT_NEAR(cov.sigma_px, expected.sigma, 1e-12);
      EXPECT_EQ(cov.num_tracks, p.layout.num_points);
    }
  }
}

TEST(GlobalCovariance, RefusesInconsistentInput) {
  RandomProblem p = MakeRandomProblem(4);
  p.obs[3].point = 99;
  EXPECT_THROW(ComputeGlobalCovariances(p.layout, p.obs), InputError);
  p = MakeRandomProblem(4);
  p.priors[0].global = 6;
  EXPECT_THROW(ComputeGlobalCovariances(p.layout, p.obs, p.priors), InputError);
}

}  // namespace
}  // namespace rscalib::bundle
