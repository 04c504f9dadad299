"""Safety of the `_core` bindings from plain Python (issue #14).

- An instance made by `Cls.__new__(Cls)` (no `__init__`) has no C++ object: every method and property
  of every class, and every function taking it as an argument, must raise TypeError instead of handing
  C++ raw memory.
- Objects whose methods run without the GIL (`SogBank`, `BSpline`) are shared between threads: calls
  must serialise. Oracle for the spline: knot insertion leaves the curve unchanged (Boehm), so every
  evaluation from any thread must equal the curve before the insertions.

Each check runs this file as a script in a child interpreter, so a segfault fails the test (exit code
-11) instead of killing the test run.
"""
import inspect
import re
import subprocess
import sys
import threading

import numpy as np

from rscalib import _core

THREADS = 4


def _run_child(mode, timeout_s=120):
    result = subprocess.run([sys.executable, __file__, mode], capture_output=True, text=True, timeout=timeout_s)
    assert result.returncode == 0, (f"child `{mode}` exited with {result.returncode}\n"
                                    f"stdout:\n{result.stdout[-3000:]}\nstderr:\n{result.stderr[-3000:]}")
    return result.stdout


# ------------------------------------------------------------------------------------ sample objects


def _civera_camera():
    return _core.CameraModel("civera-radial", [200.0, 160.0, 120.0, 0.01, 0.001], 320, 240, [0.0112, 0.0112])


def _bank():
    sigmas = np.array([7.5, 10 / 3, 10 / 3, 0.02, 0.00225])
    means = np.array([[190.0, 160.0, 120.0, 0.0, 0.0], [220.0, 160.0, 120.0, 0.0, 0.0]])
    covs = np.tile(np.diag(sigmas ** 2), (2, 1, 1))
    return _core.SogBank(_core.SogOptions(), means, covs, np.array([0.5, 0.5]), (320, 240), 0.0112)


def _line_delay_problem():
    """A camera 1 m in front of a 3x3 grid on z = 0, at rest: arguments of the line-delay functions."""
    camera = _core.CameraModel("pinhole-radtan", [300.0, 300.0, 160.0, 120.0], 320, 240)
    trajectory = _core.BSpline.uniform(0.0, 1.0, 2, 6)
    trajectory.control_points = np.tile([0.0, 0.0, 1.0, 0.0, 0.0, 0.0], (5, 1))
    grid = np.stack(np.meshgrid([-0.2, 0.0, 0.2], [-0.1, 0.0, 0.1]), -1).reshape(-1, 2)
    points = np.column_stack([grid, np.zeros(len(grid))])
    frames = np.repeat([0.2, 0.5, 0.8], len(points))
    points_w = np.tile(points, (3, 1))
    uv = camera.project(points_w + [0.0, 0.0, 1.0])
    return camera, trajectory, frames, uv, points_w


def _bundle_args():
    """Positional arguments of solve_bundle: three keyframes looking at a 5 x 4 grid 3 m ahead."""
    camera = _civera_camera()
    grid = np.stack(np.meshgrid(np.linspace(-1, 1, 5), np.linspace(-0.6, 0.6, 4)), -1).reshape(-1, 2)
    points = np.column_stack([grid, np.full(len(grid), 3.0)])
    poses = np.array([[0.0, 0, 0, 0, 0, 0], [-0.5, 0, 0, 0, 0, 0], [-0.2, 0.1, 0.1, 0, 0, 0]])
    uv = np.vstack([camera.project(points + pose[:3]) for pose in poses])
    abr = np.column_stack([points[:, :2] / 3.0, np.full(len(points), 1 / 3.0)])
    return (camera, poses, np.repeat(np.arange(3), len(points)), np.tile(np.arange(len(points)), 3), uv,
            np.zeros_like(uv), np.zeros(len(points), np.int64), abr, None, 0.0, False, None, 119.5,
            _core.BundleOptions())


