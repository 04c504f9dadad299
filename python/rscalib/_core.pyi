"""
C++ core of rscalib: B-spline trajectories, camera models, the rolling-shutter solver and the SOG filter bank and the self-calibration bundle adjustment.
"""
from __future__ import annotations
import collections.abc
import numpy
import numpy.typing
import typing
__all__: list[str] = ['BSpline', 'BundleOptions', 'BundleResult', 'CameraModel', 'InputError', 'LinearInterpOptions', 'LinearInterpSummary', 'RsSolveSummary', 'RsSolverOptions', 'SogBank', 'SogOptions', 'SogUpdateReport', 'corners_are_saddles', 'edge_profile_maps', 'edge_width_from_profiles', 'error_noise_map', 'evaluate_line_delay', 'evaluate_rs_cost', 'fit_bspline', 'linear_interp_pose_state', 'local_homography_residual', 'poses_at', 'rotation_matrix_to_vector', 'rotation_vector_to_matrix', 'saddle_sample_points', 'solve_bundle', 'solve_line_delay', 'solve_line_delay_linear', 'standardisation_weight', 'unwrap_rotation_vectors']
class InputError(ValueError):
    pass
class BSpline:
    """
    Non-uniform cubic (order 4) B-spline x(t) in R^N with clamped ends.
    
    knots: n + 4 non-decreasing values with 4 equal knots at each end; control_points: (n, N).
    Segment s is [breakpoints[s], breakpoints[s+1]); span = segment + 3 in the knot vector.
    """
    @staticmethod
    def clamped_knots(breakpoints: collections.abc.Sequence[typing.SupportsFloat | typing.SupportsIndex]) -> list[float]:
        """
        Clamped knot vector from strictly increasing breakpoints.
        """
    @staticmethod
    def uniform(t_begin: typing.SupportsFloat | typing.SupportsIndex, t_end: typing.SupportsFloat | typing.SupportsIndex, num_segments: typing.SupportsInt | typing.SupportsIndex, dimension: typing.SupportsInt | typing.SupportsIndex) -> BSpline:
        """
        Uniform segments on [t_begin, t_end], control points zero.
        """
    def __copy__(self) -> BSpline:
        ...
    def __deepcopy__(self, arg0: dict) -> BSpline:
        ...
    def __getstate__(self) -> tuple[list[float], typing.Annotated[numpy.typing.NDArray[numpy.float64], "[m, n]"]]:
        ...
    def __init__(self, knots: collections.abc.Sequence[typing.SupportsFloat | typing.SupportsIndex], control_points: typing.Annotated[numpy.typing.ArrayLike, numpy.float64, "[m, n]"]) -> None:
        ...
    def __repr__(self) -> str:
        ...
    def __setstate__(self, arg0: tuple) -> None:
        ...
    def basis(self, t: typing.SupportsFloat | typing.SupportsIndex) -> tuple[int, typing.Annotated[numpy.typing.NDArray[numpy.float64], "[3, 4]"]]:
        """
        (span, weights): weights[k, j] = d^k w_j/dt^k of control point span-3+j, k = 0..2.
        """
    def copy(self) -> BSpline:
        ...
    def evaluate(self, t: typing.Any, derivative: typing.SupportsInt | typing.SupportsIndex = 0) -> numpy.typing.NDArray[numpy.float64]:
        """
        Value or derivative (0..3) at a time (-> (N,)) or at an array of times (-> (m, N)).
        """
    def insert_knot(self, t: typing.SupportsFloat | typing.SupportsIndex) -> None:
        """
        Boehm knot insertion: one more control point, the curve unchanged.
        """
    def segment_at(self, t: typing.SupportsFloat | typing.SupportsIndex) -> int:
        ...
    def span_at(self, t: typing.SupportsFloat | typing.SupportsIndex) -> int:
        ...
    @property
    def breakpoints(self) -> numpy.typing.NDArray[numpy.float64]:
        ...
    @property
    def control_points(self) -> typing.Annotated[numpy.typing.NDArray[numpy.float64], "[m, n]"]:
        """
        (n, N) control points (a copy; assign to change them).
        """
    @control_points.setter
    def control_points(self, arg1: typing.Annotated[numpy.typing.ArrayLike, numpy.float64, "[m, n]"]) -> None:
        ...
    @property
    def dimension(self) -> int:
        ...
    @property
    def knots(self) -> numpy.typing.NDArray[numpy.float64]:
        ...
    @property
    def num_control_points(self) -> int:
        ...
    @property
    def num_segments(self) -> int:
        ...
    @property
    def t_begin(self) -> float:
        ...
    @property
    def t_end(self) -> float:
        ...
class CameraModel:
    """
    A camera: model name, parameters, image size (and pixel size for civera-radial).
    
    Models and parameter layouts (docs/conventions.md):
      pinhole-radtan       [fx, fy, cx, cy, k1, k2, p1, p2, k3]   (OpenCV; 4 or 8 values also accepted)
      pinhole-equidistant  [fx, fy, cx, cy, k1, k2, k3, k4]       (OpenCV fisheye)
      civera-radial        [f, cx, cy, k1, k2] + pixel_size_mm (dx, dy)
    Points are in the camera frame (x right, y down, z forward); pixels in OpenCV's convention.
    Points that cannot be projected give NaN.
    """
    def __getstate__(self) -> tuple[str, typing.Annotated[numpy.typing.NDArray[numpy.float64], "[m, 1]"], int, int, typing.Annotated[numpy.typing.NDArray[numpy.float64], "[2, 1]"]]:
        ...
    def __init__(self, model: str, params: typing.Annotated[numpy.typing.ArrayLike, numpy.float64, "[m, 1]"], width: typing.SupportsInt | typing.SupportsIndex, height: typing.SupportsInt | typing.SupportsIndex, pixel_size_mm: typing.Annotated[numpy.typing.ArrayLike, numpy.float64, "[2, 1]"] = ...) -> None:
        ...
    def __repr__(self) -> str:
        ...
    def __setstate__(self, arg0: tuple) -> None:
        ...
    def distort(self, uv_undistorted: typing.Annotated[numpy.typing.ArrayLike, numpy.float64]) -> numpy.typing.NDArray[numpy.float64]:
        """
        civera-radial: undistorted -> distorted pixels (Newton).
        """
    def project(self, points_c: typing.Annotated[numpy.typing.ArrayLike, numpy.float64]) -> numpy.typing.NDArray[numpy.float64]:
        """
        (n, 3) camera-frame points -> (n, 2) pixels.
        """
    def project_with_jacobians(self, points_c: typing.Annotated[numpy.typing.ArrayLike, numpy.float64]) -> tuple:
        """
        -> (uv (n, 2), d_uv_d_point (n, 2, 3), d_uv_d_params (n, 2, num_params)).
        """
    def undistort(self, uv_distorted: typing.Annotated[numpy.typing.ArrayLike, numpy.float64]) -> numpy.typing.NDArray[numpy.float64]:
        """
        civera-radial: distorted -> undistorted pixels.
        """
    def unproject(self, uv: typing.Annotated[numpy.typing.ArrayLike, numpy.float64]) -> numpy.typing.NDArray[numpy.float64]:
        """
        (n, 2) pixels -> (n, 3) rays with z = 1.
        """
    @property
    def height(self) -> int:
        ...
    @property
    def model(self) -> str:
        ...
    @property
    def param_names(self) -> list[str]:
        ...
    @property
    def params(self) -> typing.Annotated[numpy.typing.NDArray[numpy.float64], "[m, 1]"]:
        ...
    @property
    def pixel_size_mm(self) -> typing.Annotated[numpy.typing.NDArray[numpy.float64], "[2, 1]"]:
        ...
    @property
    def width(self) -> int:
        ...
