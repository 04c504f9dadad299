#pragma once
// The bundle adjustment's reprojection error of one feature observation (docs/sog.md §23):
//   r = uv_obs - (pi_theta(h) + u_dot (v_obs - v_ref) d)
// pi_theta: the camera model (camera/camera_model.hpp: civera-radial, pinhole-radtan,
// pinhole-equidistant) with its parameters theta as unknowns; h = rho x_c of the anchored point
// (anchored_point.hpp), projected like x_c; u_dot: the observation's image velocity in px/s (data,
// from its track); v_obs - v_ref: its row from the reference row; d: the rolling shutter's line
// delay. The shift is the first-order rolling-shutter model of docs/sog.md §21: row v is exposed
// (v - v_ref) d after the keyframe's time, the feature moving at u_dot meanwhile.
//
// Parameter blocks (observer != anchor):
//   intrinsics     : kNumIntrinsics, the camera model's layout (its pixel size is fixed)
//   anchor_pose    : 6, [p; phi] T_cw of the point's anchor keyframe
//   observer_pose  : 6, [p; phi] T_cw of the observing keyframe
//   point          : 3, (a, b, rho)
//   line_delay     : 1, d in microseconds per row (the scale of the other blocks' steps)
// In the anchor keyframe itself the poses drop out (h = (a, b, 1)); Ceres takes a block only once
// per residual, so that observation has the blocks (intrinsics, point, line_delay).
//
// A point that cannot be projected (h_z <= 0: behind the camera for rho > 0, or outside the
// camera model's domain) returns false: Ceres then rejects the step that took it there (no
// clamped, non-smooth residual), and SolveBundle drops observations that cannot be projected at
// the start.
#include <ceres/autodiff_cost_function.h>
#include <ceres/sized_cost_function.h>

#include "rscalib/bundle/anchored_point.hpp"
#include "rscalib/camera/camera_model.hpp"
#include "rscalib/core/error.hpp"

namespace rscalib::bundle {

constexpr double kMicroseconds = 1e-6;  // the line delay block is in µs/row

struct ReprojectionCost {
  ReprojectionCost(camera::CameraModelType model, const double* pixel_size_mm, const double* uv_px,
                   const double* image_velocity_px_s, double reference_row)
      : model_(model),
        pixel_size_mm_{pixel_size_mm[0], pixel_size_mm[1]},
        uv_px_{uv_px[0], uv_px[1]},
        shift_px_per_us_{image_velocity_px_s[0] * (uv_px[1] - reference_row) * kMicroseconds,
                         image_velocity_px_s[1] * (uv_px[1] - reference_row) * kMicroseconds} {}

  // Observed from another keyframe than the anchor.
  template <typename T>
  bool operator()(const T* intrinsics, const T* anchor_pose, const T* observer_pose, const T* point,
                  const T* line_delay_us, T* residual) const {
    T h[3];
    AnchoredPointInCamera(anchor_pose, observer_pose, point, h);
    return Residual(intrinsics, h, line_delay_us[0], residual);
  }

  // Observed in its anchor keyframe.
  template <typename T>
  bool operator()(const T* intrinsics, const T* point, const T* line_delay_us, T* residual) const {
    T h[3];
    AnchoredPointInAnchor(point, h);
    return Residual(intrinsics, h, line_delay_us[0], residual);
  }

  template <typename T>
  bool Residual(const T* intrinsics, const T* h, const T& line_delay_us, T* residual) const {
    T uv[2];
    if (!camera::ProjectPoint(model_, intrinsics, pixel_size_mm_, h, uv)) return false;
    residual[0] = uv_px_[0] - (uv[0] + shift_px_per_us_[0] * line_delay_us);
    residual[1] = uv_px_[1] - (uv[1] + shift_px_per_us_[1] * line_delay_us);
    return true;
  }

  // d r_row / d(line delay in µs/row): the residual is linear in it.
  double shift_px_per_us(int row) const { return shift_px_per_us_[row]; }

  // The cost of an observation; in_anchor: observed in the point's anchor keyframe (the blocks
  // above without the poses). From another keyframe its Jacobian is chained
  // (ChainedReprojectionCost), in the anchor it is autodiff of the functor.
  static ceres::CostFunction* Create(camera::CameraModelType model, const double* pixel_size_mm,
                                     const double* uv_px, const double* image_velocity_px_s,
                                     double reference_row, bool in_anchor) {
    auto* functor =
        new ReprojectionCost(model, pixel_size_mm, uv_px, image_velocity_px_s, reference_row);
    switch (camera::NumCameraParams(model)) {
      case 5: return Make<5>(functor, in_anchor);
      case 8: return Make<8>(functor, in_anchor);
      case 9: return Make<9>(functor, in_anchor);
    }
    delete functor;
    throw InputError("ReprojectionCost: unsupported number of camera parameters");
  }

