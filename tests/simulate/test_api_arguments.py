"""Absurd arguments of the simulator's Python API (contacts, optimize, noise) are refused with a
ParameterError whose one line names the argument, before any work; sane ones of any numeric
type give the same result."""
import math

import numpy as np
import pytest
from matplotlib.figure import Figure

from crosssection.core.errors import ParameterError
from simulate import optimize
from simulate.checks import check_real, check_seed, check_whole
from simulate.contacts import MAX_SAMPLES, MIN_CONTACT_DISTANCE, analyze_rod, resample_rod
from simulate.load import plot_configuration
from simulate.noise import (angle_increments, initial_shape, initial_theta, intersection_rate,
                            largest_noise)
from simulate.optimize import (anneal, default_contact_cutoff, from_params, lbfgs_quench,
                               powell_protocol, scipy_powell, scipy_protocol, to_params)
from simulate.shapes import hairpin, resample

N = 60
XY = resample(hairpin(0.01, arm=0.3), N)
LAM = 2e4
XY0 = initial_shape(N, 300.0, seed=1)
#: one short Powell run: enough to reach every check
QUICK = dict(n_runs=1, maxiter=1, nematic_runs=())
ROD = r"must be an \(N\+1, 2\) array of finite numbers with N >= 2, "
NAN_ROW = np.where(np.arange(N + 1)[:, None] == 3, np.nan, XY)


# --- simulate.checks -------------------------------------------------------------------------

def test_check_whole_takes_whole_numbers_of_any_type_and_refuses_the_rest():
    for v in (3, np.int64(3), 3.0, np.float32(3.0)):
        out = check_whole("k", v, low=1)
        assert out == 3 and type(out) is int
    for v in (3.5, True, "3", None, math.nan, math.inf, 0):
        with pytest.raises(ParameterError, match=r"^k must be a whole number >= 1, got "):
            check_whole("k", v, low=1)


def test_check_real_names_the_range_and_why():
    assert check_real("x", np.float32(0.5), low=0.0, high=1.0) == 0.5
    with pytest.raises(ParameterError,
                       match=r"^x must be a finite number > 0 and < 1 \(a reason\), got 1$"):
        check_real("x", 1, low=0.0, low_open=True, high=1.0, high_open=True, why="a reason")
    for v in (True, "1", math.nan, -math.inf, [1.0]):
        with pytest.raises(ParameterError, match="^x must be a finite number"):
            check_real("x", v)


def test_check_seed_takes_what_numpy_generators_take():
    ss, gen = np.random.SeedSequence(1), np.random.default_rng(1)
    for seed in (None, 0, np.int64(5), [1, 2], ss, gen):
        assert check_seed(seed) is seed
    for seed in ("a", 1.5, -1, True, [1.5], object()):
        with pytest.raises(ParameterError, match="^seed must be None, an integer >= 0"):
            check_seed(seed)
    with pytest.raises(ParameterError, match=r"SeedSequence, got Generator"):
        check_seed(gen, generator=False)


# --- simulate.contacts -----------------------------------------------------------------------

@pytest.mark.parametrize("value", [-1, 0, 1e-9, MIN_CONTACT_DISTANCE * 0.99, 1.0, 10.0,
                                   math.nan, math.inf, "x", True])
def test_analyze_rod_refuses_a_contact_distance_out_of_range(value):
    with pytest.raises(ParameterError, match=r"^contact_distance must be a finite number "
                                             r">= 1e-05 and < 1 \(units of the rod length L; "
                                             r"about 3 / contact_distance samples\), got "):
        analyze_rod(XY, lam=LAM, contact_distance=value)


def test_analyze_rod_takes_contact_distances_of_any_numeric_type_at_the_bounds():
    ref = analyze_rod(XY, lam=LAM)
    same = analyze_rod(XY, lam=int(LAM), contact_distance=np.float32(0.5) / np.float32(N))
    assert abs(same.contact_distance - 0.5 / N) < 1e-9
    assert (same.n_stacks, same.n_branches) == (ref.n_stacks, ref.n_branches)
    # the smallest cut-off accepted: about 3 / delta samples whatever N
    small = analyze_rod(XY, lam=LAM, contact_distance=MIN_CONTACT_DISTANCE)
    assert len(small.samples_s) == N * int(np.ceil(3.0 / (N * MIN_CONTACT_DISTANCE))) + 1


