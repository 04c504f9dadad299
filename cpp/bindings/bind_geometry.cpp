// Bindings: rotation vectors; the detectors' local-homography check, blur measure and saddle check.
#include <cmath>
#include <string>

#include <Eigen/LU>
#include <pybind11/eigen.h>

#include "bindings.hpp"
#include "rscalib/core/error.hpp"
#include "rscalib/geometry/corner_saddles.hpp"
#include "rscalib/geometry/edge_width.hpp"
#include "rscalib/geometry/local_homography.hpp"
#include "rscalib/geometry/rotation.hpp"

namespace rscalib::python {

namespace {

// NaN stands for a rotation that is not known (a frame PnP failed on) and stays NaN; infinity is
// no rotation at all.
bool HasInfinity(const double* values, Eigen::Index count) {
  for (Eigen::Index i = 0; i < count; ++i)
    if (std::isinf(values[i])) return true;
  return false;
}

// How far R^T R may be from I: a matrix that is not a rotation at all (a scale of 2, a shear, a
// reflection) is refused; a small departure (rounding, the self-calibration's mean of unit
// quaternions, which is not one) is taken to its rotation, as before.
constexpr double kRotationTolerance = 0.5;

}  // namespace

void BindGeometry(py::module_& m) {
  m.def(
      "unwrap_rotation_vectors",
      [](const Eigen::MatrixX3d& rotation_vectors) {
        if (HasInfinity(rotation_vectors.data(), rotation_vectors.size()))
          throw InputError(
              "rotation_vectors has an infinite value (NaN rows, unknown rotations, stay NaN)");
        return geometry::UnwrapRotationVectors(rotation_vectors);
      },
      py::arg("rotation_vectors"),
      "Paper eq. 22: make a (n, 3) sequence of rotation vectors continuous (2*pi per axis); "
      "NaN rows (unknown rotations) stay NaN.");
  m.def(
      "rotation_vector_to_matrix",
      [](const Eigen::Vector3d& phi) {
        if (HasInfinity(phi.data(), 3))
          throw InputError(
              "rotation_vector has an infinite value (NaN, an unknown rotation, gives NaN)");
        if (!phi.allFinite()) return Eigen::Matrix3d::Constant(std::nan("")).eval();
        return geometry::RotationVectorToMatrix(phi.data());
      },
      py::arg("rotation_vector"),
      "R = exp([phi]x) of a rotation vector phi (radians); NaN (an unknown rotation) gives NaN.");
  m.def(
      "rotation_matrix_to_vector",
      [](const Eigen::Matrix3d& rotation) {
        if (HasInfinity(rotation.data(), 9))
          throw InputError("rotation has an infinite value (NaN, an unknown rotation, gives NaN)");
        if (!rotation.allFinite()) return Eigen::Vector3d::Constant(std::nan("")).eval();
        {
          const double off =
              (rotation.transpose() * rotation - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff();
          const double det = rotation.determinant();
          if (!(off <= kRotationTolerance) || !(det > 0.0))
            throw InputError("rotation is not a rotation matrix (|R^T R - I| = " +
                             std::to_string(off) + ", det R = " + std::to_string(det) + ")");
        }
        return geometry::RotationMatrixToVector(rotation);
      },
      py::arg("rotation"),
      "phi (angle in [0, pi]) of a rotation matrix; NaN (an unknown rotation) gives NaN.");
  m.def(
      "saddle_sample_points",
      [](const Eigen::MatrixX2d& grid, int rows, int cols, double fraction) {
        geometry::SampleMap map_x, map_y;
        {
          py::gil_scoped_release release;
          geometry::SaddleSamplePoints(grid, rows, cols, fraction, &map_x, &map_y);
        }
        return py::make_tuple(map_x, map_y);
      },
      py::arg("grid"), py::arg("rows"), py::arg("cols"), py::arg("fraction"),
      "(map_x, map_y), (rows * cols, 4) float32: where cv2.remap samples the quadrants of each "
      "corner of a grid ((rows * cols, 2), row-major); "
      "rscalib.detection.tracking.corners_are_saddles.");
  m.def(
      "corners_are_saddles",
      [](const Eigen::Ref<const Eigen::Matrix<double, Eigen::Dynamic, 4, Eigen::RowMajor>>& values,
         const Eigen::Ref<const Eigen::Matrix<bool, Eigen::Dynamic, 1>>& even, double min_contrast,
         double min_gap_fraction) {
        py::gil_scoped_release release;
        return geometry::CornersAreSaddles(values, even, min_contrast, min_gap_fraction);
      },
      py::arg("values"), py::arg("even"), py::arg("min_contrast"), py::arg("min_gap_fraction"),
      "Whether the grey levels sampled at the saddle points ((n, 4)) show a checkerboard saddle at "
      "every corner (even: each corner's parity).");
  m.def(
      "edge_profile_maps",
      [](const Eigen::MatrixX2d& a, const Eigen::MatrixX2d& b, bool across_rim, double fraction,
         const Eigen::VectorXd& profile_s, double max_half_px, double min_half_px) {
        geometry::EdgeProfileMaps maps;
        {
          py::gil_scoped_release release;
          maps = geometry::EdgeProfileMapsFor(a, b, across_rim, fraction, profile_s, max_half_px,
                                              min_half_px);
        }
        return py::make_tuple(maps.map_x, maps.map_y, maps.half_px);
      },
      py::arg("a"), py::arg("b"), py::arg("across_rim"), py::arg("fraction"), py::arg("profile_s"),
      py::arg("max_half_px"), py::arg("min_half_px"),
      "(map_x, map_y, half_px): where cv2.remap samples an intensity profile across each target "
      "edge (a, b: its ends' pixels, (m, 2)), as float32 maps (one row per kept edge), and each "
      "profile's half length; rscalib.detection.quality.edge_width_px.");
  m.def(
      "edge_width_from_profiles",
      [](const Eigen::Ref<const Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic,
                                              Eigen::RowMajor>>& profiles,
         const Eigen::VectorXd& half_px, double min_contrast) {
        py::gil_scoped_release release;
        return geometry::EdgeWidthFromProfiles(profiles, half_px, min_contrast);
      },
      py::arg("profiles"), py::arg("half_px"), py::arg("min_contrast"),
      "The 75th percentile of the edge widths (px) of sampled profiles (m, samples; grey "
      "levels) of half lengths half_px; NaN if no profile has more than min_contrast grey "
      "levels of contrast.");
  m.def(
      "local_homography_residual",
      [](const Eigen::MatrixX2d& target_xy, const Eigen::MatrixX2d& uv,
         const Eigen::MatrixXi& nearest) {
        py::gil_scoped_release release;
        return geometry::LocalHomographyResidual(target_xy, uv, nearest);
      },
      py::arg("target_xy"), py::arg("uv"), py::arg("nearest"),
      "For each point (rows of target_xy and uv, (n, 2)), the distance in grid steps from its "
      "pixel to the homography of its k nearest target neighbours (nearest, (n, k) row "
      "indices), fitted by the normalised DLT; NaN where it cannot be fitted.");
}

}  // namespace rscalib::python
