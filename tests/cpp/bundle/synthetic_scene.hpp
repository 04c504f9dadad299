#pragma once
// A synthetic self-calibration scene for the bundle tests: a civera-radial camera walking and
// turning in a room whose walls, floor and ceiling carry random points, seen at keyframes, with
// an optional rolling shutter (each point seen at its own row's time), pixel noise and outliers.
#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <ceres/rotation.h>

#include "rscalib/bundle/anchored_point.hpp"
#include "rscalib/bundle/bundle_problem.hpp"
#include "rscalib/camera/camera_model.hpp"
#include "rscalib/geometry/pose.hpp"

namespace rscalib::bundle::testing {

inline camera::CameraModel PaperCamera() {
  Eigen::VectorXd params(5);
  params << 194.06, 160.22, 128.87, 0.06333, 0.0139;
  return camera::CameraModel("civera-radial", params, 320, 240, Eigen::Vector2d(0.0112, 0.0112));
}

// T_cw [p; phi] of the walking, turning camera at time t (s); its path scaled by `walk` (0: only
// turning).
inline Eigen::Matrix<double, 6, 1> WalkPose(double t, double walk = 1.0) {
  // the turning rates change sign within a few seconds: a rolling shutter's shear then differs
  // between keyframes and cannot be absorbed by a deformed scene
  const Eigen::Vector3d centre =
      walk * Eigen::Vector3d(0.6 * std::sin(0.9 * t), 0.1 * std::sin(1.9 * t),
                             0.5 * std::sin(0.7 * t) - 0.2);
  const double yaw = 0.6 * std::sin(1.1 * t) + 0.2 * t, pitch = 0.2 * std::sin(1.7 * t + 0.5),
               roll = 0.1 * std::sin(2.3 * t);
  // R_wc = Ry(yaw) Rx(pitch) Rz(roll) (y down: yaw about the vertical)
  const Eigen::Matrix3d r_wc = (Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitY()) *
                                Eigen::AngleAxisd(pitch, Eigen::Vector3d::UnitX()) *
                                Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitZ()))
                                   .toRotationMatrix();
  const Eigen::Matrix3d r_cw = r_wc.transpose();
  Eigen::Matrix<double, 6, 1> pose;
  pose.head<3>() = -r_cw * centre;
  ceres::RotationMatrixToAngleAxis(ceres::ColumnMajorAdapter3x3(r_cw.data()), pose.data() + 3);
  return pose;
}

inline std::vector<Eigen::Vector3d> RoomPoints(int per_face, std::mt19937* rng) {
  const Eigen::Vector3d size(6.0, 2.7, 6.0), centre(0.0, -0.1, 0.5);
  std::uniform_real_distribution<double> uniform(-0.5, 0.5);
  std::vector<Eigen::Vector3d> points;
  for (int axis = 0; axis < 3; ++axis)
    for (double side : {-0.5, 0.5})
      for (int i = 0; i < per_face; ++i) {
        Eigen::Vector3d p;
        for (int c = 0; c < 3; ++c) p[c] = c == axis ? side * size[c] : uniform(*rng) * size[c];
        points.push_back(p + centre);
      }
  return points;
}

struct Scene {
  camera::CameraModel camera = PaperCamera();
  double line_delay_s = 0.0;
  double reference_row = 119.5;
  KeyframePoseMatrix poses;               // truth
  std::vector<Eigen::Vector3d> points_w;  // truth, those kept
  BundleData data;                        // the observations; start = truth (perturb it)
  std::vector<bool> outlier;              // per observation
};

struct SceneOptions {
  int keyframes = 30;
  double keyframe_interval_s = 0.1;
  int points_per_face = 150;
  double noise_px = 0.3;
  double outlier_fraction = 0.0;  // observations moved by up to +-15 px
  double line_delay_s = 0.0;
  int min_views = 3;
  double room_scale = 1.0;  // the room's points scaled about the world origin
  double walk = 1.0;        // the camera's path scaled (0: only turning)
  unsigned seed = 1;
};

// Distorted pixel of world point x at pose `pose`; false when not visible.
inline bool ProjectWorld(const camera::CameraModel& cam, const Eigen::Matrix<double, 6, 1>& pose,
                         const Eigen::Vector3d& x, Eigen::Vector2d* uv) {
  Eigen::Vector3d xc;
  geometry::TransformWorldToCamera(pose.data(), x.data(), xc.data());
  if (xc[2] < 0.2) return false;
  return cam.Project(xc, uv);
}