class RsSolverOptions:
    """
    Options of the line-delay solve (docs/formulation.md).
    """
    compute_covariance: bool
    estimate_line_delay: bool
    standardise_errors: bool
    use_motion_prior: bool
    verbose: bool
    def __init__(self) -> None:
        ...
    @property
    def analytic_jacobian(self) -> bool:
        """
        Jacobian chained through the basis weights (false: full autodiff)
        """
    @analytic_jacobian.setter
    def analytic_jacobian(self, arg0: bool) -> None:
        ...
    @property
    def fixed_intrinsics(self) -> list[int]:
        """
        indices of the camera's parameters held at their starting value
        """
    @fixed_intrinsics.setter
    def fixed_intrinsics(self, arg0: collections.abc.Sequence[typing.SupportsInt | typing.SupportsIndex]) -> None:
        ...
    @property
    def function_tolerance(self) -> float:
        ...
    @function_tolerance.setter
    def function_tolerance(self, arg0: typing.SupportsFloat | typing.SupportsIndex) -> None:
        ...
    @property
    def gradient_tolerance(self) -> float:
        ...
    @gradient_tolerance.setter
    def gradient_tolerance(self, arg0: typing.SupportsFloat | typing.SupportsIndex) -> None:
        ...
    @property
    def intrinsics_prior_covariance(self) -> typing.Annotated[numpy.typing.NDArray[numpy.float64], "[m, n]"]:
        """
        (n, n) prior covariance; rows of fixed parameters ignored
        """
    @intrinsics_prior_covariance.setter
    def intrinsics_prior_covariance(self, arg0: typing.Annotated[numpy.typing.ArrayLike, numpy.float64, "[m, n]"]) -> None:
        ...
    @property
    def intrinsics_prior_mean(self) -> typing.Annotated[numpy.typing.NDArray[numpy.float64], "[m, 1]"]:
        """
        prior mean of the camera's n parameters (its layout)
        """
    @intrinsics_prior_mean.setter
    def intrinsics_prior_mean(self, arg0: typing.Annotated[numpy.typing.ArrayLike, numpy.float64, "[m, 1]"]) -> None:
        ...
    @property
    def line_delay_score(self) -> bool:
        """
        also each observation's score of d (summary.line_delay_score)
        """
    @line_delay_score.setter
    def line_delay_score(self, arg0: bool) -> None:
        ...
    @property
    def max_iterations(self) -> int:
        ...
    @max_iterations.setter
    def max_iterations(self, arg0: typing.SupportsInt | typing.SupportsIndex) -> None:
        ...
    @property
    def max_outer_iterations(self) -> int:
        ...
    @max_outer_iterations.setter
    def max_outer_iterations(self, arg0: typing.SupportsInt | typing.SupportsIndex) -> None:
        ...
    @property
    def max_rs_gain(self) -> float:
        ...
    @max_rs_gain.setter
    def max_rs_gain(self, arg0: typing.SupportsFloat | typing.SupportsIndex) -> None:
        ...
    @property
    def motion_prior_q(self) -> typing.Annotated[numpy.typing.NDArray[numpy.float64], "[6, 1]"]:
        """
        diag(Q), 6 values
        """
    @motion_prior_q.setter
    def motion_prior_q(self, arg0: typing.Annotated[numpy.typing.ArrayLike, numpy.float64, "[6, 1]"]) -> None:
        ...
    @property
    def num_threads(self) -> int:
        ...
    @num_threads.setter
    def num_threads(self, arg1: typing.SupportsInt | typing.SupportsIndex) -> None:
        ...
    @property
    def observation_sigma(self) -> typing.Annotated[numpy.typing.NDArray[numpy.float64], "[m, 1]"]:
        """
        optional per-observation sigma (M values, px); empty: pixel_sigma for all
        """
    @observation_sigma.setter
    def observation_sigma(self, arg0: typing.Annotated[numpy.typing.ArrayLike, numpy.float64, "[m, 1]"]) -> None:
        ...
    @property
    def parameter_tolerance(self) -> float:
        ...
    @parameter_tolerance.setter
    def parameter_tolerance(self, arg0: typing.SupportsFloat | typing.SupportsIndex) -> None:
        ...
    @property
    def pixel_sigma(self) -> float:
        """
        R = sigma^2 I, px
        """
    @pixel_sigma.setter
    def pixel_sigma(self, arg0: typing.SupportsFloat | typing.SupportsIndex) -> None:
        ...
    @property
    def refine_intrinsics(self) -> bool:
        """
        refine the camera's parameters jointly (docs/formulation.md §14)
        """
    @refine_intrinsics.setter
    def refine_intrinsics(self, arg0: bool) -> None:
        ...
    @property
    def robust_loss(self) -> str:
        """
        none | huber | cauchy
        """
    @robust_loss.setter
    def robust_loss(self, arg0: str) -> None:
        ...
    @property
    def robust_loss_scale(self) -> float:
        ...
    @robust_loss_scale.setter
    def robust_loss_scale(self, arg0: typing.SupportsFloat | typing.SupportsIndex) -> None:
        ...
    @property
    def schur_variance(self) -> bool:
        """
        sigma_d from the Schur complement (false: Ceres' covariance)
        """
    @schur_variance.setter
    def schur_variance(self, arg0: bool) -> None:
        ...