@pytest.mark.parametrize("name, value, cause", [
    ("min_run", -1.0, ">= 0 and < 1"), ("min_run", 1.0, ">= 0 and < 1"),
    ("min_run", math.nan, ">= 0 and < 1"), ("min_run", "3", ">= 0 and < 1"),
    ("void_px", 0.0, r"> 0 and <= 0\.00833"), ("void_px", -1.0, r"> 0 and <= 0\.00833"),
    ("void_px", 1.0, r"> 0 and <= 0\.00833"), ("void_px", math.inf, r"> 0 and <= 0\.00833"),
    ("lam", -1.0, ">= 0, got"), ("lam", math.nan, ">= 0, got"), ("lam", "x", ">= 0, got"),
])
def test_analyze_rod_refuses_other_options_out_of_range(name, value, cause):
    with pytest.raises(ParameterError, match=f"^{name} must be a finite number {cause}"):
        analyze_rod(XY, **{"lam": LAM, name: value})


def test_analyze_rod_takes_min_run_and_void_px_at_their_bounds():
    delta = 0.5 / N
    assert analyze_rod(XY, lam=LAM, min_run=0.0, void_px=delta).contact_distance == delta


@pytest.mark.parametrize("xy, cause", [
    (XY.T, r"got shape \(2, 61\) \(transposed\? pass xy\.T\)"),
    (NAN_ROW, r"got 2 non-finite coordinate\(s\)"),
    (XY[:2], r"got shape \(2, 2\)"),
])
def test_analyze_rod_refuses_what_is_not_a_rod(xy, cause):
    with pytest.raises(ParameterError, match=f"^xy {ROD}{cause}$"):
        analyze_rod(xy, lam=LAM)


def test_plot_configuration_refuses_a_negative_contact_distance():
    with pytest.raises(ParameterError, match="^contact_distance must be"):
        plot_configuration(XY, contact_distance=-0.01)
    assert isinstance(plot_configuration(XY, contact_distance=1.0 / N), Figure)


@pytest.mark.parametrize("spacing, cause", [
    (0.0, "a finite number > 0"), (-1.0, "a finite number > 0"),
    (math.nan, "a finite number > 0"), (1e-12, f"at most {MAX_SAMPLES} samples"),
])
def test_resample_rod_refuses_a_spacing_out_of_range(spacing, cause):
    with pytest.raises(ParameterError, match=f"^spacing must (be|give) {cause}"):
        resample_rod(XY, spacing)
    with pytest.raises(ParameterError, match=r"transposed\? pass xy\.T"):
        resample_rod(XY.T, 0.01)
    s, pts, sub = resample_rod(XY, 0.5 / N)
    assert sub == 2 and len(s) == len(pts) == 2 * N + 1


# --- simulate.optimize -----------------------------------------------------------------------

@pytest.mark.parametrize("xy0, cause", [
    (XY0.T, r"got shape \(2, 61\) \(transposed\? pass xy0\.T\)"),
    (np.full((10, 2), np.nan), r"got 20 non-finite coordinate\(s\)"),
    ("abc", "got 'abc'"),
])
@pytest.mark.parametrize("minimise", [powell_protocol, lbfgs_quench, anneal, scipy_powell,
                                      scipy_protocol])
def test_minimisers_refuse_a_start_that_is_not_a_rod(minimise, xy0, cause):
    with pytest.raises(ParameterError, match=f"^xy0 {ROD}{cause}$"):
        minimise(xy0, LAM)


@pytest.mark.parametrize("lam", [-5.0, -1e-9, math.nan, math.inf, "7e5", None, 1e12])
@pytest.mark.parametrize("minimise", [powell_protocol, lbfgs_quench, anneal, scipy_powell,
                                      scipy_protocol])
def test_minimisers_refuse_a_lambda_out_of_0_to_the_jammed_bound(minimise, lam):
    # the command line's bound (quench --lambda) holds in the API too
    with pytest.raises(ParameterError, match="^lam must be a finite number >= 0 and <= 1e"
                                             r"\+10 \(above it the rod is jammed"):
        minimise(XY0, lam)