inline Scene MakeScene(const SceneOptions& o) {
  Scene scene;
  scene.line_delay_s = o.line_delay_s;
  std::mt19937 rng(o.seed);
  std::normal_distribution<double> normal(0.0, 1.0);
  std::uniform_real_distribution<double> uniform(-1.0, 1.0), unit(0.0, 1.0);
  auto all_points = RoomPoints(o.points_per_face, &rng);
  for (auto& point : all_points) point *= o.room_scale;
  const auto& cam = scene.camera;
  scene.poses.resize(o.keyframes, 6);
  for (int k = 0; k < o.keyframes; ++k)
    scene.poses.row(k) = WalkPose(k * o.keyframe_interval_s, o.walk).transpose();
  struct Obs {
    int keyframe;
    Eigen::Vector2d uv, velocity;
  };
  std::vector<std::vector<Obs>> tracks(all_points.size());
  const double border = 4.0;
  for (int k = 0; k < o.keyframes; ++k) {
    const double t = k * o.keyframe_interval_s;
    for (size_t j = 0; j < all_points.size(); ++j) {
      Eigen::Vector2d uv;
      if (!ProjectWorld(cam, WalkPose(t, o.walk), all_points[j], &uv)) continue;
      bool ok = true;  // rolling shutter: the row's own time, by fixed-point iteration
      for (int pass = 0; pass < 5 && ok && o.line_delay_s != 0.0; ++pass)
        ok = ProjectWorld(cam, WalkPose(t + o.line_delay_s * (uv[1] - scene.reference_row), o.walk),
                          all_points[j], &uv);
      const double t_row = t + o.line_delay_s * (uv[1] - scene.reference_row);
      Eigen::Vector2d before, after;
      const double dt = 1e-4;
      ok = ok && ProjectWorld(cam, WalkPose(t_row - dt, o.walk), all_points[j], &before) &&
           ProjectWorld(cam, WalkPose(t_row + dt, o.walk), all_points[j], &after);
      if (!ok || uv[0] < border || uv[1] < border || uv[0] > cam.width() - 1 - border ||
          uv[1] > cam.height() - 1 - border)
        continue;
      tracks[j].push_back({k, uv, (after - before) / (2 * dt)});
    }
  }
  std::vector<Eigen::Vector3i> rows;  // keyframe, point, track entry
  auto& data = scene.data;
  std::vector<Eigen::Vector3d> anchored;
  std::vector<int> anchors;
  for (size_t j = 0; j < tracks.size(); ++j) {
    if (static_cast<int>(tracks[j].size()) < o.min_views) continue;
    const int p = static_cast<int>(scene.points_w.size());
    scene.points_w.push_back(all_points[j]);
    const int anchor = tracks[j].front().keyframe;
    Eigen::Vector3d abr;
    AnchoredPointFromWorld(scene.poses.row(anchor).data(), all_points[j], &abr);
    anchored.push_back(abr);
    anchors.push_back(anchor);
    for (size_t e = 0; e < tracks[j].size(); ++e) rows.emplace_back(tracks[j][e].keyframe, p, e);
  }
  // Observations keyframe by keyframe (as a front end emits them).
  std::stable_sort(rows.begin(), rows.end(),
                   [](const Eigen::Vector3i& a, const Eigen::Vector3i& b) { return a[0] < b[0]; });
  const int n = static_cast<int>(rows.size());
  auto& obs = data.observations;
  obs.keyframe.resize(n);
  obs.point.resize(n);
  obs.uv_px.resize(n, 2);
  obs.image_velocity_px_s.resize(n, 2);
  scene.outlier.assign(n, false);
  std::vector<int> original(scene.points_w.size());
  {
    int p = 0;
    for (size_t j = 0; j < tracks.size(); ++j)
      if (static_cast<int>(tracks[j].size()) >= o.min_views) original[p++] = static_cast<int>(j);
  }
  for (int i = 0; i < n; ++i) {
    const auto& entry = tracks[original[rows[i][1]]][rows[i][2]];
    obs.keyframe[i] = rows[i][0];
    obs.point[i] = rows[i][1];
    Eigen::Vector2d noise(normal(rng), normal(rng));
    obs.uv_px.row(i) = (entry.uv + o.noise_px * noise).transpose();
    if (unit(rng) < o.outlier_fraction) {
      obs.uv_px.row(i) += Eigen::RowVector2d(15.0 * uniform(rng), 15.0 * uniform(rng));
      scene.outlier[i] = true;
    }
    obs.image_velocity_px_s.row(i) = entry.velocity.transpose();
  }
  data.keyframe_poses = scene.poses;
  data.points.resize(static_cast<Eigen::Index>(anchored.size()), 3);
  data.point_anchor.resize(static_cast<Eigen::Index>(anchored.size()));
  for (size_t p = 0; p < anchored.size(); ++p) {
    data.points.row(p) = anchored[p].transpose();
    data.point_anchor[p] = anchors[p];
  }
  data.reference_row = scene.reference_row;
  return scene;
}

// A start away from the truth: the camera by a few %, the poses by cm and 0.6 degrees, the
// points' directions and inverse depths; the first pose stays (the gauge).
inline void PerturbStart(Scene* scene, Eigen::VectorXd* camera_start, unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> normal(0.0, 1.0);
  auto& data = scene->data;
  for (Eigen::Index k = 1; k < data.keyframe_poses.rows(); ++k)
    for (int c = 0; c < 6; ++c) data.keyframe_poses(k, c) += (c < 3 ? 0.02 : 0.01) * normal(rng);
  for (Eigen::Index p = 0; p < data.points.rows(); ++p) {
    data.points(p, 0) += 0.005 * normal(rng);
    data.points(p, 1) += 0.005 * normal(rng);
    data.points(p, 2) *= 1.0 + 0.2 * normal(rng);
  }
  *camera_start = scene->camera.params();
  (*camera_start)[0] *= 1.05;
  (*camera_start)[1] += 5.0;
  (*camera_start)[2] -= 4.0;
  (*camera_start)[3] = 0.0;
  (*camera_start)[4] = 0.0;
}

}  // namespace rscalib::bundle::testing