class RsSolveSummary:
    @property
    def clamped_weights(self) -> int:
        ...
    @property
    def converged(self) -> bool:
        ...
    @property
    def covariance_ok(self) -> bool:
        ...
    @property
    def covariance_time_s(self) -> float:
        ...
    @property
    def image_velocity_px_s(self) -> typing.Annotated[numpy.typing.NDArray[numpy.float64], "[m, 2]"]:
        ...
    @property
    def intrinsics(self) -> typing.Annotated[numpy.typing.NDArray[numpy.float64], "[m, 1]"]:
        """
        refined camera parameters (refine_intrinsics), else empty
        """
    @property
    def intrinsics_prior_cost(self) -> float:
        ...
    @property
    def iterations(self) -> int:
        ...
    @property
    def line_delay_intrinsics_covariance(self) -> typing.Annotated[numpy.typing.NDArray[numpy.float64], "[m, n]"]:
        """
        (1 + n, 1 + n) covariance of [d, intrinsics] (refine_intrinsics), else empty
        """
    @property
    def line_delay_s(self) -> float:
        ...
    @property
    def line_delay_score(self) -> typing.Annotated[numpy.typing.NDArray[numpy.float64], "[m, 2]"]:
        ...
    @property
    def line_delay_std_s(self) -> float:
        ...
    @property
    def measurement_cost(self) -> float:
        ...
    @property
    def message(self) -> str:
        ...
    @property
    def num_error_terms(self) -> int:
        ...
    @property
    def observation_time_s(self) -> typing.Annotated[numpy.typing.NDArray[numpy.float64], "[m, 1]"]:
        ...
    @property
    def outer_iterations(self) -> int:
        ...
    @property
    def prior_cost(self) -> float:
        ...
    @property
    def reattached(self) -> int:
        ...
    @property
    def residual_px(self) -> typing.Annotated[numpy.typing.NDArray[numpy.float64], "[m, 2]"]:
        ...
    @property
    def rms_px(self) -> float:
        ...
    @property
    def segment_cost(self) -> list[float]:
        ...
    @property
    def segment_count(self) -> list[int]:
        ...
    @property
    def solve_time_s(self) -> float:
        ...
    @property
    def standardised_sq(self) -> typing.Annotated[numpy.typing.NDArray[numpy.float64], "[m, 1]"]:
        ...
    @property
    def unprojectable(self) -> int:
        ...
class LinearInterpOptions:
    """
    Options of the linear-interpolation line-delay solve.
    """
    compute_covariance: bool
    estimate_line_delay: bool
    verbose: bool
    def __init__(self) -> None:
        ...
    @property
    def function_tolerance(self) -> float:
        ...
    @function_tolerance.setter
    def function_tolerance(self, arg0: typing.SupportsFloat | typing.SupportsIndex) -> None:
        ...
    @property
    def gradient_tolerance(self) -> float:
        ...
    @gradient_tolerance.setter
    def gradient_tolerance(self, arg0: typing.SupportsFloat | typing.SupportsIndex) -> None:
        ...
    @property
    def max_frame_interval_s(self) -> float:
        """
        frames further apart are not interpolated between; 0: 1.5 x median
        """
    @max_frame_interval_s.setter
    def max_frame_interval_s(self, arg0: typing.SupportsFloat | typing.SupportsIndex) -> None:
        ...
    @property
    def max_iterations(self) -> int:
        ...
    @max_iterations.setter
    def max_iterations(self, arg0: typing.SupportsInt | typing.SupportsIndex) -> None:
        ...
    @property
    def max_outer_iterations(self) -> int:
        ...
    @max_outer_iterations.setter
    def max_outer_iterations(self, arg0: typing.SupportsInt | typing.SupportsIndex) -> None:
        ...
    @property
    def max_rs_gain(self) -> float:
        ...
    @max_rs_gain.setter
    def max_rs_gain(self, arg0: typing.SupportsFloat | typing.SupportsIndex) -> None:
        ...
    @property
    def num_threads(self) -> int:
        ...
    @num_threads.setter
    def num_threads(self, arg1: typing.SupportsInt | typing.SupportsIndex) -> None:
        ...
    @property
    def parameter_tolerance(self) -> float:
        ...
    @parameter_tolerance.setter
    def parameter_tolerance(self, arg0: typing.SupportsFloat | typing.SupportsIndex) -> None:
        ...
    @property
    def pixel_sigma(self) -> float:
        """
        R = sigma^2 I, px
        """
    @pixel_sigma.setter
    def pixel_sigma(self, arg0: typing.SupportsFloat | typing.SupportsIndex) -> None:
        ...
    @property
    def robust_loss(self) -> str:
        """
        none | huber | cauchy
        """
    @robust_loss.setter
    def robust_loss(self, arg0: str) -> None:
        ...
    @property
    def robust_loss_scale(self) -> float:
        ...
    @robust_loss_scale.setter
    def robust_loss_scale(self, arg0: typing.SupportsFloat | typing.SupportsIndex) -> None:
        ...
    @property
    def standardise_errors(self) -> bool:
        """
        A R A^T weights (default False: plain error / sigma)
        """
    @standardise_errors.setter
    def standardise_errors(self, arg0: bool) -> None:
        ...
class LinearInterpSummary:
    @property
    def clamped_weights(self) -> int:
        ...
    @property
    def converged(self) -> bool:
        ...
    @property
    def covariance_ok(self) -> bool:
        ...
    @property
    def covariance_time_s(self) -> float:
        ...
    @property
    def extrapolated(self) -> int:
        ...
    @property
    def image_velocity_px_s(self) -> typing.Annotated[numpy.typing.NDArray[numpy.float64], "[m, 2]"]:
        ...
    @property
    def isolated(self) -> int:
        ...
    @property
    def iterations(self) -> int:
        ...
    @property
    def line_delay_s(self) -> float:
        ...
    @property
    def line_delay_std_s(self) -> float:
        ...
    @property
    def max_frame_interval_s(self) -> float:
        ...
    @property
    def measurement_cost(self) -> float:
        ...
    @property
    def message(self) -> str:
        ...
    @property
    def num_chains(self) -> int:
        ...
    @property
    def num_error_terms(self) -> int:
        ...
    @property
    def observation_time_s(self) -> typing.Annotated[numpy.typing.NDArray[numpy.float64], "[m, 1]"]:
        ...
    @property
    def outer_iterations(self) -> int:
        ...
    @property
    def pair_first(self) -> typing.Annotated[numpy.typing.NDArray[numpy.int32], "[m, 1]"]:
        ...
    @property
    def residual_px(self) -> typing.Annotated[numpy.typing.NDArray[numpy.float64], "[m, 2]"]:
        ...
    @property
    def rms_px(self) -> float:
        ...
    @property
    def solve_time_s(self) -> float:
        ...
    @property
    def standardised_sq(self) -> typing.Annotated[numpy.typing.NDArray[numpy.float64], "[m, 1]"]:
        ...
    @property
    def unprojectable(self) -> int:
        ...