@pytest.mark.parametrize("name, value, match", [
    ("seed", "a", "^seed must be None, an integer >= 0"),
    ("seed", 1.5, "^seed must be None, an integer >= 0"),
    ("seed", -1, "^seed must be None, an integer >= 0"),
    ("n_runs", 1.5, "^n_runs must be a whole number >= 0"),
    ("n_runs", -1, "^n_runs must be a whole number >= 0"),
    ("maxiter", 0, "^maxiter must be a whole number >= 1"),
    ("nematic_runs", (0.5,), "^nematic_runs must be a whole number >= 0"),
    ("nematic_runs", 5, "^nematic_runs must be a sequence of run numbers, got 5"),
    ("u", -1.0, "^u must be a finite number >= 0"),
    ("xtol", 0.0, "^xtol must be a finite number > 0"),
    ("ftol", math.nan, "^ftol must be a finite number > 0"),
    ("contact_cutoff", 0.0, "^contact_cutoff must be a finite number > 0"),
    ("min_separation", 0, "^min_separation must be a whole number >= 1"),
    ("wall_radius", -1.0, "^wall_radius must be a finite number > 0"),
    ("parametrization", "polar", "^parametrization must be 'bend' or 'tangent', got 'polar'"),
])
def test_powell_protocol_refuses_absurd_options(name, value, match):
    with pytest.raises(ParameterError, match=match):
        powell_protocol(XY0, LAM, **{**QUICK, name: value})


def test_powell_protocol_takes_every_kind_of_seed_and_whole_numbers_of_any_type():
    ref = powell_protocol(XY0, LAM, seed=3, **QUICK)
    for seed in (np.int64(3), np.random.SeedSequence(3), np.random.default_rng(3)):
        assert np.array_equal(powell_protocol(XY0, LAM, seed=seed, **QUICK).xy, ref.xy)
    same = powell_protocol(XY0, int(LAM), seed=3, n_runs=1.0, maxiter=np.int64(1),
                           nematic_runs=())
    assert np.array_equal(same.xy, ref.xy)


def test_scipy_powell_refuses_an_unknown_parametrization():
    # refused rather than taken for "bend"
    with pytest.raises(ParameterError, match="^parametrization must be 'bend' or 'tangent'"):
        scipy_powell(XY0, LAM, maxiter=1, parametrization="theta")
    with pytest.raises(ParameterError, match="^n_runs must be a whole number >= 0"):
        scipy_protocol(XY0, LAM, n_runs=2.5)


@pytest.mark.parametrize("name, value", [("barrier", -1.0), ("barrier_range", 0.0),
                                         ("maxiter", 0), ("restarts", 0), ("gtol", 0.0),
                                         ("min_separation", 0.5), ("seed", "a")])
def test_lbfgs_quench_refuses_absurd_options(name, value):
    with pytest.raises(ParameterError, match=f"^{name} must be"):
        lbfgs_quench(XY0, LAM, **{name: value})


def test_fewer_runs_than_the_default_nematic_runs_name_them():
    """n_runs = 2 with the default nematic_runs said only "must not be used in the last run",
    naming neither the parameter nor its default."""
    from simulate.optimize import NEMATIC_RUNS, _check_runs

    with pytest.raises(ParameterError, match=r"^nematic_runs \[1, 2\] names run 1, the last "
                       r"of n_runs = 2: .* defaults to \[1, 2\]"):
        _check_runs(2, NEMATIC_RUNS)


@pytest.mark.parametrize("kw, match", [
    (dict(n_runs=-1), "^n_runs must be"), (dict(maxiter=0), "^maxiter must be"),
    (dict(nematic_runs=(9,)), "must not be used in the last run"),
    (dict(stages=0), "^stages must be a whole number >= 1"),
    (dict(stages=2.5), "^stages must be a whole number >= 1"),
    (dict(runs_per_stage=0), "^runs_per_stage must be a whole number >= 1"),
    (dict(lam_start=0.0), "^lam_start must be a finite number > 0"),
    (dict(seed=np.random.default_rng(0)), r"SeedSequence, got Generator"),
    (dict(method="newton"), "^method must be 'powell' or 'lbfgs', got 'newton'"),
    (dict(ramp="cubic"), "unknown ramp 'cubic'"),
    (dict(lam=0.0), r"^lam must be > 0 for the geometric ramp"),
])
def test_anneal_checks_every_option_before_the_first_stage(monkeypatch, kw, match):
    def stage(*args, **kwargs):
        raise AssertionError("a stage ran before the options were checked")

    monkeypatch.setattr(optimize, "powell_protocol", stage)
    monkeypatch.setattr(optimize, "lbfgs_quench", stage)
    kw = {"lam": LAM, "stages": 3, "n_runs": 10, **kw}
    with pytest.raises(ParameterError, match=match):
        anneal(XY0, **kw)