def _calls():
    """Per class: (factory of an initialised instance, {method name: call(obj)}). Properties need no entry."""
    camera, trajectory, frames, uv, points_w = _line_delay_problem()
    summary = _core.evaluate_line_delay(frames, uv, points_w, camera, trajectory, 0.0, _core.RsSolverOptions())
    frame_index = np.repeat(np.arange(3, dtype=np.int32), 9)
    poses = np.tile([0.0, 0.0, 1.0, 0.0, 0.0, 0.0], (3, 1))
    linear_args = (frame_index, uv, points_w, np.array([0.2, 0.5, 0.8]), camera, poses, 0.0)

    def report():
        bank = _bank()
        bank.add_features(np.array([[100.0, 100.0], [200.0, 150.0]]))
        bank.predict(1 / 30)
        ids, predicted, _ = bank.predict_measurements()
        return bank.update(ids, predicted)

    def bank_with_features():
        bank = _bank()
        bank.add_features(np.array([[100.0, 100.0], [200.0, 150.0]]))
        return bank

    state = np.array([0, 0, 0, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0], dtype=float)
    spline = {
        "evaluate": lambda s: s.evaluate(0.5), "span_at": lambda s: s.span_at(0.5),
        "segment_at": lambda s: s.segment_at(0.5), "basis": lambda s: s.basis(0.5),
        "insert_knot": lambda s: s.insert_knot(0.3), "copy": lambda s: s.copy(),
        "__copy__": lambda s: s.__copy__(), "__deepcopy__": lambda s: s.__deepcopy__({}),
        "__repr__": repr, "__getstate__": lambda s: s.__getstate__(),
    }
    cam = {
        "project": lambda c: c.project([[0.1, 0.0, 1.0]]),
        "project_with_jacobians": lambda c: c.project_with_jacobians([[0.1, 0.0, 1.0]]),
        "unproject": lambda c: c.unproject([[150.0, 100.0]]), "distort": lambda c: c.distort([[150.0, 100.0]]),
        "undistort": lambda c: c.undistort([[150.0, 100.0]]), "__repr__": repr,
        "__getstate__": lambda c: c.__getstate__(),
    }
    bank = {
        "set_camera_state": lambda b: b.set_camera_state(state, np.eye(13) * 1e-6),
        "predict": lambda b: b.predict(1 / 30), "predict_measurements": lambda b: b.predict_measurements(),
        "update": lambda b: b.update(np.array([0]), np.array([[100.0, 100.0]])),
        "add_features": lambda b: b.add_features(np.array([[50.0, 60.0]])),
        "remove_features": lambda b: b.remove_features(np.array([1])),
        "state": lambda b: b.state(0), "covariance": lambda b: b.covariance(0),
        "calibration_bounds_99": lambda b: b.calibration_bounds_99(), "feature_points": lambda b: b.feature_points(),
    }
    return {
        _core.BSpline: (lambda: _core.BSpline.uniform(0.0, 1.0, 3, 2), spline),
        _core.CameraModel: (_civera_camera, cam),
        _core.SogBank: (bank_with_features, bank),
        _core.SogOptions: (_core.SogOptions, {"__repr__": repr}),
        _core.SogUpdateReport: (report, {}),
        _core.RsSolverOptions: (_core.RsSolverOptions, {}),
        _core.RsSolveSummary: (lambda: summary, {}),
        _core.LinearInterpOptions: (_core.LinearInterpOptions, {}),
        _core.BundleOptions: (_core.BundleOptions, {}),
        _core.BundleResult: (lambda: _core.solve_bundle(*_bundle_args()), {}),
        _core.LinearInterpSummary: (lambda: _core.solve_line_delay_linear(
            *linear_args, _core.LinearInterpOptions())[0], {}),
    }


def _bound_classes():
    return [c for c in vars(_core).values() if inspect.isclass(c) and not issubclass(c, BaseException)]


def _members(cls):
    """Instance methods and properties of a bound class (no statics, no pybind11 internals)."""
    kept = {"__repr__", "__copy__", "__deepcopy__", "__getstate__"}
    out = {}
    for name, value in vars(cls).items():
        if (name.startswith("_") and name not in kept) or isinstance(value, staticmethod):
            continue
        out[name] = value
    return out


def _expect_uninitialised(failures, what, call):
    failures.checked += 1
    try:
        call()
    except TypeError as error:
        if "not initialised" not in str(error):
            failures.append(f"{what}: TypeError without the reason: {error}")
    except Exception as error:  # noqa: BLE001 - any other outcome is a failure to report
        failures.append(f"{what}: {type(error).__name__}: {error}")
    else:
        failures.append(f"{what}: no exception")


class _Failures(list):
    checked = 0