class SogOptions:
    """
    Options of the SOG self-calibration bank (docs/sog.md §9). SI units; pixels in px.
    """
    prune: bool
    def __init__(self) -> None:
        ...
    def __repr__(self) -> str:
        ...
    @property
    def accel_sigma(self) -> float:
        """
        linear acceleration noise std (m/s^2) of the constant-velocity model
        """
    @accel_sigma.setter
    def accel_sigma(self, arg1: typing.SupportsFloat | typing.SupportsIndex) -> None:
        ...
    @property
    def angular_accel_sigma(self) -> float:
        """
        angular acceleration noise std (rad/s^2)
        """
    @angular_accel_sigma.setter
    def angular_accel_sigma(self, arg1: typing.SupportsFloat | typing.SupportsIndex) -> None:
        ...
    @property
    def calibration_random_walk(self) -> typing.Annotated[numpy.typing.NDArray[numpy.float64], "[5, 1]"]:
        """
        per-sqrt(s) random walk of (f, Cx, Cy, k1, k2); zeros = static calibration
        """
    @calibration_random_walk.setter
    def calibration_random_walk(self, arg1: typing.Annotated[numpy.typing.ArrayLike, numpy.float64, "[5, 1]"]) -> None:
        ...
    @property
    def deletion_min_match_ratio(self) -> float:
        ...
    @deletion_min_match_ratio.setter
    def deletion_min_match_ratio(self, arg0: typing.SupportsFloat | typing.SupportsIndex) -> None:
        ...
    @property
    def deletion_min_predictions(self) -> int:
        ...
    @deletion_min_predictions.setter
    def deletion_min_predictions(self, arg0: typing.SupportsInt | typing.SupportsIndex) -> None:
        ...
    @property
    def gate_chi2(self) -> float:
        """
        matches beyond this Mahalanobis^2 of the merged prediction are not used (<= 0: no gate)
        """
    @gate_chi2.setter
    def gate_chi2(self, arg0: typing.SupportsFloat | typing.SupportsIndex) -> None:
        ...
    @property
    def guard_f_sigma_ratio(self) -> float:
        ...
    @guard_f_sigma_ratio.setter
    def guard_f_sigma_ratio(self, arg0: typing.SupportsFloat | typing.SupportsIndex) -> None:
        ...
    @property
    def guard_min_frames(self) -> int:
        ...
    @guard_min_frames.setter
    def guard_min_frames(self, arg0: typing.SupportsInt | typing.SupportsIndex) -> None:
        ...
    @property
    def guard_min_rotation_deg(self) -> float:
        ...
    @guard_min_rotation_deg.setter
    def guard_min_rotation_deg(self, arg0: typing.SupportsFloat | typing.SupportsIndex) -> None:
        ...
    @property
    def initial_angular_velocity_sigma(self) -> float:
        """
        rad/s
        """
    @initial_angular_velocity_sigma.setter
    def initial_angular_velocity_sigma(self, arg0: typing.SupportsFloat | typing.SupportsIndex) -> None:
        ...
    @property
    def initial_inverse_depth(self) -> float:
        """
        rho0 of new features (1/m)
        """
    @initial_inverse_depth.setter
    def initial_inverse_depth(self, arg0: typing.SupportsFloat | typing.SupportsIndex) -> None:
        ...
    @property
    def initial_inverse_depth_sigma(self) -> float:
        """
        (1/m)
        """
    @initial_inverse_depth_sigma.setter
    def initial_inverse_depth_sigma(self, arg0: typing.SupportsFloat | typing.SupportsIndex) -> None:
        ...
    @property
    def initial_velocity_sigma(self) -> float:
        """
        m/s
        """
    @initial_velocity_sigma.setter
    def initial_velocity_sigma(self, arg0: typing.SupportsFloat | typing.SupportsIndex) -> None:
        ...
    @property
    def likelihood_temperature(self) -> float:
        """
        weights and SPRT use the innovation likelihood to the power 1/T (T >= 1)
        """
    @likelihood_temperature.setter
    def likelihood_temperature(self, arg0: typing.SupportsFloat | typing.SupportsIndex) -> None:
        ...
    @property
    def linearity_threshold(self) -> float:
        """
        inverse depth -> XYZ below this linearity index (<= 0: never)
        """
    @linearity_threshold.setter
    def linearity_threshold(self, arg0: typing.SupportsFloat | typing.SupportsIndex) -> None:
        ...
    @property
    def max_features(self) -> int:
        """
        map cap: features matched longest ago are deleted beyond it (<= 0: no cap)
        """
    @max_features.setter
    def max_features(self, arg0: typing.SupportsInt | typing.SupportsIndex) -> None:
        ...
    @property
    def merge_mahalanobis2(self) -> float:
        """
        while pruning, merge Gaussians whose calibrations are closer than this (<= 0: never)
        """
    @merge_mahalanobis2.setter
    def merge_mahalanobis2(self, arg0: typing.SupportsFloat | typing.SupportsIndex) -> None:
        ...
    @property
    def min_log_weight(self) -> float:
        """
        while pruning, drop Gaussians with log weight below this
        """
    @min_log_weight.setter
    def min_log_weight(self, arg0: typing.SupportsFloat | typing.SupportsIndex) -> None:
        ...
    @property
    def num_threads(self) -> int:
        ...
    @num_threads.setter
    def num_threads(self, arg1: typing.SupportsInt | typing.SupportsIndex) -> None:
        ...
    @property
    def pixel_sigma(self) -> float:
        """
        measurement noise std (px)
        """
    @pixel_sigma.setter
    def pixel_sigma(self, arg0: typing.SupportsFloat | typing.SupportsIndex) -> None:
        ...
    @property
    def ransac_hypotheses(self) -> int:
        """
        1-point RANSAC hypotheses per frame (Civera et al. 2010; 0: off)
        """
    @ransac_hypotheses.setter
    def ransac_hypotheses(self, arg0: typing.SupportsInt | typing.SupportsIndex) -> None:
        ...
    @property
    def ransac_threshold_px(self) -> float:
        """
        1-point RANSAC: low-innovation inlier threshold (px)
        """
    @ransac_threshold_px.setter
    def ransac_threshold_px(self, arg0: typing.SupportsFloat | typing.SupportsIndex) -> None:
        ...
    @property
    def sprt_alpha(self) -> float:
        """
        type I error of the SPRT
        """
    @sprt_alpha.setter
    def sprt_alpha(self, arg0: typing.SupportsFloat | typing.SupportsIndex) -> None:
        ...
    @property
    def sprt_beta(self) -> float:
        """
        type II error of the SPRT
        """
    @sprt_beta.setter
    def sprt_beta(self, arg0: typing.SupportsFloat | typing.SupportsIndex) -> None:
        ...
    @property
    def sprt_keep_accepted(self) -> bool:
        """
        a Gaussian accepted by the SPRT (> A) is kept for good (else its test restarts)
        """
    @sprt_keep_accepted.setter
    def sprt_keep_accepted(self, arg0: bool) -> None:
        ...
    @property
    def unpredicted_log_likelihood(self) -> float:
        ...
    @unpredicted_log_likelihood.setter
    def unpredicted_log_likelihood(self, arg0: typing.SupportsFloat | typing.SupportsIndex) -> None:
        ...
    @property
    def update_iterations(self) -> int:
        """
        1: EKF update; > 1: iterated EKF (relinearised at the updated mean)
        """
    @update_iterations.setter
    def update_iterations(self, arg0: typing.SupportsInt | typing.SupportsIndex) -> None:
        ...
    @property
    def visibility_min_weight(self) -> float:
        ...
    @visibility_min_weight.setter
    def visibility_min_weight(self, arg0: typing.SupportsFloat | typing.SupportsIndex) -> None:
        ...