def test_parameter_helpers_refuse_absurd_input():
    with pytest.raises(ParameterError, match="^n_segments must be a whole number >= 1"):
        default_contact_cutoff(2.5)
    assert default_contact_cutoff(np.int64(4)) == 0.25
    with pytest.raises(ParameterError, match=r"^xy must .*transposed"):
        to_params(XY0.T)
    with pytest.raises(ParameterError, match=r"got shape \(2,\)$"):
        from_params([1.0, 2.0])
    with pytest.raises(ParameterError, match=r"got 1 non-finite value\(s\)$"):
        from_params([0.0, np.nan, 0.0, 0.0])
    assert np.allclose(from_params(to_params(XY0)), XY0)


# --- simulate.noise --------------------------------------------------------------------------

@pytest.mark.parametrize("kw, match", [
    (dict(n_segments=60.5), "^n_segments must be a whole number >= 2, got 60.5"),
    (dict(n_segments=1), "^n_segments must be a whole number >= 2, got 1"),
    (dict(n_segments="60"), "^n_segments must be a whole number >= 2"),
    (dict(noise=-1.0), "^noise must be a finite number >= 0"),
    (dict(noise=math.nan), "^noise must be a finite number >= 0"),
    (dict(seed="a"), "^seed must be None, an integer >= 0"),
    (dict(seed=2.0), "^seed must be None, an integer >= 0"),
    (dict(max_tries=0), "^max_tries must be a whole number >= 1"),
])
def test_initial_shape_refuses_absurd_arguments(kw, match):
    with pytest.raises(ParameterError, match=match):
        initial_shape(**{"n_segments": 60, "noise": 750.0, **kw})


def test_initial_shape_takes_every_kind_of_seed_and_whole_numbers_of_any_type():
    ref = initial_shape(60, 750.0, seed=4)
    for seed in (np.int64(4), np.random.SeedSequence(4), np.random.default_rng(4)):
        assert np.array_equal(initial_shape(60, 750.0, seed=seed), ref)
    assert np.array_equal(initial_shape(60.0, 750, seed=4), ref)


def test_noise_helpers_refuse_absurd_arguments():
    rng = np.random.default_rng(0)
    for draw in (angle_increments, initial_theta):
        with pytest.raises(ParameterError, match="^rng must be a numpy.random.Generator"):
            draw(10, 1.0, 3)
        with pytest.raises(ParameterError, match="^n_segments must be a whole number"):
            draw(10.5, 1.0, rng)
        with pytest.raises(ParameterError, match="^noise must be a finite number >= 0"):
            draw(10, -1.0, rng)
    with pytest.raises(ParameterError, match="^n_samples must be a whole number >= 1"):
        intersection_rate(750.0, n_samples=0)
    with pytest.raises(ParameterError, match="^threshold must be a finite number >= 0 and <= 1"):
        largest_noise(threshold=2.0)
    with pytest.raises(ParameterError, match="^noises must be a finite number >= 0, got 'a'"):
        largest_noise(noises=["a"])
    with pytest.raises(ParameterError, match="SeedSequence, got Generator"):
        largest_noise(seed=rng)


def test_functions_that_spawn_seeds_take_a_seed_sequence():
    # their docstrings promise a SeedSequence; it spawns the same children as its entropy
    from simulate.noise import initial_shape, largest_noise
    from simulate.optimize import anneal

    xy = initial_shape(40, seed=3)
    kw = dict(stages=1, n_runs=1, maxiter=1, nematic_runs=())
    a = anneal(xy, 7e5, seed=np.random.SeedSequence(1), **kw)
    b = anneal(xy, 7e5, seed=1, **kw)
    assert np.array_equal(a.xy, b.xy)
    kw = dict(n_segments=40, noises=(100, 500), n_samples=50)
    assert largest_noise(seed=np.random.SeedSequence(2), **kw) == largest_noise(seed=2, **kw)


@pytest.mark.parametrize("theta", [np.zeros(0), np.zeros((2, 3)), []])
def test_angles_that_make_no_rod_are_a_parameter_error(theta):
    """An empty theta would divide by zero in positions and energy_and_gradient."""
    from simulate.energy import energy_and_gradient
    from simulate.geometry import positions

    with pytest.raises(ParameterError, match="theta must be a 1-d array of N >= 1"):
        positions(theta)
    with pytest.raises(ParameterError, match="theta must be a 1-d array of N >= 1"):
        energy_and_gradient(theta, (0.0, 0.0), 1.0)
    # one segment is a rod: from the start, 1/N along its angle
    assert np.allclose(positions([0.5]), [[0.0, 0.0], [np.cos(0.5), np.sin(0.5)]])
