"""`--refine-intrinsics`: the camera's parameters refined jointly with the trajectory and the line delay,
with the given calibration as a prior (docs/formulation.md §14).

Simulated rolling-shutter observations (rscalib.sim.target_observations, exact RS projections, fixed seeds)
with a deliberately wrong starting calibration (f 2 % off, principal point 8 px off) must give d, f and c
within 3 sigma of the truth; the default path (no refinement) must give the numbers of the golden file
written before the feature existed (data/default_path_golden.json): the same knots, rounds and counts,
every float to 1e-12 relative. Not bit for bit: libm and BLAS pick their kernels by CPU (the golden file
was written on an AVX2 machine; an AVX-512 one differs in the last bits), while a change of the path
would move the numbers by far more."""
import json
import math
from pathlib import Path

import numpy as np
import pytest

import rscalib
from rscalib import InputError, _core
from rscalib.linedelay import spline
from rscalib.linedelay.common import (
    DEFAULT_PRIOR_CENTRE_PX,
    DEFAULT_PRIOR_FOCAL_FRACTION,
    default_intrinsics_prior,
    intrinsics_prior_from_std,
    load_intrinsics_prior,
)
from rscalib.linedelay.options import LineDelayOptions
from rscalib.sim import target_observations as simulate

TRUE_PARAMS = np.array([500.0, 502.0, 321.0, 238.5, -0.1, 0.05, 5e-4, -3e-4, 0.0])
CAMERA = rscalib.CameraModel("pinhole-radtan", TRUE_PARAMS, 640, 480)
GOLDEN = Path(__file__).parent / "data" / "default_path_golden.json"


def wrong_start(params=TRUE_PARAMS, focal_factor=1.02, centre_shift_px=(8.0, -8.0)) -> rscalib.CameraModel:
    p = np.array(params, dtype=np.float64)
    p[:2] *= focal_factor
    p[2:4] += centre_shift_px
    return rscalib.CameraModel("pinhole-radtan", p, 640, 480)


_RUNS = {}


def refined(seed: int, line_delay_s: float = 30e-6, duration_s: float = 4.0):
    """(simulation, result) of a refinement from the wrong start, once per seed."""
    if seed not in _RUNS:
        sim = simulate.simulate_observations(CAMERA, line_delay_s, fps=30.0, duration_s=duration_s,
                                             noise_px=0.3, seed=seed)
        _RUNS[seed] = sim, spline.calibrate_line_delay(sim.observations, wrong_start(), LineDelayOptions(refine_intrinsics=True))
    return _RUNS[seed]


def _golden_fields(result) -> dict:
    """The numbers of the golden file (everything but times), as scripts/… wrote them before the feature."""
    d = result.summary_dict()
    keep = {k: v for k, v in d.items() if isinstance(v, (int, float)) and k != "solve_time_s"}
    keep["history"] = [{k: v for k, v in h.items() if k != "solve_time_s"} for h in d["history"]]
    keep["knots"] = [float(x).hex() for x in result.knots]
    keep["control_points_hex"] = [float(x).hex() for x in np.asarray(result.trajectory.control_points).ravel()[::7]]
    keep["line_delay_hex"] = float(result.line_delay_s).hex()
    keep["std_hex"] = float(result.line_delay_std_s).hex()
    keep["keys"] = sorted(d)
    return json.loads(json.dumps(keep))


def _default_path(monkeypatch=None):
    """calibrate_line_delay on the golden file's simulation; with `monkeypatch`, on the reference solver
    path (autodiff of the whole functor, Ceres' covariance: the arithmetic before issue 17)."""
    if monkeypatch is not None:
        make_options = spline._solver_options

        def reference_options(*args, **kwargs):
            options = make_options(*args, **kwargs)
            options.analytic_jacobian = False
            options.schur_variance = False
            return options

        monkeypatch.setattr(spline, "_solver_options", reference_options)
    sim = simulate.simulate_observations(CAMERA, 30e-6, fps=30.0, duration_s=3.0, noise_px=0.3, seed=4242)
    return spline.calibrate_line_delay(sim.observations, CAMERA)


def _assert_matches_golden(got: dict, golden: dict, rel: float) -> None:
    """The same knots, keys, rounds and counts; every float, and every hex-stored one, to ``rel``."""
    assert got["knots"] == golden["knots"] and got["keys"] == golden["keys"]
    assert [{k: v for k, v in h.items() if not isinstance(v, float)} for h in got["history"]] == \
        [{k: v for k, v in h.items() if not isinstance(v, float)} for h in golden["history"]]
    for name, value in golden.items():
        if isinstance(value, float):
            assert got[name] == pytest.approx(value, rel=rel), name
        elif isinstance(value, (bool, int)):
            assert got[name] == value, name
    for mine, theirs in zip(got["history"], golden["history"]):
        for name, value in theirs.items():
            if isinstance(value, float):
                assert mine[name] == pytest.approx(value, rel=rel), name
    for name in ("control_points_hex", "line_delay_hex", "std_hex"):
        mine = np.array([float.fromhex(x) for x in np.atleast_1d(got[name])])
        theirs = np.array([float.fromhex(x) for x in np.atleast_1d(golden[name])])
        np.testing.assert_allclose(mine, theirs, rtol=rel, atol=1e-15, err_msg=name)