 private:
  template <int kNumIntrinsics>
  static ceres::CostFunction* Make(ReprojectionCost* functor, bool in_anchor);

  camera::CameraModelType model_;
  double pixel_size_mm_[2];
  double uv_px_[2];
  double shift_px_per_us_[2];  // d(uv)/d(line delay in µs/row)
};

// ReprojectionCost observed from another keyframe than the anchor, with its Jacobian chained by
// hand (docs/sog.md §26): r depends on the poses and the point only through h (3), so
//   dr/d(anchor, observer, point) = dr/dh dh/d(anchor, observer, point),
// h autodiffed over its 15 parameters and the projection over h and the intrinsics (3 + K): two
// narrow Jets instead of one 21-27 wide, the same derivatives (to rounding); dr/dd = -shift.
// Parameter blocks as ReprojectionCost's: intrinsics (K), anchor_pose (6), observer_pose (6),
// point (3), line_delay (1).
template <int kNumIntrinsics>
class ChainedReprojectionCost
    : public ceres::SizedCostFunction<2, kNumIntrinsics, 6, 6, kAnchoredPointDim, 1> {
 public:
  explicit ChainedReprojectionCost(const ReprojectionCost& functor) : functor_(functor) {}

  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override {
    const double* intrinsics = parameters[0];
    const double line_delay_us = parameters[4][0];
    if (jacobians == nullptr) {
      double h[3];
      AnchoredPointInCamera(parameters[1], parameters[2], parameters[3], h);
      return functor_.Residual(intrinsics, h, line_delay_us, residuals);
    }
    using GeometryJet = ceres::Jet<double, kGeometryParams>;
    GeometryJet anchor[6], observer[6], point[kAnchoredPointDim], h[3];
    for (int i = 0; i < 6; ++i) {
      anchor[i] = GeometryJet(parameters[1][i], i);
      observer[i] = GeometryJet(parameters[2][i], 6 + i);
    }
    for (int i = 0; i < kAnchoredPointDim; ++i) point[i] = GeometryJet(parameters[3][i], 12 + i);
    AnchoredPointInCamera(anchor, observer, point, h);

    using ProjectionJet = ceres::Jet<double, 3 + kNumIntrinsics>;
    ProjectionJet theta[kNumIntrinsics], h_jet[3], r[2];
    for (int i = 0; i < 3; ++i) h_jet[i] = ProjectionJet(h[i].a, i);
    for (int k = 0; k < kNumIntrinsics; ++k) theta[k] = ProjectionJet(intrinsics[k], 3 + k);
    if (!functor_.Residual(theta, h_jet, ProjectionJet(line_delay_us), r)) return false;
    residuals[0] = r[0].a;
    residuals[1] = r[1].a;

    if (jacobians[0] != nullptr) {
      for (int row = 0; row < 2; ++row)
        for (int k = 0; k < kNumIntrinsics; ++k)
          jacobians[0][row * kNumIntrinsics + k] = r[row].v[3 + k];
    }
    constexpr int kOffset[3] = {0, 6, 12};
    constexpr int kSize[3] = {6, 6, kAnchoredPointDim};
    for (int b = 0; b < 3; ++b) {
      double* d_r_d_block = jacobians[1 + b];
      if (d_r_d_block == nullptr) continue;
      for (int row = 0; row < 2; ++row)
        for (int c = 0; c < kSize[b]; ++c)
          d_r_d_block[row * kSize[b] + c] = r[row].v[0] * h[0].v[kOffset[b] + c] +
                                            r[row].v[1] * h[1].v[kOffset[b] + c] +
                                            r[row].v[2] * h[2].v[kOffset[b] + c];
    }
    if (jacobians[4] != nullptr) {
      jacobians[4][0] = -functor_.shift_px_per_us(0);
      jacobians[4][1] = -functor_.shift_px_per_us(1);
    }
    return true;
  }

 private:
  static constexpr int kGeometryParams = 6 + 6 + kAnchoredPointDim;
  const ReprojectionCost functor_;
};

template <int kNumIntrinsics>
ceres::CostFunction* ReprojectionCost::Make(ReprojectionCost* functor, bool in_anchor) {
  if (in_anchor)
    return new ceres::AutoDiffCostFunction<ReprojectionCost, 2, kNumIntrinsics, 3, 1>(functor);
  ceres::CostFunction* chained = new ChainedReprojectionCost<kNumIntrinsics>(*functor);
  delete functor;
  return chained;
}

}  // namespace rscalib::bundle
