"""Property-based fuzzing (Hypothesis) of every `_core` entry point that takes arrays or numbers (issue #14).

Inputs: NaN, inf, huge and tiny numbers, empty arrays, wrong shapes and dtypes, non-contiguous arrays,
absurd sizes and counts, negative sizes, non-increasing knots; each drawn example corrupts one or two
arguments of a valid call, so the checks behind the first one are reached too. Every call must return
or raise ValueError (rscalib's InputError) or TypeError; anything else, a crash, or an attempt to
allocate an absurd amount of memory (the child runs under an address-space limit, so it would surface
as MemoryError) fails.

Each test runs its Hypothesis body in a child interpreter (this file run as a script) with a fixed
derandomised seed and a bounded number of examples, so a segfault fails the test instead of killing
the run. On a crash the child's faulthandler traceback names the entry point.
"""
import math
import os
import re
import subprocess
import sys

import numpy as np
import pytest

CHILD_ADDRESS_SPACE_BYTES = 6 << 30  # absurd sizes must be refused, not allocated
ACCEPTED = (ValueError, TypeError)

# target -> examples; the whole file takes well under a minute on 2 cores
TARGETS = {
    "spline_construct": 250,
    "spline_methods": 250,
    "fit_bspline": 150,
    "geometry": 200,
    "camera_construct": 200,
    "camera_methods": 250,
    "line_delay": 120,
    "rs_terms": 200,
    "line_delay_linear": 120,
    "sog_construct": 150,
    "sog_methods": 150,
    "absurd_sizes": 1,
}


