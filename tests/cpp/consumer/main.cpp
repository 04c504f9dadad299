// Links rscalib::core from an installed prefix and checks two results.
#include <cmath>
#include <cstdio>

#include <rscalib/camera/camera_model.hpp>
#include <rscalib/spline/cubic_bspline.hpp>

int main() {
  auto curve = rscalib::spline::CubicBSpline::Uniform(0.0, 1.0, 4, 1);
  curve.mutable_control_points().setConstant(2.5);  // a constant spline stays constant
  const double value = curve.Evaluate(0.37)[0];
  Eigen::VectorXd params(4);
  params << 500, 500, 320, 240;
  rscalib::camera::CameraModel camera("pinhole-radtan", params, 640, 480);
  Eigen::Vector2d uv;
  const bool ok = camera.Project(Eigen::Vector3d(0.1, -0.2, 2.0), &uv);
  const bool pass = ok && std::abs(value - 2.5) < 1e-12 && std::abs(uv[0] - 345.0) < 1e-9 &&
                    std::abs(uv[1] - 190.0) < 1e-9;
  std::printf("consumer: spline %.3f, projection (%.3f, %.3f): %s\n", value, uv[0], uv[1],
              pass ? "ok" : "WRONG");
  return pass ? 0 : 1;
}
