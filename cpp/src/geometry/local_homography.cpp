#include "rscalib/geometry/local_homography.hpp"

#include <cmath>
#include <limits>
#include <string>

#include <Eigen/Eigenvalues>
#include <Eigen/LU>

#include "rscalib/core/error.hpp"

namespace rscalib::geometry {

namespace {

constexpr int kInverseIterations = 3;

// Up to kMaxNeighbours neighbours live on the stack: this runs for every point of every detected
// frame (54 points in 3.3 us each with heap-sized matrices and a GEMM for D^T D, 0.2 ms a frame).
constexpr int kMaxNeighbours = 16;
using Points = Eigen::Matrix<double, Eigen::Dynamic, 2, 0, kMaxNeighbours, 2>;

// Points centred on their mean and scaled to unit rms distance; returns mean and scale.
void Normalise(const Points& points, Points* normalised, Eigen::RowVector2d* mean, double* scale) {
  *mean = points.colwise().mean();
  *normalised = points.rowwise() - *mean;
  *scale = std::sqrt(normalised->rowwise().squaredNorm().mean()) + 1e-300;
  *normalised /= *scale;
}

// D^T D of the DLT's design matrix (two rows per correspondence: [x 0 -u x], [0 x -v x], x
// homogeneous), summed correspondence by correspondence.
Eigen::Matrix<double, 9, 9> NormalMatrix(const Points& x_n, const Points& u_n) {
  Eigen::Matrix<double, 9, 9> normal = Eigen::Matrix<double, 9, 9>::Zero();
  for (Eigen::Index j = 0; j < x_n.rows(); ++j) {
    const Eigen::Vector3d xh(x_n(j, 0), x_n(j, 1), 1.0);
    Eigen::Matrix<double, 9, 1> row = Eigen::Matrix<double, 9, 1>::Zero();
    row.head<3>() = xh;
    row.tail<3>() = -u_n(j, 0) * xh;
    normal.noalias() += row * row.transpose();
    row.head<3>().setZero();
    row.segment<3>(3) = xh;
    row.tail<3>() = -u_n(j, 1) * xh;
    normal.noalias() += row * row.transpose();
  }
  return normal;
}

}  // namespace

Eigen::VectorXd LocalHomographyResidual(const Eigen::MatrixX2d& target_xy,
                                        const Eigen::MatrixX2d& uv,
                                        const Eigen::MatrixXi& nearest) {
  const Eigen::Index n = uv.rows();
  if (target_xy.rows() != n || nearest.rows() != n)
    throw InputError("target_xy, uv and nearest must have one row per point");
  if (nearest.size() > 0 && (nearest.minCoeff() < 0 || nearest.maxCoeff() >= n))
    throw InputError("nearest holds a row that is not a point");
  const Eigen::Index k = nearest.cols();
  const double nan = std::numeric_limits<double>::quiet_NaN();
  Eigen::VectorXd residual = Eigen::VectorXd::Constant(n, nan);
  if (k < 4) return residual;
  if (k > kMaxNeighbours)
    throw InputError("nearest has " + std::to_string(k) + " columns; at most " +
                     std::to_string(kMaxNeighbours) + " neighbours");
  Points x(k, 2), u(k, 2), x_n(k, 2), u_n(k, 2);
  for (Eigen::Index i = 0; i < n; ++i) {
    for (Eigen::Index j = 0; j < k; ++j) {
      x.row(j) = target_xy.row(nearest(i, j));
      u.row(j) = uv.row(nearest(i, j));
    }
    if (!x.allFinite() || !u.allFinite() || !uv.row(i).allFinite()) continue;
    Eigen::RowVector2d x_mean, u_mean;
    double x_scale, u_scale;
    Normalise(x, &x_n, &x_mean, &x_scale);
    Normalise(u, &u_n, &u_mean, &u_scale);
    const Eigen::Matrix<double, 9, 9> normal = NormalMatrix(x_n, u_n);
    // The null vector of D^T D: the homography with h33 = 1 (both sides are centred, so h33 is
    // far from 0), then inverse iteration with a tiny shift.
    Eigen::Matrix<double, 9, 1> h;
    h.head<8>() = normal.topLeftCorner<8, 8>().partialPivLu().solve(-normal.block<8, 1>(0, 8));
    h[8] = 1.0;
    const Eigen::Matrix<double, 9, 9> shifted =
        normal + 1e-12 * normal.trace() * Eigen::Matrix<double, 9, 9>::Identity();
    const Eigen::PartialPivLU<Eigen::Matrix<double, 9, 9>> lu(shifted);
    for (int iteration = 0; iteration < kInverseIterations; ++iteration) {
      h = lu.solve(h);
      h /= h.norm();
    }
    if (!h.allFinite()) {  // a degenerate neighbourhood: the eigenvector of the smallest eigenvalue
      const Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, 9, 9>> eigen(normal);
      h = eigen.eigenvectors().col(0);
    }
    const Eigen::Vector3d p((target_xy(i, 0) - x_mean[0]) / x_scale,
                            (target_xy(i, 1) - x_mean[1]) / x_scale, 1.0);
    const Eigen::Vector3d q(h.segment<3>(0).dot(p), h.segment<3>(3).dot(p), h.segment<3>(6).dot(p));
    const Eigen::Vector2d predicted(q[0] / q[2] * u_scale + u_mean[0],
                                    q[1] / q[2] * u_scale + u_mean[1]);
    const double step_px = (uv.row(nearest(i, 0)) - uv.row(i)).norm();
    const double value = (predicted - uv.row(i).transpose()).norm() / step_px;
    if (std::isfinite(value)) residual[i] = value;
  }
  return residual;
}

}  // namespace rscalib::geometry
