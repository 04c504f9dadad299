#pragma once
// A camera chosen at run time: model name + parameter vector (+ image size, and the
// pixel size for civera-radial). Templated ProjectPoint() dispatches to the model
// structs so cost functors and EKFs can use any model with double or ceres::Jet.
#include <string>
#include <vector>

#include <Eigen/Core>

#include "rscalib/camera/civera_radial.hpp"
#include "rscalib/camera/pinhole_equidistant.hpp"
#include "rscalib/camera/pinhole_radtan.hpp"

namespace rscalib::camera {

enum class CameraModelType { kPinholeRadtan, kPinholeEquidistant, kCiveraRadial };

// "pinhole-radtan" | "pinhole-equidistant" | "civera-radial"; throws InputError otherwise.
CameraModelType ParseCameraModelType(const std::string& name);
std::string CameraModelName(CameraModelType type);
int NumCameraParams(CameraModelType type);
std::vector<std::string> CameraParamNames(CameraModelType type);

template <typename T>
bool ProjectPoint(CameraModelType type, const T* params, const double* pixel_size_mm,
                  const T* point_c, T* uv) {
  switch (type) {
    case CameraModelType::kPinholeRadtan: return PinholeRadtan::Project(params, point_c, uv);
    case CameraModelType::kPinholeEquidistant:
      return PinholeEquidistant::Project(params, point_c, uv);
    case CameraModelType::kCiveraRadial:
      return CiveraRadial::Project(params, pixel_size_mm, point_c, uv);
  }
  return false;
}

class CameraModel {
 public:
  static constexpr int kMaxParams = 9;
  // An image side at most (a camera file's limit, rscalib.checks.MAX_IMAGE_SIDE_PX).
  static constexpr int kMaxImageSidePx = 100000;

  // pinhole-radtan accepts 4 (no distortion), 5, 8 or 9 values in OpenCV order
  // [fx, fy, cx, cy, k1, k2, p1, p2, k3]; missing coefficients are zero. civera-radial
  // needs pixel_size_mm (dx, dy) > 0.
  CameraModel(const std::string& model, const Eigen::VectorXd& params, int width, int height,
              const Eigen::Vector2d& pixel_size_mm = Eigen::Vector2d::Zero());

  CameraModelType type() const { return type_; }
  std::string name() const { return CameraModelName(type_); }
  const Eigen::VectorXd& params() const { return params_; }
  int width() const { return width_; }
  int height() const { return height_; }
  const Eigen::Vector2d& pixel_size_mm() const { return pixel_size_mm_; }

  // False when the point cannot be projected (behind the camera, not invertible).
  bool Project(const Eigen::Vector3d& point_c, Eigen::Vector2d* uv) const;
  // Jacobians by forward-mode autodiff (ceres::Jet); d_uv_d_params is 2 x num params.
  bool ProjectWithJacobians(const Eigen::Vector3d& point_c, Eigen::Vector2d* uv,
                            Eigen::Matrix<double, 2, 3>* d_uv_d_point,
                            Eigen::Matrix<double, 2, Eigen::Dynamic>* d_uv_d_params) const;
  // Ray (x, y, 1) in the camera frame whose projection is uv; false if none (e.g. a
  // fisheye pixel beyond 90 degrees, or the undistortion iteration did not converge).
  bool Unproject(const Eigen::Vector2d& uv, Eigen::Vector3d* ray) const;

 private:
  CameraModelType type_;
  Eigen::VectorXd params_;
  int width_;
  int height_;
  Eigen::Vector2d pixel_size_mm_;
};

}  // namespace rscalib::camera