def _child_uninitialised():
    failures = _Failures()
    calls = _calls()
    for cls in _bound_classes():
        if cls not in calls:
            failures.append(f"{cls.__name__}: no sample calls (add it to _calls)")
            continue
        make, methods = calls[cls]
        for name, member in _members(cls).items():
            what = f"{cls.__name__}.{name}"
            if isinstance(member, property):
                value = getattr(make(), name)  # the sample works on a constructed instance
                _expect_uninitialised(failures, what + " (get)", lambda n=name, k=cls: getattr(k.__new__(k), n))
                if member.fset is not None:
                    _expect_uninitialised(failures, what + " (set)",
                                          lambda n=name, v=value, k=cls: setattr(k.__new__(k), n, v))
            elif name not in methods:
                failures.append(f"{what}: no sample call (add it to _calls)")
            else:
                methods[name](make())
                _expect_uninitialised(failures, what, lambda c=methods[name], k=cls: c(k.__new__(k)))
    # Uninitialised instances as arguments of functions and constructors.
    camera, trajectory, frames, uv, points_w = _line_delay_problem()
    options = _core.RsSolverOptions()
    new = {c: c.__new__(c) for c in _bound_classes()}
    args = {
        "solve_line_delay": (frames, uv, points_w, camera, trajectory.copy(), 0.0, options),
        "evaluate_line_delay": (frames, uv, points_w, camera, trajectory, 0.0, options),
        "evaluate_rs_cost": (trajectory, 3, camera, 0.5, uv[0], points_w[0], 0.0, np.eye(2)),
        "poses_at": (trajectory, np.array([0.5])),
        "solve_line_delay_linear": (np.repeat(np.arange(3, dtype=np.int32), 9), uv, points_w,
                                    np.array([0.2, 0.5, 0.8]), camera, np.tile([0, 0, 1.0, 0, 0, 0], (3, 1)), 0.0,
                                    _core.LinearInterpOptions()),
        "solve_bundle": _bundle_args(),
        "SogBank": (_core.SogOptions(), np.array([[200.0, 160, 120, 0, 0]]), np.eye(5)[None], np.ones(1),
                    (320, 240), 0.0112),
    }
    for name, fn in vars(_core).items():
        if not callable(fn) or (inspect.isclass(fn) and name not in args):
            continue
        signature = (fn.__init__ if inspect.isclass(fn) else fn).__doc__.splitlines()[0].split("->")[0]
        parameters = re.sub(r"^[^(]*\(self: [^,)]*,?", "", signature)  # constructors: not `self`
        taken = [c for c in _bound_classes() if f"rscalib._core.{c.__name__}" in parameters]
        if taken and name not in args:
            failures.append(f"{name}: takes {[c.__name__ for c in taken]} but has no sample arguments")
            continue
        if taken:
            fn(*args[name])  # the sample arguments work
        for cls in taken:
            positions = [i for i, a in enumerate(args[name]) if type(a) is cls]
            assert positions, (name, cls)
            for i in positions:
                bad = list(args[name])
                bad[i] = new[cls]
                _expect_uninitialised(failures, f"{name}(arg {i}: {cls.__name__}.__new__)", lambda b=bad, f=fn: f(*b))
    # CameraModel is read without the GIL and without a lock because nothing can change it: a second
    # __init__ or __setstate__ on a live instance leaves it as it was.
    before = camera.__getstate__()
    camera.__init__("pinhole-radtan", [100.0, 100.0, 10.0, 10.0], 20, 20)
    camera.__setstate__(("pinhole-radtan", np.ones(9), 5, 5, np.zeros(2)))
    after = camera.__getstate__()
    if repr(after) != repr(before):
        failures.append(f"CameraModel changed by a second __init__/__setstate__: {before} -> {after}")
    print("\n".join(failures) if failures else f"ok: {failures.checked} uses of uninitialised instances refused")
    return 1 if failures else 0


# ------------------------------------------------------------------------------------ threads