def test_the_default_path_gives_the_golden_numbers_to_machine_rounding(monkeypatch):
    result = _default_path(monkeypatch)
    _assert_matches_golden(_golden_fields(result), json.loads(GOLDEN.read_text()), rel=1e-12)
    assert result.intrinsics is None and result.camera is None
    assert "intrinsics" not in result.summary_dict()
    assert _core.RsSolverOptions().refine_intrinsics is False


def test_the_leaner_solve_gives_the_golden_numbers_to_rounding():
    """The default solver (Jacobian chained by hand, sigma_d from the Schur complement; issue 17) rounds
    differently: the same knots, rounds and counts, every number to 1e-9 relative."""
    _assert_matches_golden(_golden_fields(_default_path()), json.loads(GOLDEN.read_text()), rel=1e-9)


@pytest.mark.parametrize("seed", [3101, 3102])
def test_d_f_and_c_are_recovered_within_3_sigma_from_a_wrong_start(seed):
    sim, result = refined(seed)
    ki = result.intrinsics
    assert result.determined
    assert abs(result.line_delay_s - sim.line_delay_s) <= 3 * result.line_delay_std_s
    for i, name in enumerate(["fx", "fy", "cx", "cy"]):
        error = ki["estimate"][name] - TRUE_PARAMS[i]
        assert abs(error) <= 3 * ki["std"][name], (name, error, ki["std"][name])
    # the start was 2 % / 8 px off: the data moved the estimate most of the way back
    assert abs(ki["estimate"]["fx"] - TRUE_PARAMS[0]) < 0.25 * 0.02 * TRUE_PARAMS[0]
    assert abs(ki["estimate"]["cx"] - TRUE_PARAMS[2]) < 0.25 * 8.0
    assert 0.7 < result.normalised_cost < 1.5
    # the camera of the result is the refined one; k3 (0 in the file) was held
    assert np.allclose(result.camera.params, [ki["estimate"][n] for n in ki["names"]])
    assert ki["estimate"]["k3"] == 0.0 and "k3" in ki["prior"]["held"]


def test_the_covariance_of_d_with_the_intrinsics_is_reported():
    _, result = refined(3101)
    ki = result.summary_dict()["intrinsics"]
    cov = np.array(ki["covariance"])
    assert ki["covariance_order"] == ["line_delay_s"] + list(CAMERA.param_names)
    assert cov.shape == (10, 10)
    assert np.allclose(cov, cov.T)
    free = [0, 1, 2, 3, 4, 5, 6, 7, 8]
    free.remove(8)  # k3 held: zero row and column
    assert np.all(cov[9] == 0.0)
    sub = cov[np.ix_([0] + [i + 1 for i in free], [0] + [i + 1 for i in free])]
    assert np.all(np.linalg.eigvalsh(sub) > 0)
    assert math.isclose(math.sqrt(cov[0, 0]), result.line_delay_std_s, rel_tol=1e-9)
    for i, name in enumerate(CAMERA.param_names):
        assert math.isclose(ki["std"][name], math.sqrt(cov[i + 1, i + 1]), rel_tol=1e-9, abs_tol=0.0)
    # the prior said where it came from
    assert ki["prior"]["source"].startswith("default")
    assert all(abs(c) <= 1.0 + 1e-9 for c in ki["correlation_with_line_delay"].values() if c is not None)


def test_a_tight_prior_gives_the_fixed_camera_answer():
    sim = simulate.simulate_observations(CAMERA, 30e-6, fps=30.0, duration_s=3.0, noise_px=0.3, seed=3103)
    fixed = spline.calibrate_line_delay(sim.observations, CAMERA)
    tight = intrinsics_prior_from_std(CAMERA, [1e-6] * 8 + [0.0], "test: tight")
    joint = spline.calibrate_line_delay(sim.observations, CAMERA, LineDelayOptions(refine_intrinsics=True, intrinsics_prior=tight))
    assert abs(joint.line_delay_s - fixed.line_delay_s) < 0.02 * fixed.line_delay_std_s
    assert np.allclose(joint.camera.params, TRUE_PARAMS, atol=1e-5)
    assert math.isclose(joint.line_delay_std_s, fixed.line_delay_std_s, rel_tol=0.02)