class SogUpdateReport:
    """
    What SogBank.update did this frame.
    """
    @property
    def converted_feature_ids(self) -> numpy.typing.NDArray[numpy.int64]:
        ...
    @property
    def deleted_feature_ids(self) -> numpy.typing.NDArray[numpy.int64]:
        ...
    @property
    def gate_chi2(self) -> typing.Annotated[numpy.typing.NDArray[numpy.float64], "[m, 1]"]:
        """
        (k,) Mahalanobis^2 of each match w.r.t. the merged prediction (NaN if not matched)
        """
    @property
    def gaussian_ids(self) -> list[int]:
        ...
    @property
    def log_likelihoods(self) -> typing.Annotated[numpy.typing.NDArray[numpy.float64], "[m, 1]"]:
        ...
    @property
    def merged_gaussian_ids(self) -> list[int]:
        ...
    @property
    def nis(self) -> typing.Annotated[numpy.typing.NDArray[numpy.float64], "[m, 1]"]:
        """
        per Gaussian: nu^T S^-1 nu (expect ~ 2 num_used)
        """
    @property
    def num_capped(self) -> int:
        """
        features deleted by the map cap (max_features)
        """
    @property
    def num_gaussians(self) -> int:
        ...
    @property
    def num_low_innovation(self) -> int:
        """
        1-point RANSAC inliers (num_used without RANSAC)
        """
    @property
    def num_rescued(self) -> int:
        """
        1-point RANSAC: matches used in the rescue update
        """
    @property
    def num_used(self) -> int:
        ...
    @property
    def pruned_gaussian_ids(self) -> list[int]:
        ...
    @property
    def pruning_active(self) -> bool:
        ...
    @property
    def used(self) -> numpy.typing.NDArray[numpy.bool]:
        """
        (k,) bool: matched, inside the gate and used in the update
        """
class SogBank:
    """
    Bank of EKFs for sequential self-calibration (Civera et al. 2009; docs/sog.md).
    
    SogBank(options, initial_means (N, 5), initial_covs (N, 5, 5), initial_weights (N,),
            image_size (width, height), pixel_size_mm)
    Calibration vectors are [f, cx, cy, k1 (mm^-2), k2 (mm^-4)] (civera-radial). The world frame is
    the first camera frame. Per frame: predict(dt_s); predict_measurements() for active search;
    update(ids, uv, matched); add_features(uv) when the image needs more features.
    """
    def __init__(self, options: SogOptions, initial_means: typing.Annotated[numpy.typing.ArrayLike, numpy.float64], initial_covs: typing.Annotated[numpy.typing.ArrayLike, numpy.float64], initial_weights: typing.Annotated[numpy.typing.ArrayLike, numpy.float64], image_size: tuple[typing.SupportsInt | typing.SupportsIndex, typing.SupportsInt | typing.SupportsIndex], pixel_size_mm: typing.Annotated[numpy.typing.ArrayLike, numpy.float64]) -> None:
        ...
    def add_features(self, uv: typing.Annotated[numpy.typing.ArrayLike, numpy.float64]) -> numpy.typing.NDArray[numpy.int64]:
        """
        New inverse-depth features at distorted pixels (k, 2) -> ids (k,).
        """
    def calibration_bounds_99(self) -> typing.Annotated[numpy.typing.NDArray[numpy.float64], "[5, 2]"]:
        """
        (5, 2) [lo, hi]: mean -+ 2.576 sigma of the merged Gaussian, per parameter
        """
    def covariance(self, gaussian: typing.SupportsInt | typing.SupportsIndex) -> typing.Annotated[numpy.typing.NDArray[numpy.float64], "[m, n]"]:
        ...
    def feature_points(self, gaussian: typing.SupportsInt | typing.SupportsIndex = -1) -> numpy.typing.NDArray[numpy.float64]:
        """
        (n, 3) XYZ of every map feature in one filter (default the leading one)
        """
    def predict(self, dt_s: typing.SupportsFloat | typing.SupportsIndex) -> None:
        """
        Constant-velocity prediction of every filter over dt_s seconds.
        """
    def predict_measurements(self) -> tuple[numpy.typing.NDArray[numpy.int64], numpy.typing.NDArray[numpy.float64], numpy.typing.NDArray[numpy.float64]]:
        """
        -> (ids (n,), uv (n, 2), cov (n, 2, 2)): merged predicted pixels of the features visible in the image, with covariances (pixel noise included) for active search.
        """
    def remove_features(self, ids: typing.Annotated[numpy.typing.ArrayLike, numpy.int64]) -> None:
        ...
    def set_camera_state(self, state: typing.Annotated[numpy.typing.ArrayLike, numpy.float64, "[13, 1]"], covariance: typing.Annotated[numpy.typing.ArrayLike, numpy.float64, "[13, 13]"]) -> None:
        """
        Replace [r (3), q_wc (4, w first), v (3), w (3)] and its 13x13 covariance in every filter.
        """
    def state(self, gaussian: typing.SupportsInt | typing.SupportsIndex) -> typing.Annotated[numpy.typing.NDArray[numpy.float64], "[m, 1]"]:
        """
        full state of one filter: [f, cx, cy, k1, k2, r, q, v, w, features...]
        """
    def update(self, ids: typing.Annotated[numpy.typing.ArrayLike, numpy.int64], uv: typing.Annotated[numpy.typing.ArrayLike, numpy.float64], matched: typing.Any = None) -> SogUpdateReport:
        """
        EKF update of every filter with the shared matches, weights, SPRT pruning, feature deletion and inverse-depth -> XYZ conversion. ids: features searched; uv (k, 2): measured pixels (ignored where not matched); matched (k,) bool (default all).
        """
    @property
    def accumulated_rotation_rad(self) -> float:
        ...
    @property
    def calibration_cov(self) -> typing.Annotated[numpy.typing.NDArray[numpy.float64], "[5, 5]"]:
        ...
    @property
    def calibration_covs(self) -> numpy.typing.NDArray[numpy.float64]:
        """
        (N, 5, 5) per-filter calibration covariances
        """
    @property
    def calibration_mean(self) -> typing.Annotated[numpy.typing.NDArray[numpy.float64], "[5, 1]"]:
        """
        moment-matched [f, cx, cy, k1, k2]
        """
    @property
    def calibration_means(self) -> typing.Annotated[numpy.typing.NDArray[numpy.float64], "[m, 5]"]:
        """
        (N, 5) per-filter calibration means
        """
    @property
    def camera_cov(self) -> typing.Annotated[numpy.typing.NDArray[numpy.float64], "[13, 13]"]:
        ...
    @property
    def camera_state(self) -> typing.Annotated[numpy.typing.NDArray[numpy.float64], "[13, 1]"]:
        """
        merged [r, q_wc, v, w] (13,)
        """
    @property
    def feature_ids(self) -> numpy.typing.NDArray[numpy.int64]:
        ...
    @property
    def feature_is_xyz(self) -> numpy.typing.NDArray[numpy.bool]:
        ...
    @property
    def feature_match_counts(self) -> typing.Annotated[numpy.typing.NDArray[numpy.int64], "[m, 2]"]:
        """
        (n, 2): times predicted visible (searched), times matched
        """
    @property
    def feature_offsets(self) -> numpy.typing.NDArray[numpy.int64]:
        """
        first state index of each feature
        """
    @property
    def frame(self) -> int:
        """
        number of updates so far
        """
    @property
    def gaussian_ids(self) -> list[int]:
        """
        index of each surviving Gaussian in the initial bank
        """
    @property
    def image_size(self) -> tuple[int, int]:
        ...
    @property
    def leading_gaussian(self) -> int:
        ...
    @property
    def log_weights(self) -> typing.Annotated[numpy.typing.NDArray[numpy.float64], "[m, 1]"]:
        ...
    @property
    def num_features(self) -> int:
        ...
    @property
    def num_gaussians(self) -> int:
        ...
    @property
    def options(self) -> SogOptions:
        """
        a copy (the bank's own options must not change beside an update without the GIL)
        """
    @property
    def pixel_size_mm(self) -> typing.Annotated[numpy.typing.NDArray[numpy.float64], "[2, 1]"]:
        ...
    @property
    def pruning_active(self) -> bool:
        """
        guard released, SPRT running
        """
    @property
    def sprt_accepted(self) -> numpy.typing.NDArray[numpy.bool]:
        ...
    @property
    def sprt_statistic(self) -> typing.Annotated[numpy.typing.NDArray[numpy.float64], "[m, 1]"]:
        """
        log prod L(H0)/L(H1) per Gaussian since the guard released
        """
    @property
    def state_dim(self) -> int:
        ...
    @property
    def weights(self) -> typing.Annotated[numpy.typing.NDArray[numpy.float64], "[m, 1]"]:
        ...
