#include "rscalib/camera/camera_model.hpp"

#include <cmath>

#include <Eigen/Dense>
#include <ceres/jet.h>

#include "rscalib/core/error.hpp"

namespace rscalib::camera {

CameraModelType ParseCameraModelType(const std::string& name) {
  if (name == PinholeRadtan::kName) return CameraModelType::kPinholeRadtan;
  if (name == PinholeEquidistant::kName) return CameraModelType::kPinholeEquidistant;
  if (name == CiveraRadial::kName) return CameraModelType::kCiveraRadial;
  throw InputError("unknown camera model '" + name +
                   "' (expected pinhole-radtan, pinhole-equidistant or civera-radial)");
}

std::string CameraModelName(CameraModelType type) {
  switch (type) {
    case CameraModelType::kPinholeRadtan: return PinholeRadtan::kName;
    case CameraModelType::kPinholeEquidistant: return PinholeEquidistant::kName;
    case CameraModelType::kCiveraRadial: return CiveraRadial::kName;
  }
  return "";
}

int NumCameraParams(CameraModelType type) {
  switch (type) {
    case CameraModelType::kPinholeRadtan: return PinholeRadtan::kNumParams;
    case CameraModelType::kPinholeEquidistant: return PinholeEquidistant::kNumParams;
    case CameraModelType::kCiveraRadial: return CiveraRadial::kNumParams;
  }
  return 0;
}

std::vector<std::string> CameraParamNames(CameraModelType type) {
  switch (type) {
    case CameraModelType::kPinholeRadtan:
      return {"fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3"};
    case CameraModelType::kPinholeEquidistant:
      return {"fx", "fy", "cx", "cy", "k1", "k2", "k3", "k4"};
    case CameraModelType::kCiveraRadial: return {"f", "cx", "cy", "k1", "k2"};
  }
  return {};
}

CameraModel::CameraModel(const std::string& model, const Eigen::VectorXd& params, int width,
                         int height, const Eigen::Vector2d& pixel_size_mm)
    : type_(ParseCameraModelType(model)),
      width_(width),
      height_(height),
      pixel_size_mm_(pixel_size_mm) {
  const int expected = NumCameraParams(type_);
  const int given = static_cast<int>(params.size());
  if (type_ == CameraModelType::kPinholeRadtan && (given == 4 || given == 8)) {
    params_ = Eigen::VectorXd::Zero(expected);  // missing distortion coefficients are zero
    params_.head(given) = params;
  } else if (given == expected) {
    params_ = params;
  } else {
    const std::string alternatives = type_ == CameraModelType::kPinholeRadtan ? " (or 4 or 8)" : "";
    throw InputError(model + " takes " + std::to_string(expected) + " parameters" + alternatives +
                     ", got " + std::to_string(given));
  }
  if (!params_.allFinite()) throw InputError("camera parameters (params) must be finite");
  if (width <= 0 || height <= 0 || width > kMaxImageSidePx || height > kMaxImageSidePx)
    throw InputError("image width and height must be 1 to " + std::to_string(kMaxImageSidePx) +
                     " px, not " + std::to_string(width) + " x " + std::to_string(height));
  if (type_ == CameraModelType::kCiveraRadial) {
    if (!(params_[0] > 0.0)) throw InputError("civera-radial focal length must be positive");
    if (!(pixel_size_mm_[0] > 0.0 && pixel_size_mm_[1] > 0.0))
      throw InputError("civera-radial needs a positive pixel size in mm (dx, dy)");
  } else if (!(params_[0] > 0.0 && params_[1] > 0.0)) {
    throw InputError("focal lengths fx, fy must be positive");
  }
}

bool CameraModel::Project(const Eigen::Vector3d& point_c, Eigen::Vector2d* uv) const {
  return ProjectPoint(type_, params_.data(), pixel_size_mm_.data(), point_c.data(), uv->data());
}

bool CameraModel::ProjectWithJacobians(
    const Eigen::Vector3d& point_c, Eigen::Vector2d* uv, Eigen::Matrix<double, 2, 3>* d_uv_d_point,
    Eigen::Matrix<double, 2, Eigen::Dynamic>* d_uv_d_params) const {
  using Jet = ceres::Jet<double, 3 + kMaxParams>;
  const int num_params = static_cast<int>(params_.size());
  Jet point[3], params[kMaxParams], out[2];
  for (int i = 0; i < 3; ++i) point[i] = Jet(point_c[i], i);
  for (int i = 0; i < num_params; ++i) params[i] = Jet(params_[i], 3 + i);
  if (!ProjectPoint(type_, params, pixel_size_mm_.data(), point, out)) return false;
  d_uv_d_params->resize(2, num_params);
  for (int r = 0; r < 2; ++r) {
    (*uv)[r] = out[r].a;
    d_uv_d_point->row(r) = out[r].v.head<3>().transpose();
    d_uv_d_params->row(r) = out[r].v.segment(3, num_params).transpose();
  }
  return true;
}

namespace {

// Solves PinholeRadtan::Distort(x) = target by Newton (2x2, Jacobian by Jets).
bool UndistortRadtan(const Eigen::VectorXd& params, const Eigen::Vector2d& target,
                     Eigen::Vector2d* normalised) {
  using Jet = ceres::Jet<double, 2>;
  Jet jet_params[PinholeRadtan::kNumParams];
  for (int i = 0; i < PinholeRadtan::kNumParams; ++i) jet_params[i] = Jet(params[i]);
  Eigen::Vector2d x = target;
  for (int iteration = 0; iteration < 100; ++iteration) {
    Jet xd, yd;
    PinholeRadtan::Distort(jet_params, Jet(x[0], 0), Jet(x[1], 1), &xd, &yd);
    const Eigen::Vector2d residual(xd.a - target[0], yd.a - target[1]);
    if (residual.norm() < 1e-15 * std::max(1.0, target.norm())) {
      *normalised = x;
      return true;
    }
    Eigen::Matrix2d jacobian;
    jacobian << xd.v[0], xd.v[1], yd.v[0], yd.v[1];
    const Eigen::Vector2d step = jacobian.partialPivLu().solve(residual);
    if (!step.allFinite()) return false;
    x -= step;
  }
  // Converged to rounding noise but not below the strict threshold: accept if tiny.
  double xd, yd;
  PinholeRadtan::Distort(params.data(), x[0], x[1], &xd, &yd);
  *normalised = x;
  return std::hypot(xd - target[0], yd - target[1]) < 1e-12;
}

}  // namespace

bool CameraModel::Unproject(const Eigen::Vector2d& uv, Eigen::Vector3d* ray) const {
  const Eigen::VectorXd& p = params_;
  switch (type_) {
    case CameraModelType::kPinholeRadtan: {
      const Eigen::Vector2d distorted((uv[0] - p[2]) / p[0], (uv[1] - p[3]) / p[1]);
      Eigen::Vector2d normalised;
      if (!UndistortRadtan(p, distorted, &normalised)) return false;
      *ray << normalised, 1.0;
      return true;
    }
    case CameraModelType::kPinholeEquidistant: {
      const Eigen::Vector2d distorted((uv[0] - p[2]) / p[0], (uv[1] - p[3]) / p[1]);
      const double theta_d = distorted.norm();
      if (theta_d < 1e-15) {
        *ray << distorted, 1.0;
        return true;
      }
      double theta = theta_d;
      for (int iteration = 0; iteration < 100; ++iteration) {
        const double t2 = theta * theta;
        const double g =
            theta * (1 + t2 * (p[4] + t2 * (p[5] + t2 * (p[6] + t2 * p[7])))) - theta_d;
        const double dg = 1 + t2 * (3 * p[4] + t2 * (5 * p[5] + t2 * (7 * p[6] + t2 * 9 * p[7])));
        if (!(dg > 0.0)) return false;
        theta -= g / dg;
        if (std::abs(g) < 1e-16) break;
      }
      if (!(theta >= 0.0 && theta < M_PI / 2)) return false;
      *ray << distorted * (std::tan(theta) / theta_d), 1.0;
      return true;
    }
    case CameraModelType::kCiveraRadial: {
      Eigen::Vector2d undistorted;
      CiveraRadial::Undistort(p.data(), pixel_size_mm_.data(), uv.data(), undistorted.data());
      *ray << (undistorted[0] - p[1]) / p[0], (undistorted[1] - p[2]) / p[0], 1.0;
      return true;
    }
  }
  return false;
}

}  // namespace rscalib::camera
