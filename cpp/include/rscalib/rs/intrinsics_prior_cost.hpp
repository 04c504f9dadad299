#pragma once
// Prior on the camera intrinsics for their joint refinement with the line delay
// (docs/formulation.md §14): the whitened difference from the starting calibration,
//   r = S (theta - theta_0),   S = L^{-1} on the free parameters,  Sigma_0 = L L^T,
// so sum r^2 = (theta - theta_0)^T Sigma_0^{-1} (theta - theta_0) over the free parameters.
// Rows and columns of S of parameters held fixed are zero.
//
// Parameter block:
//   intrinsics : kIntrinsicsBlockSize (9), the camera model's parameters in its layout
//                (docs/conventions.md: [fx, fy, cx, cy, k1, k2, p1, p2, k3] for pinhole-radtan),
//                zero-padded after the model's own parameters (the padding is held fixed).
#include <vector>

#include <Eigen/Core>
#include <ceres/autodiff_cost_function.h>

#include "rscalib/camera/camera_model.hpp"

namespace rscalib::rs {

constexpr int kIntrinsicsBlockSize = camera::CameraModel::kMaxParams;
using IntrinsicsVector = Eigen::Matrix<double, kIntrinsicsBlockSize, 1>;
using IntrinsicsMatrix = Eigen::Matrix<double, kIntrinsicsBlockSize, kIntrinsicsBlockSize>;

// S for the prior: `covariance` is (n, n) over the model's n parameters (units of the layout:
// px for f and c, the distortion's own units); `fixed` lists the indices held constant (their
// rows and columns of the covariance are ignored). The Cholesky factor L of the free
// sub-block gives S = L^{-1} there, zero elsewhere. Throws InputError unless the free
// sub-block is symmetric positive definite and every index is in [0, n).
IntrinsicsMatrix IntrinsicsPriorSqrtInformation(const Eigen::MatrixXd& covariance,
                                                const std::vector<int>& fixed);

struct IntrinsicsPriorCost {
  IntrinsicsPriorCost(const IntrinsicsVector& prior_mean, const IntrinsicsMatrix& sqrt_information)
      : prior_mean_(prior_mean), sqrt_information_(sqrt_information) {}

  template <typename T>
  bool operator()(const T* intrinsics, T* residual) const {
    T difference[kIntrinsicsBlockSize];
    for (int i = 0; i < kIntrinsicsBlockSize; ++i) difference[i] = intrinsics[i] - prior_mean_[i];
    for (int r = 0; r < kIntrinsicsBlockSize; ++r) {
      residual[r] = T(0.0);
      for (int c = 0; c < kIntrinsicsBlockSize; ++c)
        if (sqrt_information_(r, c) != 0.0) residual[r] += sqrt_information_(r, c) * difference[c];
    }
    return true;
  }

  static ceres::CostFunction* Create(const IntrinsicsVector& prior_mean,
                                     const IntrinsicsMatrix& sqrt_information) {
    return new ceres::AutoDiffCostFunction<IntrinsicsPriorCost, kIntrinsicsBlockSize,
                                           kIntrinsicsBlockSize>(
        new IntrinsicsPriorCost(prior_mean, sqrt_information));
  }

 private:
  IntrinsicsVector prior_mean_;
  IntrinsicsMatrix sqrt_information_;
};

}  // namespace rscalib::rs