class BundleOptions:
    """
    Options of the self-calibration bundle adjustment (docs/sog.md §23).
    """
    compute_covariance: bool
    def __init__(self) -> None:
        ...
    @property
    def beyond_infinity_limit(self) -> float:
        """
        rho >= -beyond_infinity_limit x the median start rho (< 0: no bound)
        """
    @beyond_infinity_limit.setter
    def beyond_infinity_limit(self, arg0: typing.SupportsFloat | typing.SupportsIndex) -> None:
        ...
    @property
    def free_points_first(self) -> bool:
        """
        solve with the points free first; points ending outside the bounds are dropped while few, else solved again with Ceres' bounds
        """
    @free_points_first.setter
    def free_points_first(self, arg0: bool) -> None:
        ...
    @property
    def function_tolerance(self) -> float:
        ...
    @function_tolerance.setter
    def function_tolerance(self, arg0: typing.SupportsFloat | typing.SupportsIndex) -> None:
        ...
    @property
    def gradient_tolerance(self) -> float:
        ...
    @gradient_tolerance.setter
    def gradient_tolerance(self, arg0: typing.SupportsFloat | typing.SupportsIndex) -> None:
        ...
    @property
    def linear_solver(self) -> str:
        """
        sparse_schur (SuiteSparse) | dense_schur | iterative_schur
        """
    @linear_solver.setter
    def linear_solver(self, arg0: str) -> None:
        ...
    @property
    def max_free_iterations(self) -> int:
        """
        the free solve's iterations at most (0: no cap of its own); then on bounded
        """
    @max_free_iterations.setter
    def max_free_iterations(self, arg0: typing.SupportsInt | typing.SupportsIndex) -> None:
        ...
    @property
    def max_iterations(self) -> int:
        ...
    @max_iterations.setter
    def max_iterations(self, arg0: typing.SupportsInt | typing.SupportsIndex) -> None:
        ...
    @property
    def max_out_of_range_share(self) -> float:
        """
        the share of the points a free solve may drop for leaving the bounds
        """
    @max_out_of_range_share.setter
    def max_out_of_range_share(self, arg0: typing.SupportsFloat | typing.SupportsIndex) -> None:
        ...
    @property
    def near_limit(self) -> float:
        """
        a point stays farther from its anchor than near_limit x the median start depth (<= 0: no bound)
        """
    @near_limit.setter
    def near_limit(self, arg0: typing.SupportsFloat | typing.SupportsIndex) -> None:
        ...
    @property
    def num_threads(self) -> int:
        ...
    @num_threads.setter
    def num_threads(self, arg1: typing.SupportsInt | typing.SupportsIndex) -> None:
        ...
    @property
    def parameter_tolerance(self) -> float:
        ...
    @parameter_tolerance.setter
    def parameter_tolerance(self, arg0: typing.SupportsFloat | typing.SupportsIndex) -> None:
        ...
    @property
    def prior_pixel_sigma_px(self) -> float:
        """
        the pixel noise a line-delay prior is weighed against, px
        """
    @prior_pixel_sigma_px.setter
    def prior_pixel_sigma_px(self, arg0: typing.SupportsFloat | typing.SupportsIndex) -> None:
        ...
    @property
    def robust_loss(self) -> str:
        """
        none | huber | cauchy | soft_l1 (Ceres' losses of |r|^2 per observation)
        """
    @robust_loss.setter
    def robust_loss(self, arg0: str) -> None:
        ...
    @property
    def robust_loss_scale_px(self) -> float:
        """
        where the loss leaves its quadratic part, px
        """
    @robust_loss_scale_px.setter
    def robust_loss_scale_px(self, arg0: typing.SupportsFloat | typing.SupportsIndex) -> None:
        ...
    @property
    def scale_keyframe(self) -> int:
        """
        the keyframe whose distance from the first is held; -1: the farthest
        """
    @scale_keyframe.setter
    def scale_keyframe(self, arg0: typing.SupportsInt | typing.SupportsIndex) -> None:
        ...
    @property
    def verbose(self) -> bool:
        """
        Ceres' iteration log to stdout
        """
    @verbose.setter
    def verbose(self, arg0: bool) -> None:
        ...