@pytest.mark.parametrize("target", sorted(TARGETS))
def test_core_entry_points_never_abort(target):
    result = subprocess.run([sys.executable, __file__, target], capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, (f"fuzz target {target}: exit {result.returncode} "
                                    f"({'signal ' + str(-result.returncode) if result.returncode < 0 else 'failure'})"
                                    f"\nstdout:\n{result.stdout[-4000:]}\nstderr:\n{result.stderr[-4000:]}")
    if target != "absurd_sizes":  # the examples reach both the refusals and the computations behind them
        returned, refused = (int(v) for v in re.findall(r"returned=(\d+) refused=(\d+)", result.stdout)[0])
        assert returned > 0 and refused > 0, result.stdout[-500:]


# ------------------------------------------------------------------------------------ child side


def _child(target):  # noqa: C901 - one strategy per entry point, kept together on purpose
    import faulthandler
    import resource

    from hypothesis import HealthCheck, given, note, settings
    from hypothesis import strategies as st
    from hypothesis.extra import numpy as hnp

    from rscalib import _core

    faulthandler.enable()
    resource.setrlimit(resource.RLIMIT_AS, (CHILD_ADDRESS_SPACE_BYTES, CHILD_ADDRESS_SPACE_BYTES))

    # ------------------------------------------------------------------ wild values
    special = [0.0, -0.0, 1e-300, -1e-300, 5e-324, 1e308, -1e308, math.nan, math.inf, -math.inf]
    floats = st.one_of(st.sampled_from(special), st.floats(allow_nan=True, allow_infinity=True),
                       st.floats(-10, 10))
    big_ints = [-(2 ** 63), -(2 ** 31), -1, 0, 2 ** 31 - 1, 2 ** 31, 2 ** 63 - 1, 2 ** 64, 10 ** 6, 10 ** 9]
    ints = st.one_of(st.integers(-3, 12), st.sampled_from(big_ints))
    numbers = st.one_of(floats, ints, st.none(), st.text(max_size=2))
    dtypes = st.sampled_from([np.float64, np.float32, np.int64, np.int32, np.bool_, np.complex128, np.uint8])

    @st.composite
    def any_array(draw, width=None, like=None):
        """An array: `like` with a few values made wild, or of shape (n, width), or of any dtype and shape;
        maybe non-contiguous (strided, Fortran order, transposed) or a nested list."""
        modes = (["like", "like"] if like is not None else []) + (["width"] if width is not None else []) + ["any"]
        mode = draw(st.sampled_from(modes))
        if mode == "like":
            array = np.array(like, dtype=draw(st.sampled_from([np.float64, np.float64, np.float32])))
            if array.size:
                for index in draw(st.lists(st.integers(0, array.size - 1), max_size=3)):
                    array.flat[index] = draw(floats)
        elif mode == "width":
            shape = draw(st.sampled_from([(draw(st.integers(0, 6)), width), (width,), (0, width)]))
            array = draw(hnp.arrays(np.float64, shape, elements=st.one_of(st.floats(-1e3, 1e3), floats)))
        else:
            dtype = draw(dtypes)
            shape = draw(hnp.array_shapes(min_dims=0, max_dims=3, min_side=0, max_side=5))
            elements = floats if np.dtype(dtype).kind == "f" else None
            array = draw(hnp.arrays(dtype, shape, elements=elements))
        layouts = ["contiguous", "strided", "list", "fortran"] + (["transposed"] if mode == "any" else [])
        layout = draw(st.sampled_from(layouts))
        if layout == "strided" and array.ndim:
            array = np.repeat(array, 2, axis=-1)[..., ::2]
        elif layout == "transposed":
            array = array.T
        elif layout == "fortran":
            array = np.asfortranarray(array)
        elif layout == "list":
            return array.tolist()
        return array

    def wild_array(width=None, like=None):
        """Mostly arrays; a tenth of the time a number, None or text instead."""
        return st.integers(0, 9).flatmap(lambda k: numbers if k == 0 else any_array(width, like))

    @st.composite
    def mutated(draw, valid, wild):
        """`valid` (name -> value) with one or two entries replaced by draws from `wild`."""
        args = dict(valid)
        for name in draw(st.lists(st.sampled_from(sorted(wild)), min_size=1, max_size=2, unique=True)):
            args[name] = draw(wild[name])
        return args

    outcomes = {"returned": 0, "refused": 0}

    def call(fn, *args, **kwargs):
        try:
            fn(*args, **kwargs)
            outcomes["returned"] += 1
        except ACCEPTED:
            outcomes["refused"] += 1

    # RSCALIB_FUZZ_SCALE=10 for a longer campaign by hand (same seeds, more examples).
    examples = int(TARGETS[target] * float(os.environ.get("RSCALIB_FUZZ_SCALE", "1")))

    def fuzz(strategy):
        def decorate(body):
            return settings(max_examples=examples, derandomize=True, deadline=None, database=None,
                            suppress_health_check=list(HealthCheck))(given(strategy)(body))
        return decorate

    # ------------------------------------------------------------------ valid samples
    def spline(dimension=6, segments=4):
        s = _core.BSpline.uniform(0.0, 1.0, segments, dimension)
        row = np.zeros(dimension)
        row[min(2, dimension - 1)] = 1.0  # 6-D: 1 m in front of the target
        s.control_points = np.tile(row, (segments + 3, 1))
        return s

    pinhole = _core.CameraModel("pinhole-radtan", [300.0, 300.0, 160.0, 120.0], 320, 240)
    cameras = [pinhole,
               _core.CameraModel("pinhole-equidistant", [300.0, 300.0, 160.0, 120.0, 0.01, 0, 0, 0], 320, 240),
               _core.CameraModel("civera-radial", [200.0, 160.0, 120.0, 0.01, 0.001], 320, 240, [0.0112, 0.0112])]
    grid = np.stack(np.meshgrid([-0.2, 0.0, 0.2], [-0.1, 0.0, 0.1]), -1).reshape(-1, 2)
    points_w = np.tile(np.column_stack([grid, np.zeros(9)]), (3, 1))
    frame_times = np.repeat([0.2, 0.5, 0.8], 9)
    uv = pinhole.project(points_w + [0.0, 0.0, 1.0])
    sigmas = np.array([7.5, 10 / 3, 10 / 3, 0.02, 0.00225])

    def wild_options(cls, lengths):
        """An options object with about a quarter of its fields (every settable field is a candidate, by
        the type of its default) set to wild values; setting may itself be refused. `lengths`: valid
        lengths of array fields (e.g. one sigma per observation), so those are reached too."""
        defaults = cls()
        strategies = {}
        for name, member in vars(cls).items():
            if not (isinstance(member, property) and member.fset):
                continue
            value = getattr(defaults, name)
            if isinstance(value, bool):
                strategies[name] = st.booleans()
            elif isinstance(value, int):
                strategies[name] = ints
            elif isinstance(value, float):
                strategies[name] = st.one_of(floats, ints)
            elif isinstance(value, str):
                strategies[name] = st.one_of(st.sampled_from(["none", "huber", "cauchy"]), st.text(max_size=6))
            elif isinstance(value, list):
                strategies[name] = list_of(ints)
            else:
                like = np.ones(lengths.get(name, value.shape)) if name in lengths else value
                strategies[name] = wild_array(like=like if np.size(like) else None)

        @st.composite
        def build(draw):
            o = cls()
            drawn = {}
            for name in sorted(strategies):
                if draw(st.integers(0, 3)) == 0:
                    drawn[name] = draw(strategies[name])
                    try:
                        setattr(o, name, drawn[name])
                    except ACCEPTED:
                        pass
            note(f"{cls.__name__} fields set: {drawn}")  # shown with a failing example
            return o
        return build()

    def list_of(strategy):
        return st.one_of(st.lists(strategy, max_size=8), numbers)

    # ------------------------------------------------------------------ targets
    if target == "spline_construct":
        @fuzz(st.one_of(
            st.tuples(st.just("init"), st.one_of(list_of(floats), wild_array()), wild_array(6)),
            st.tuples(st.just("init_sorted"), st.lists(floats, min_size=4, max_size=12).map(sorted), wild_array(2)),
            st.tuples(st.just("init_clamped"), st.sampled_from([[0.0, 1.0], [0.0, 0.5, 1.0], [0.0, 0.5, 0.5, 0.5, 1.0]]),
                      wild_array(like=np.ones((6, 2)))),
            st.tuples(st.just("uniform"), st.tuples(numbers, numbers, ints, ints)),
            st.tuples(st.just("clamped"), st.one_of(list_of(floats), wild_array())),
            st.tuples(st.just("setstate"), st.one_of(st.tuples(list_of(floats), wild_array(2)),
                                                     st.tuples(), st.tuples(numbers), numbers))))
        def body(case):
            kind = case[0]
            if kind in ("init", "init_sorted"):
                call(_core.BSpline, case[1], case[2])
            elif kind == "init_clamped":  # valid knots; the control points may be too few, NaN, ...
                knots = [case[1][0]] * 3 + case[1] + [case[1][-1]] * 3
                call(_core.BSpline, knots, case[2])
                call(_core.BSpline, knots, np.ones((len(knots) - 4, 2)))
            elif kind == "uniform":
                call(_core.BSpline.uniform, *case[1])
            elif kind == "clamped":
                call(_core.BSpline.clamped_knots, case[1])
            else:
                call(_core.BSpline.__new__(_core.BSpline).__setstate__, case[1])

    elif target == "spline_methods":
        @fuzz(st.tuples(st.sampled_from(["evaluate", "span_at", "segment_at", "basis", "insert_knot",
                                         "control_points", "poses_at"]),
                        st.one_of(wild_array(like=np.linspace(0.0, 1.0, 5)), floats), ints,
                        st.sampled_from([1, 3, 6])))
        def body(case):
            method, value, derivative, dimension = case
            s = spline(dimension)
            if method == "evaluate":
                call(s.evaluate, value, derivative)
            elif method == "control_points":
                try:
                    s.control_points = value
                except ACCEPTED:
                    pass
            elif method == "poses_at":
                call(_core.poses_at, s, value)
            elif method == "insert_knot":
                for _ in range(3):  # repeated knots too
                    call(s.insert_knot, value)
                call(s.evaluate, np.linspace(0.0, 1.0, 7))
            else:
                call(getattr(s, method), value)

    elif target == "fit_bspline":
        valid = {"knots": _core.BSpline.clamped_knots([0.0, 0.5, 1.0]), "times": np.linspace(0, 1, 11),
                 "samples": np.zeros((11, 2)), "acceleration_weight": [1e-3], "sample_weight": np.ones(11).tolist()}
        wild = {"knots": st.one_of(list_of(floats), wild_array(like=valid["knots"])),
                "times": wild_array(like=valid["times"]), "samples": wild_array(2, like=np.ones((11, 2))),
                "acceleration_weight": list_of(floats), "sample_weight": st.one_of(list_of(floats),
                                                                                   wild_array(like=np.ones(11)))}

        @fuzz(mutated(valid, wild))
        def body(args):
            call(_core.fit_bspline, **args)

    elif target == "geometry":
        @fuzz(st.tuples(st.sampled_from(["unwrap", "to_matrix", "to_vector"]),
                        wild_array(3, like=[[0.1, 3.0, 0.0], [0.1, -3.1, 0.0], [6.0, 0.0, 0.0]]),
                        hnp.arrays(np.float64, (3, 3), elements=floats)))
        def body(case):
            kind, value, matrix = case
            if kind == "unwrap":
                call(_core.unwrap_rotation_vectors, value)
            elif kind == "to_matrix":
                call(_core.rotation_vector_to_matrix, value)
            else:
                call(_core.rotation_matrix_to_vector, value)
                call(_core.rotation_matrix_to_vector, matrix)

    elif target == "camera_construct":
        valid = {"model": "civera-radial", "params": [200.0, 160.0, 120.0, 0.01, 0.001], "width": 320,
                 "height": 240, "pixel_size_mm": [0.0112, 0.0112]}
        wild = {"model": st.one_of(st.sampled_from(["pinhole-radtan", "pinhole-equidistant", "civera-radial", ""]),
                                   st.text(max_size=4), numbers),
                "params": st.one_of(list_of(floats), wild_array()), "width": numbers, "height": numbers,
                "pixel_size_mm": wild_array(2)}

        @fuzz(st.one_of(mutated(valid, wild).map(lambda a: ("init", a)),
                        st.tuples(st.just("setstate"), st.one_of(st.tuples(*[wild[k] for k in valid]),
                                                                 st.tuples(), numbers))))
        def body(case):
            if case[0] == "init":
                call(_core.CameraModel, **case[1])
            else:
                call(_core.CameraModel.__new__(_core.CameraModel).__setstate__, case[1])

    elif target == "camera_methods":
        @fuzz(st.tuples(st.sampled_from(range(3)),
                        st.sampled_from(["project", "project_with_jacobians", "unproject", "distort", "undistort"]),
                        st.one_of(wild_array(3, like=[[0.1, 0.0, 1.0], [-0.2, 0.3, 2.0], [0.0, 0.0, 0.0]]),
                                  wild_array(2, like=[[150.0, 100.0], [0.0, 0.0], [320.0, 240.0]]))))
        def body(case):
            camera_index, method, value = case
            call(getattr(cameras[camera_index], method), value)

    elif target == "line_delay":
        valid = {"frame_time_s": frame_times, "uv": uv, "point_w": points_w, "camera": pinhole,
                 "trajectory": None, "line_delay_s": 0.0, "options": _core.RsSolverOptions()}
        options = wild_options(_core.RsSolverOptions, {"observation_sigma": 27, "motion_prior_q": 6,
                                                       "intrinsics_prior_mean": 9,
                                                       "intrinsics_prior_covariance": (9, 9)})
        wild = {"frame_time_s": wild_array(like=frame_times), "uv": wild_array(2, like=uv),
                "point_w": wild_array(3, like=points_w), "camera": st.sampled_from(cameras),
                "trajectory": st.sampled_from([(6, 4), (3, 4), (6, 1), (1, 1)]),
                "line_delay_s": numbers, "options": options}

        @fuzz(st.tuples(st.booleans(), mutated(valid, wild)))
        def body(case):
            solve, args = case
            args["trajectory"] = spline(*(args["trajectory"] or (6, 4)))
            call(_core.solve_line_delay if solve else _core.evaluate_line_delay, **args)

    elif target == "rs_terms":
        valid = {"trajectory": spline(), "span": 4, "camera": pinhole, "frame_time_s": 0.5, "uv": uv[0],
                 "point_w": points_w[0], "line_delay_s": 1e-5, "sqrt_information": np.eye(2)}
        wild = {"trajectory": st.sampled_from([spline(3), spline(6, 1)]), "span": ints, "frame_time_s": numbers,
                "uv": wild_array(like=uv[0]), "point_w": wild_array(like=points_w[0]), "line_delay_s": numbers,
                "sqrt_information": wild_array(2, like=np.eye(2)), "camera": st.sampled_from(cameras)}

        @fuzz(st.tuples(mutated(valid, wild), numbers, wild_array(like=[30.0, -20.0]), numbers, numbers))
        def body(case):
            args, d, velocity, sigma, gain = case
            call(_core.evaluate_rs_cost, **args)
            call(_core.error_noise_map, d, velocity)
            call(_core.standardisation_weight, d, velocity, sigma, gain)
            call(_core.linear_interp_pose_state, velocity, args["uv"], d)

    elif target == "line_delay_linear":
        valid = {"frame_index": np.repeat(np.arange(3, dtype=np.int32), 9), "uv": uv, "point_w": points_w,
                 "frame_time_s": np.array([0.2, 0.5, 0.8]), "camera": pinhole,
                 "frame_poses": np.tile([0.0, 0.0, 1.0, 0.0, 0.0, 0.0], (3, 1)), "line_delay_s": 0.0,
                 "options": _core.LinearInterpOptions()}
        wild = {"frame_index": st.one_of(wild_array(), hnp.arrays(np.int32, 27, elements=st.integers(-5, 5))),
                "uv": wild_array(2, like=uv), "point_w": wild_array(3, like=points_w),
                "frame_time_s": wild_array(like=valid["frame_time_s"]),
                "frame_poses": wild_array(6, like=valid["frame_poses"]), "line_delay_s": numbers,
                "camera": st.sampled_from(cameras),
                "options": wild_options(_core.LinearInterpOptions, {})}

        @fuzz(mutated(valid, wild))
        def body(args):
            call(_core.solve_line_delay_linear, **args)

    elif target == "sog_construct":
        valid = {"options": _core.SogOptions(), "initial_means": np.array([[200.0, 160, 120, 0, 0]]),
                 "initial_covs": np.diag(sigmas ** 2)[None], "initial_weights": np.ones(1),
                 "image_size": (320, 240), "pixel_size_mm": 0.0112}
        wild = {"options": wild_options(_core.SogOptions, {}),
                "initial_means": wild_array(5, like=valid["initial_means"]),
                "initial_covs": wild_array(like=valid["initial_covs"]),
                "initial_weights": wild_array(like=valid["initial_weights"]),
                "image_size": st.one_of(st.tuples(ints, ints), numbers), "pixel_size_mm": wild_array()}

        @fuzz(mutated(valid, wild))
        def body(args):
            try:
                bank = _core.SogBank(**args)
            except ACCEPTED:
                outcomes["refused"] += 1
                return
            outcomes["returned"] += 1
            # A bank that was accepted must also run a frame.
            call(bank.add_features, np.array([[100.0, 100.0], [200.0, 150.0]]))
            call(bank.predict, 1 / 30)
            try:
                ids, predicted, _ = bank.predict_measurements()
                bank.update(ids, predicted)
            except ACCEPTED:
                pass

    elif target == "sog_methods":
        means = np.array([[190.0, 160.0, 120.0, 0.0, 0.0], [220.0, 160.0, 120.0, 0.0, 0.0]])
        covs = np.tile(np.diag(sigmas ** 2), (2, 1, 1))
        features_uv = np.array([[100.0, 100.0], [200.0, 150.0], [60.0, 200.0]])

        @fuzz(st.lists(st.tuples(st.sampled_from(["set_camera_state", "predict", "update", "add_features",
                                                  "remove_features", "state", "covariance", "feature_points"]),
                                 wild_array(like=[0, 1, 2]), wild_array(2, like=features_uv),
                                 st.one_of(st.none(), wild_array(like=[True, False, True])), numbers),
                       min_size=1, max_size=4))
        def body(steps):
            bank = _core.SogBank(_core.SogOptions(), means, covs, np.array([0.5, 0.5]), (320, 240), 0.0112)
            bank.add_features(features_uv)
            for method, array, rows, extra, number in steps:
                if method == "set_camera_state":
                    call(bank.set_camera_state, array, rows)
                elif method == "update":
                    call(bank.update, array, rows, extra)
                    call(bank.update, bank.feature_ids, rows, extra)
                elif method == "add_features":
                    call(bank.add_features, rows)
                elif method == "remove_features":
                    call(bank.remove_features, array)
                elif method == "predict":
                    call(bank.predict, number)
                else:
                    call(getattr(bank, method), number)
                call(bank.predict, 1 / 30)
                call(bank.predict_measurements)

    elif target == "absurd_sizes":
        def body():
            """Sizes that would need far more memory (or threads, or time) than any machine has: refused."""
            bank = _core.SogBank(_core.SogOptions(), np.array([[200.0, 160, 120, 0, 0]]),
                                 np.diag(sigmas ** 2)[None], np.ones(1), (320, 240), 0.0112)
            rng = np.random.default_rng(0)
            cases = {
                "BSpline.uniform(num_segments=1e9)": lambda: _core.BSpline.uniform(0.0, 1.0, 10 ** 9, 6),
                "BSpline.uniform(num_segments=2**31-1)": lambda: _core.BSpline.uniform(0.0, 1.0, 2 ** 31 - 1, 1),
                "BSpline.uniform(dimension=1e9)": lambda: _core.BSpline.uniform(0.0, 1.0, 4, 10 ** 9),
                "BSpline.uniform(1e5 segments, 1e5 dimensions)": lambda: _core.BSpline.uniform(0, 1, 10 ** 5, 10 ** 5),
                "SogBank.add_features(1e5 pixels)": lambda: bank.add_features(rng.uniform(10, 230, (10 ** 5, 2))),
            }
            sog_args = (np.array([[200.0, 160, 120, 0, 0]]), np.diag(sigmas ** 2)[None], np.ones(1), (320, 240),
                        0.0112)
            linear_args = (np.repeat(np.arange(3, dtype=np.int32), 9), uv, points_w, np.array([0.2, 0.5, 0.8]),
                           pinhole, np.tile([0.0, 0.0, 1.0, 0.0, 0.0, 0.0], (3, 1)), 0.0)

            def with_option(cls, field, value, run):
                def go():
                    o = cls()
                    setattr(o, field, value)  # refused here or by `run`
                    run(o)
                return go

            cases.update({
                "SogOptions.update_iterations=1e9": with_option(
                    _core.SogOptions, "update_iterations", 10 ** 9, lambda o: _core.SogBank(o, *sog_args)),
                "SogOptions.ransac_hypotheses=1e9": with_option(
                    _core.SogOptions, "ransac_hypotheses", 10 ** 9, lambda o: _core.SogBank(o, *sog_args)),
                "SogOptions.num_threads=1e6": with_option(
                    _core.SogOptions, "num_threads", 10 ** 6, lambda o: _core.SogBank(o, *sog_args).predict(0.1)),
                "RsSolverOptions.num_threads=1e6": with_option(
                    _core.RsSolverOptions, "num_threads", 10 ** 6,
                    lambda o: _core.solve_line_delay(frame_times, uv, points_w, pinhole, spline(), 0.0, o)),
                "LinearInterpOptions.num_threads=1e6": with_option(
                    _core.LinearInterpOptions, "num_threads", 10 ** 6,
                    lambda o: _core.solve_line_delay_linear(*linear_args, o)),
            })
            accepted = [name for name, fn in cases.items() if _accepts(fn)]
            assert not accepted, f"absurd sizes accepted or not refused cleanly: {accepted}"

    body()
    print(f"outcomes: returned={outcomes['returned']} refused={outcomes['refused']}")


def _accepts(fn):
    """True when fn returned (the absurd request was not refused); an exception other than
    ValueError/TypeError propagates (a MemoryError means it tried to allocate)."""
    try:
        fn()
    except ACCEPTED as error:
        print(f"refused: {error}")
        return False
    return True


if __name__ == "__main__":
    _child(sys.argv[1])
