#pragma once
// The tracker's saddle check (rscalib.detection.tracking.corners_are_saddles), split around the
// image sampling, which stays OpenCV's (cv2.remap): where to sample the four quadrants of each
// corner of a grid, then whether the sampled values show a checkerboard saddle at every corner.
// The sample places are numpy's to the bit (its order of operations, no fused multiply-add).
#include <Eigen/Core>

namespace rscalib::geometry {

using SampleMap = Eigen::Matrix<float, Eigen::Dynamic, 4, Eigen::RowMajor>;

// grid ((rows * cols) x 2, row-major over the grid): corner pixels. For each corner, the four
// points `fraction` of the local grid steps away along both diagonals (+diagonal, -diagonal,
// +anti-diagonal, -anti-diagonal), the steps from central differences (one-sided at the ends).
void SaddleSamplePoints(const Eigen::MatrixX2d& grid, int rows, int cols, double fraction,
                        SampleMap* map_x, SampleMap* map_y);

// values (n x 4): the grey levels at those points; even (n): the corner's parity (row + col even).
// A saddle: one diagonal pair brighter than the other by min_gap_fraction x the contrast (the
// median over corners of max - min), the bright pair alternating with the parity as most corners
// have it, and a contrast of at least min_contrast grey levels.
bool CornersAreSaddles(
    const Eigen::Ref<const Eigen::Matrix<double, Eigen::Dynamic, 4, Eigen::RowMajor>>& values,
    const Eigen::Ref<const Eigen::Matrix<bool, Eigen::Dynamic, 1>>& even, double min_contrast,
    double min_gap_fraction);

}  // namespace rscalib::geometry