class BundleResult:
    """
    The adjusted camera, line delay, poses and points; Ceres' summary; the covariances of the globals (camera parameters, then the line delay in s/row; zero rows where held).
    """
    @property
    def camera_params(self) -> typing.Annotated[numpy.typing.NDArray[numpy.float64], "[m, 1]"]:
        ...
    @property
    def converged(self) -> bool:
        ...
    @property
    def covariance_model(self) -> typing.Annotated[numpy.typing.NDArray[numpy.float64], "[m, n]"]:
        ...
    @property
    def covariance_ok(self) -> bool:
        ...
    @property
    def covariance_time_s(self) -> float:
        ...
    @property
    def covariance_tracks(self) -> typing.Annotated[numpy.typing.NDArray[numpy.float64], "[m, n]"]:
        ...
    @property
    def covariance_two_way(self) -> typing.Annotated[numpy.typing.NDArray[numpy.float64], "[m, n]"]:
        ...
    @property
    def dof(self) -> int:
        ...
    @property
    def dropped_observations(self) -> int:
        ...
    @property
    def dropped_points(self) -> int:
        ...
    @property
    def final_cost(self) -> float:
        ...
    @property
    def initial_cost(self) -> float:
        ...
    @property
    def inlier(self) -> typing.Annotated[numpy.typing.NDArray[numpy.bool], "[m, 1]"]:
        """
        (N) |r| <= the loss scale
        """
    @property
    def iterations(self) -> int:
        ...
    @property
    def keyframe_poses(self) -> typing.Annotated[numpy.typing.NDArray[numpy.float64], "[m, 6]"]:
        """
        (K, 6) [p; phi] T_cw
        """
    @property
    def line_delay_s(self) -> float:
        ...
    @property
    def message(self) -> str:
        ...
    @property
    def points(self) -> typing.Annotated[numpy.typing.NDArray[numpy.float64], "[m, 3]"]:
        """
        (P, 3) (a, b, rho) in their anchors
        """
    @property
    def points_at_bounds(self) -> int:
        """
        points whose rho ended at a bound (near_limit, beyond_infinity_limit)
        """
    @property
    def points_beyond_infinity(self) -> int:
        ...
    @property
    def points_out_of_range(self) -> int:
        """
        points dropped for ending outside the bounds in the free solve
        """
    @property
    def remaining_step(self) -> typing.Annotated[numpy.typing.NDArray[numpy.float64], "[m, 1]"]:
        ...
    @property
    def residuals_px(self) -> typing.Annotated[numpy.typing.NDArray[numpy.float64], "[m, 2]"]:
        """
        (N, 2) uv - prediction; NaN where not used
        """
    @property
    def rms_px(self) -> float:
        ...
    @property
    def scale_keyframe(self) -> int:
        ...
    @property
    def sigma_px(self) -> float:
        ...
    @property
    def solve_time_s(self) -> float:
        ...
    @property
    def solved_with_bounds(self) -> bool:
        """
        Ceres' bounds gave the result (too many points left the range)
        """
    @property
    def step_sigma(self) -> float:
        ...
    @property
    def termination(self) -> str:
        ...
    @property
    def used(self) -> typing.Annotated[numpy.typing.NDArray[numpy.bool], "[m, 1]"]:
        """
        (N) false: dropped at the start
        """
def corners_are_saddles(values: typing.Annotated[numpy.typing.NDArray[numpy.float64], "[m, 4]", "flags.c_contiguous"], even: typing.Annotated[numpy.typing.NDArray[numpy.bool], "[m, 1]"], min_contrast: typing.SupportsFloat | typing.SupportsIndex, min_gap_fraction: typing.SupportsFloat | typing.SupportsIndex) -> bool:
    """
    Whether the grey levels sampled at the saddle points ((n, 4)) show a checkerboard saddle at every corner (even: each corner's parity).
    """
def edge_profile_maps(a: typing.Annotated[numpy.typing.ArrayLike, numpy.float64, "[m, 2]"], b: typing.Annotated[numpy.typing.ArrayLike, numpy.float64, "[m, 2]"], across_rim: bool, fraction: typing.SupportsFloat | typing.SupportsIndex, profile_s: typing.Annotated[numpy.typing.ArrayLike, numpy.float64, "[m, 1]"], max_half_px: typing.SupportsFloat | typing.SupportsIndex, min_half_px: typing.SupportsFloat | typing.SupportsIndex) -> tuple[typing.Annotated[numpy.typing.NDArray[numpy.float32], "[m, n]"], typing.Annotated[numpy.typing.NDArray[numpy.float32], "[m, n]"], typing.Annotated[numpy.typing.NDArray[numpy.float64], "[m, 1]"]]:
    """
    (map_x, map_y, half_px): where cv2.remap samples an intensity profile across each target edge (a, b: its ends' pixels, (m, 2)), as float32 maps (one row per kept edge), and each profile's half length; rscalib.detection.quality.edge_width_px.
    """
def edge_width_from_profiles(profiles: typing.Annotated[numpy.typing.NDArray[numpy.float64], "[m, n]", "flags.c_contiguous"], half_px: typing.Annotated[numpy.typing.ArrayLike, numpy.float64, "[m, 1]"], min_contrast: typing.SupportsFloat | typing.SupportsIndex) -> float:
    """
    The 75th percentile of the edge widths (px) of sampled profiles (m, samples; grey levels) of half lengths half_px; NaN if no profile has more than min_contrast grey levels of contrast.
    """
def error_noise_map(line_delay_s: typing.SupportsFloat | typing.SupportsIndex, image_velocity_px_s: typing.Annotated[numpy.typing.ArrayLike, numpy.float64, "[2, 1]"]) -> typing.Annotated[numpy.typing.NDArray[numpy.float64], "[2, 2]"]:
    """
    A = I - d [[0, u_dot], [0, v_dot]] (Oth et al. 2013, eq. 15-21; docs/formulation.md §4).
    """
def evaluate_line_delay(frame_time_s: typing.Annotated[numpy.typing.ArrayLike, numpy.float64, "[m, 1]"], uv: typing.Annotated[numpy.typing.ArrayLike, numpy.float64, "[m, 2]"], point_w: typing.Annotated[numpy.typing.ArrayLike, numpy.float64, "[m, 3]"], camera: CameraModel, trajectory: BSpline, line_delay_s: typing.SupportsFloat | typing.SupportsIndex, options: RsSolverOptions) -> RsSolveSummary:
    """
    Residuals and per-segment statistics at the given estimate, without solving.
    """
def evaluate_rs_cost(trajectory: BSpline, span: typing.SupportsInt | typing.SupportsIndex, camera: CameraModel, frame_time_s: typing.SupportsFloat | typing.SupportsIndex, uv: typing.Annotated[numpy.typing.ArrayLike, numpy.float64, "[2, 1]"], point_w: typing.Annotated[numpy.typing.ArrayLike, numpy.float64, "[3, 1]"], line_delay_s: typing.SupportsFloat | typing.SupportsIndex, sqrt_information: typing.Annotated[numpy.typing.ArrayLike, numpy.float64, "[2, 2]"]) -> tuple[typing.Annotated[numpy.typing.NDArray[numpy.float64], "[2, 1]"], list[typing.Annotated[numpy.typing.NDArray[numpy.float64], "[m, n]"]]]:
    """
    Residual and autodiff Jacobians (4 x (2, 6) control points, (2, 1) line delay) of one RS reprojection cost attached to `span`.
    """
def fit_bspline(knots: collections.abc.Sequence[typing.SupportsFloat | typing.SupportsIndex], times: typing.Annotated[numpy.typing.ArrayLike, numpy.float64, "[m, 1]"], samples: typing.Annotated[numpy.typing.ArrayLike, numpy.float64, "[m, n]"], acceleration_weight: collections.abc.Sequence[typing.SupportsFloat | typing.SupportsIndex] = [], sample_weight: collections.abc.Sequence[typing.SupportsFloat | typing.SupportsIndex] = []) -> BSpline:
    """
    Least-squares cubic B-spline through (times, samples (m, N)) on the given knots:
    min sum_s w_s |x(t_s) - y_s|^2 + sum_d lambda_d * integral (x_d'')^2 dt.
    acceleration_weight: [] (none), [lambda] or one lambda per dimension.
    """
