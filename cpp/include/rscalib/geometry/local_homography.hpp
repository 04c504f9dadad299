#pragma once
// The detectors' geometric check (rscalib.detection.quality.local_homography_residual): each
// detected point against the homography of its nearest neighbours on the target, fitted by the
// normalised DLT (Hartley), its null vector refined by inverse iteration. Local fits tolerate
// lens distortion; a wrong id or a stray point stands out.
#include <Eigen/Core>

namespace rscalib::geometry {

// target_xy (n x 2): the points' target coordinates; uv (n x 2): their pixels; nearest (n x k):
// each point's nearest target neighbours (rows of target_xy / uv, not itself; k <= 16). Returns for
// each point |uv - H_i(xy)| / |uv(nearest(i, 0)) - uv| (in grid steps), H_i fitted to its k
// neighbours. NaN where the fit is degenerate or a value is not finite; the caller decides
// which neighbourhoods are well posed.
Eigen::VectorXd LocalHomographyResidual(const Eigen::MatrixX2d& target_xy,
                                        const Eigen::MatrixX2d& uv, const Eigen::MatrixXi& nearest);

}  // namespace rscalib::geometry