def test_the_default_prior_is_the_documented_one():
    prior = default_intrinsics_prior(CAMERA)
    std = dict(zip(prior.names, prior.std))
    assert std["fx"] == DEFAULT_PRIOR_FOCAL_FRACTION * 500.0 and std["fy"] == DEFAULT_PRIOR_FOCAL_FRACTION * 502.0
    assert std["cx"] == std["cy"] == DEFAULT_PRIOR_CENTRE_PX
    assert prior.fixed == (8,) and std["k3"] == 0.0       # k3 = 0 in the file: not fitted, held
    assert "2 %" in prior.source and "10 px" in prior.source
    fish = rscalib.CameraModel("pinhole-equidistant", np.array([400.0, 400, 320, 240, 0.1, 0.01, 0, 0]), 640, 480)
    assert default_intrinsics_prior(fish).fixed == (6, 7)


def test_a_prior_from_an_intrinsics_result_json(tmp_path):
    names = list(CAMERA.param_names)
    std = dict(zip(names, [1.5, 1.6, 2.0, 2.1, 0.01, 0.02, 1e-4, 1e-4, 0.0]))
    path = tmp_path / "result.json"
    path.write_text(json.dumps({"model": "pinhole-radtan", "std": std}))
    prior = load_intrinsics_prior(path, CAMERA)
    assert prior.fixed == (8,)
    assert np.allclose(np.sqrt(np.diag(prior.covariance))[:8], [std[n] for n in names[:8]])
    assert str(path) in prior.source
    path.write_text(json.dumps({"model": "pinhole-equidistant", "std": std}))
    with pytest.raises(InputError, match="pinhole-equidistant"):
        load_intrinsics_prior(path, CAMERA)
    path.write_text(json.dumps({"rms_px": 0.3}))
    with pytest.raises(InputError, match="std"):
        load_intrinsics_prior(path, CAMERA)
    with pytest.raises(InputError, match="9 sigmas"):
        intrinsics_prior_from_std(CAMERA, [1.0] * 4, "x")


def test_the_flag_needs_the_spline_and_its_prior_needs_the_flag():
    from rscalib.cli import build_parser
    from rscalib.cli.linedelay import line_delay_options

    args = build_parser().parse_args(["linedelay", "v.avi", "--target", "t.yaml", "--camera", "c.yaml", "--out", "o",
                                      "--intrinsics-prior", "r.json"])
    with pytest.raises(InputError, match="--refine-intrinsics"):
        line_delay_options(args)
    args = build_parser().parse_args(["linedelay", "v.avi", "--target", "t.yaml", "--camera", "c.yaml", "--out", "o"])
    options = line_delay_options(args)
    assert not options.refine_intrinsics and options.intrinsics_prior is None
    args = build_parser().parse_args(["linedelay", "v.avi", "--target", "t.yaml", "--camera", "c.yaml", "--out", "o",
                                      "--trajectory", "linear", "--refine-intrinsics"])
    with pytest.raises(InputError, match="only for the spline"):
        line_delay_options(args)


def _verdict_of(self_check, normalised_cost=1.0, **extra):
    from types import SimpleNamespace

    from rscalib.linedelay.judge import judge_line_delay as verdict

    uv = np.c_[np.linspace(0, 640, 50), np.linspace(10, 470, 50)]
    result = SimpleNamespace(determined=True, normalised_cost=normalised_cost, frames_used=100, frames_total=100,
                             used_observations=SimpleNamespace(uv=uv), rows=480, self_check=self_check,
                             line_delay_std_s=1e-8, line_delay_s=30e-6, converged=True, readout_time_s=0.0144,
                             **extra)
    return verdict(result)


def test_a_failed_self_check_names_the_camera_and_the_flag_first_suspect():
    halves = [{"line_delay_s": 30.4e-6, "line_delay_std_s": 3e-8}, {"line_delay_s": 29.9e-6, "line_delay_std_s": 3e-8}]
    disagree = {"agree": False, "halves": halves, "z": 9.9, "widen": 9.9}
    v = _verdict_of(disagree, intrinsics=None)
    assert not v.trusted and any("--refine-intrinsics" in r for r in v.reasons)
    # already refined, or a trajectory model without the option: no such advice
    assert not any("--refine-intrinsics" in r for r in _verdict_of(disagree, intrinsics={"fx": 1}).reasons)
    assert not any("--refine-intrinsics" in r for r in _verdict_of(disagree).reasons)
    # every check passed: trusted, nothing to suggest
    v = _verdict_of({"agree": True}, intrinsics=None)
    assert v.trusted and not v.reasons