def linear_interp_pose_state(pose_a: typing.Annotated[numpy.typing.ArrayLike, numpy.float64, "[6, 1]"], pose_b: typing.Annotated[numpy.typing.ArrayLike, numpy.float64, "[6, 1]"], s: typing.SupportsFloat | typing.SupportsIndex) -> typing.Annotated[numpy.typing.NDArray[numpy.float64], "[6, 1]"]:
    """
    T_cw [p; phi] at parameter s between poses a and b: centre linear, rotation SLERP.
    """
def local_homography_residual(target_xy: typing.Annotated[numpy.typing.ArrayLike, numpy.float64, "[m, 2]"], uv: typing.Annotated[numpy.typing.ArrayLike, numpy.float64, "[m, 2]"], nearest: typing.Annotated[numpy.typing.ArrayLike, numpy.int32, "[m, n]"]) -> typing.Annotated[numpy.typing.NDArray[numpy.float64], "[m, 1]"]:
    """
    For each point (rows of target_xy and uv, (n, 2)), the distance in grid steps from its pixel to the homography of its k nearest target neighbours (nearest, (n, k) row indices), fitted by the normalised DLT; NaN where it cannot be fitted.
    """
def poses_at(pose_spline: BSpline, times: typing.Any) -> tuple[numpy.typing.NDArray[numpy.float64], numpy.typing.NDArray[numpy.float64]]:
    """
    T_cw(t) of a 6-D pose spline [p; phi] at many times: (R (m, 3, 3), p (m, 3)), x_c = R x_w + p.
    """
def rotation_matrix_to_vector(rotation: typing.Annotated[numpy.typing.ArrayLike, numpy.float64, "[3, 3]"]) -> typing.Annotated[numpy.typing.NDArray[numpy.float64], "[3, 1]"]:
    """
    phi (angle in [0, pi]) of a rotation matrix; NaN (an unknown rotation) gives NaN.
    """
def rotation_vector_to_matrix(rotation_vector: typing.Annotated[numpy.typing.ArrayLike, numpy.float64, "[3, 1]"]) -> typing.Annotated[numpy.typing.NDArray[numpy.float64], "[3, 3]"]:
    """
    R = exp([phi]x) of a rotation vector phi (radians); NaN (an unknown rotation) gives NaN.
    """
def saddle_sample_points(grid: typing.Annotated[numpy.typing.ArrayLike, numpy.float64, "[m, 2]"], rows: typing.SupportsInt | typing.SupportsIndex, cols: typing.SupportsInt | typing.SupportsIndex, fraction: typing.SupportsFloat | typing.SupportsIndex) -> tuple[typing.Annotated[numpy.typing.NDArray[numpy.float32], "[m, 4]"], typing.Annotated[numpy.typing.NDArray[numpy.float32], "[m, 4]"]]:
    """
    (map_x, map_y), (rows * cols, 4) float32: where cv2.remap samples the quadrants of each corner of a grid ((rows * cols, 2), row-major); rscalib.detection.tracking.corners_are_saddles.
    """
def solve_bundle(camera: CameraModel, keyframe_poses: typing.Annotated[numpy.typing.ArrayLike, numpy.float64], observation_keyframe: numpy.ndarray, observation_point: numpy.ndarray, uv_px: typing.Annotated[numpy.typing.ArrayLike, numpy.float64], image_velocity_px_s: typing.Annotated[numpy.typing.ArrayLike, numpy.float64], point_anchor: numpy.ndarray, points: typing.Annotated[numpy.typing.ArrayLike, numpy.float64], free_intrinsics: collections.abc.Sequence[bool] | None = None, line_delay_s: typing.SupportsFloat | typing.SupportsIndex = 0.0, estimate_line_delay: bool = False, line_delay_prior: tuple[typing.SupportsFloat | typing.SupportsIndex, typing.SupportsFloat | typing.SupportsIndex] | None = None, reference_row: typing.SupportsFloat | typing.SupportsIndex = 0.0, options: BundleOptions = ...) -> BundleResult:
    """
    The self-calibration bundle adjustment (docs/sog.md §23): keyframe_poses (K, 6) [p; phi] T_cw; per observation its keyframe, point, uv_px (N, 2) and image_velocity_px_s (N, 2); per point its anchor keyframe and (a, b, rho) (P, 3). free_intrinsics: per camera parameter (None: all). The line delay (s/row) is held at line_delay_s, estimated from it (estimate_line_delay), or estimated with a Gaussian prior (mean_s, sigma_s). reference_row: v_ref of the rolling-shutter shift. Returns a BundleResult.
    """
def solve_line_delay(frame_time_s: typing.Annotated[numpy.typing.ArrayLike, numpy.float64, "[m, 1]"], uv: typing.Annotated[numpy.typing.ArrayLike, numpy.float64, "[m, 2]"], point_w: typing.Annotated[numpy.typing.ArrayLike, numpy.float64, "[m, 3]"], camera: CameraModel, trajectory: BSpline, line_delay_s: typing.SupportsFloat | typing.SupportsIndex, options: RsSolverOptions) -> RsSolveSummary:
    """
    Refines trajectory (in place) and the line delay; returns an RsSolveSummary.
    """
def solve_line_delay_linear(frame_index: typing.Annotated[numpy.typing.ArrayLike, numpy.int32, "[m, 1]"], uv: typing.Annotated[numpy.typing.ArrayLike, numpy.float64, "[m, 2]"], point_w: typing.Annotated[numpy.typing.ArrayLike, numpy.float64, "[m, 3]"], frame_time_s: typing.Annotated[numpy.typing.ArrayLike, numpy.float64, "[m, 1]"], camera: CameraModel, frame_poses: typing.Annotated[numpy.typing.ArrayLike, numpy.float64, "[m, 6]"], line_delay_s: typing.SupportsFloat | typing.SupportsIndex, options: LinearInterpOptions) -> tuple[LinearInterpSummary, typing.Annotated[numpy.typing.NDArray[numpy.float64], "[m, 6]"]]:
    """
    Per-frame poses (F, 6) [p; phi] T_cw at the frames' row-0 times, and the line delay, with linear/SLERP interpolation between consecutive frames. Returns (summary, poses).
    """
def standardisation_weight(line_delay_s: typing.SupportsFloat | typing.SupportsIndex, image_velocity_px_s: typing.Annotated[numpy.typing.ArrayLike, numpy.float64, "[2, 1]"], pixel_sigma: typing.SupportsFloat | typing.SupportsIndex, max_rs_gain: typing.SupportsFloat | typing.SupportsIndex = 0.8) -> tuple[typing.Annotated[numpy.typing.NDArray[numpy.float64], "[2, 2]"], bool]:
    """
    (W, clamped) with W^T W = (A R A^T)^-1.
    """
def unwrap_rotation_vectors(rotation_vectors: typing.Annotated[numpy.typing.ArrayLike, numpy.float64, "[m, 3]"]) -> typing.Annotated[numpy.typing.NDArray[numpy.float64], "[m, 3]"]:
    """
    Paper eq. 22: make a (n, 3) sequence of rotation vectors continuous (2*pi per axis); NaN rows (unknown rotations) stay NaN.
    """
__version__: str = '0.1.0'