def _in_threads(work, count=THREADS):
    errors = []

    def guarded(index):
        try:
            work(index)
        except Exception as error:  # noqa: BLE001 - reported by the parent
            errors.append(f"thread {index}: {type(error).__name__}: {error}")

    threads = [threading.Thread(target=guarded, args=(i,)) for i in range(count)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    return errors


def _child_bank_threads():
    """One SogBank driven by every thread: predict, search, update, add and remove features, read it."""
    bank = _bank()
    rounds = 30

    def work(index):
        rng = np.random.default_rng(index)
        for _ in range(rounds):
            bank.add_features(rng.uniform([20, 20], [300, 220], (3, 2)))
            bank.predict(1 / 30)
            ids, uv, _ = bank.predict_measurements()
            try:  # another thread may have removed some of these ids meanwhile: refused, not a crash
                bank.update(ids, uv + rng.normal(0, 0.5, uv.shape))
                if bank.num_features > 12:
                    bank.remove_features(bank.feature_ids[:3])
            except ValueError as error:
                assert "unknown feature id" in str(error), error
            assert np.isfinite(bank.calibration_mean).all()
            bank.feature_points()

    errors = _in_threads(work)
    # The map and the filter states must still agree: 18 + 6 per inverse-depth, 3 per XYZ feature.
    xyz = bank.feature_is_xyz
    expected_dim = 18 + 6 * int((~xyz).sum()) + 3 * int(xyz.sum())
    if bank.state_dim != expected_dim or bank.covariance(0).shape != (expected_dim, expected_dim):
        errors.append(f"state_dim {bank.state_dim}, covariance {bank.covariance(0).shape}, expected {expected_dim}")
    print("\n".join(errors) if errors else "ok")
    return 1 if errors else 0


def _child_spline_threads():
    """insert_knot from one thread beside evaluate from the others, on one BSpline."""
    rng = np.random.default_rng(7)
    spline = _core.BSpline.uniform(0.0, 1.0, 20, 6)
    spline.control_points = rng.normal(size=(23, 6))
    times = np.linspace(0.0, 1.0, 20001)
    reference = spline.evaluate(times)
    insertions = rng.uniform(0.001, 0.999, 20000)
    finished = []  # evaluators done; the inserter runs until all are
    inserted = []

    def work(index):
        if index == 0:
            for t in insertions:
                if len(finished) == THREADS - 1:
                    return
                spline.insert_knot(t)
                inserted.append(t)
            return
        try:
            for _ in range(100):
                values = spline.evaluate(times)
                if not np.allclose(values, reference, rtol=0, atol=1e-9):
                    raise AssertionError(f"evaluate beside insert_knot: max error {np.abs(values - reference).max()}")
        finally:
            finished.append(index)

    errors = _in_threads(work)
    if spline.num_control_points != 23 + len(inserted):
        errors.append(f"{spline.num_control_points} control points after {len(inserted)} insertions")
    print("\n".join(errors) if errors else "ok")
    return 1 if errors else 0


def _child_solve_threads():
    """solve_line_delay refines a trajectory without the GIL while other threads evaluate it: every
    evaluation must see the trajectory before or after the solve, never half-way."""
    rng = np.random.default_rng(1)
    camera = _core.CameraModel("pinhole-radtan", [300.0, 300.0, 160.0, 120.0], 320, 240)
    grid = np.stack(np.meshgrid(np.linspace(-0.3, 0.3, 6), np.linspace(-0.2, 0.2, 5)), -1).reshape(-1, 2)
    points = np.column_stack([grid, np.zeros(len(grid))])
    truth = _core.BSpline.uniform(0.0, 2.0, 20, 6)
    control = np.tile([0.0, 0.0, 1.0, 0.0, 0.0, 0.0], (23, 1))
    control[:, [0, 1, 3, 4, 5]] += rng.normal(0, 0.05, (23, 5))
    truth.control_points = control
    frame_times = np.linspace(0.05, 1.9, 60)
    rotations, translations = _core.poses_at(truth, frame_times)
    uv = np.vstack([camera.project(points @ r.T + p) for r, p in zip(rotations, translations)])
    uv += rng.normal(0, 0.3, uv.shape)
    times = np.linspace(0.0, 2.0, 2001)
    errors = []
    for trial in range(3):
        trajectory = truth.copy()
        trajectory.control_points = control + [0.01, 0.01, 0.01, 0.0, 0.0, 0.0]
        before = trajectory.evaluate(times)
        seen = []
        done = threading.Event()

        def work(index, trajectory=trajectory, seen=seen, done=done):
            while not done.is_set():
                seen.append(trajectory.evaluate(times))

        readers = [threading.Thread(target=work, args=(i,)) for i in range(2)]
        for t in readers:
            t.start()
        _core.solve_line_delay(np.repeat(frame_times, len(points)), uv, np.tile(points, (60, 1)), camera,
                               trajectory, 0.0, _core.RsSolverOptions())
        done.set()
        for t in readers:
            t.join()
        after = trajectory.evaluate(times)
        torn = sum(not (np.array_equal(v, before) or np.array_equal(v, after)) for v in seen)
        if torn or np.array_equal(before, after):
            errors.append(f"trial {trial}: {torn} of {len(seen)} evaluations saw the solve half-way")
    print("\n".join(errors) if errors else "ok")
    return 1 if errors else 0


# ------------------------------------------------------------------------------------ tests


def test_uninitialised_instances_raise_type_error():
    out = _run_child("uninitialised")
    assert int(out.split("ok: ")[1].split()[0]) > 150  # every class, member and argument was tried


def test_one_sog_bank_driven_from_four_threads():
    _run_child("bank_threads")


def test_insert_knot_beside_evaluate_from_threads():
    _run_child("spline_threads")


def test_evaluate_beside_solve_line_delay_from_threads():
    _run_child("solve_threads")


if __name__ == "__main__":
    children = {"uninitialised": _child_uninitialised, "bank_threads": _child_bank_threads,
                "spline_threads": _child_spline_threads, "solve_threads": _child_solve_threads}
    sys.exit(children[sys.argv[1]]())
