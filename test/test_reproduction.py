"""The committed reproduction report (doc/reproduction/) matches a fresh computation.

The fresh computation is the ``reproduce`` command's, ROS run of Fig. 6 included (three
node processes in lockstep and their bag): the tests that use it are marked ``ros``.  The
checks of the committed numbers alone (markdown, claims, Fig. 6 against the in-process
simulation) are ROS-free.
"""
import json
import math

import numpy as np
import pytest

from nonfragile_tracker.workflows import reproduce
from nonfragile_tracker.control.simulation.tracker import TrackerConfig
from nonfragile_tracker.control.simulation.reference import circle
from nonfragile_tracker.control.simulation.simulate import simulate_tracking
from nonfragile_tracker.interface.scenario import paper_plant_config

from conftest import CONFIG, ROOT, unique_domain_id

#: Depends on linear algebra: make test runs it again under a second BLAS kernel (Makefile).
pytestmark = pytest.mark.numerical

DOCS = ROOT / 'doc' / 'reproduction'


#: Simulated time of the fresh Fig. 6 ROS run (s).  Trim: the command's (and the committed
#: report's) is 60 s; the claim checked - the lockstep ROS run and its bag give the numbers
#: of the in-process simulation to round-off - is the same at 10 s (3.8 s to within 1 cm,
#: 1000 steps), and the committed 60 s numbers are checked against the in-process
#: simulation of 60 s (test_fig6_numbers_equal_the_in_process_simulation): 50 s of
#: three-process lockstep less in each of make test's two passes.
FRESH_FIG6_DURATION = 10.0


def fig6_simulation(duration):
    """The in-process simulation of Fig. 6's run (the paper's K_nf, ``duration`` s)."""
    import yaml
    K = np.array(yaml.safe_load((CONFIG / 'paper_gains.yaml').read_text())['K_nf'])
    steps = int(round(duration / 0.01))
    return steps, simulate_tracking(paper_plant_config(), TrackerConfig(K=K), circle(),
                                    steps).metrics()


@pytest.fixture(scope='module')
def committed():
    return json.loads((DOCS / 'paper_reproduction.json').read_text())


@pytest.fixture(scope='module')
def fresh(tmp_path_factory, shipped_design):
    """A fresh computation of the report; its max-decay design at the paper's gain budget is
    the identical call the shipped gain's command made this session (conftest
    ``shipped_design``), every other number is computed here, Fig. 6 from a ROS run of
    :data:`FRESH_FIG6_DURATION` (the command's default is 60 s)."""
    from nonfragile_tracker.control.synthesis.design import max_decay_rate
    (fn, problem, norm), kw, result = shipped_design.calls[0]
    assert fn is max_decay_rate and kw == {'nominal': False}
    reused = []

    def at_gain_norm(design, prob, budget, **options):
        same = (design is fn and budget == norm and options == {} and prob.tau == problem.tau
                and all(np.array_equal(getattr(prob, k), getattr(problem, k))
                        for k in ('A', 'B', 'A_tau', 'E', 'F')))
        if same:
            reused.append(budget)
            return result
        return real(design, prob, budget, **options)

    real = reproduce.at_gain_norm
    patch = pytest.MonkeyPatch()
    patch.setattr(reproduce, 'at_gain_norm', at_gain_norm)
    patch.setenv('ROS_DOMAIN_ID', str(unique_domain_id('reproduce')))
    try:
        out = reproduce.compute(CONFIG, tmp_path_factory.mktemp('repro'),
                                ros_duration=FRESH_FIG6_DURATION)
    finally:
        patch.undo()
    assert reused == [norm]
    return out


def close(a, b, rel, abs_=1e-9):
    if isinstance(a, bool) or isinstance(b, bool) or a is None or b is None:
        return a == b
    if math.isnan(a) or math.isinf(a):
        return (math.isnan(a) and math.isnan(b)) or a == b
    return abs(a - b) <= abs_ + rel * abs(a)


def test_markdown_is_rendered_from_the_committed_numbers(committed):
    assert (DOCS / 'paper_reproduction.md').read_text() == reproduce.render_markdown(committed)
    for fig in committed['figures']:
        assert (DOCS / fig).stat().st_size > 10_000, fig


#: The rows whose gain is fixed (the paper's printed gains): every figure is an exact
#: computation on the same K (eigenvalues, simulation), equal across machines to round-off.
FIXED_ROWS = ('paper K_nf', 'paper K_normal')
#: The designed rows' gains come from the SDP solver, whose last digits differ between
#: OpenBLAS kernels (chosen by CPU), at flat optima: K moved by up to 3e-3 (max decay rate)
#: under Haswell, Sandybridge and Prescott kernels and an AMD EPYC.  Their figures are judged
#: with tolerances taken from that spread: the norm (the budget spent within the bisection's
#: 2e-3, measured 2e-5 apart) 1e-3, the measured fragility margin (a worst case over
#: Delta, measured 1.4e-4 apart) 1e-3, the certified one (a bisection on fixed points) 2e-3,
#: figures of K (abscissae, decay rate; measured 0.9 % apart) 2 %, tracking figures of K (a
#: slow loop's error after 20 s amplifies K's difference: measured 3.2 % apart) 5 %.
DESIGNED_TOL = {'norm': 1e-3, 'measured_margin': 1e-3, 'certified_margin': 2e-3,
                'abscissa_nominal': 2e-2, 'abscissa_delta1': 2e-2, 'abscissa_delta2': 2e-2,
                'worst_abscissa': 2e-2, 'certified_decay': 2e-2, 'delay_margin': 0,
                'certified_delay': 0}
DESIGNED_TRACKING_TOL = 5e-2
#: The max perturbation scale's K is one of a flat family (the scale is the objective; K
#: moved by 0.1 and its abscissae, decay rate and tracking by up to 20 % under the
#: Prescott kernel): of it the tolerances above hold for the norm and the fragility
#: margins only; its other figures are checked for what does not move: their sign and
#: whether they are finite (stable, reaches 1 cm).
FLAT_ROWS = ('max perturbation scale',)


@pytest.mark.ros
def test_gain_table_matches_fresh_computation(committed, fresh):
    assert list(committed['gains']) == list(fresh['gains'])
    exact = {'norm': 1e-6, 'abscissa_nominal': 1e-6, 'abscissa_delta1': 1e-6,
             'abscissa_delta2': 1e-6, 'worst_abscissa': 1e-4, 'measured_margin': 1e-3,
             'certified_margin': 2e-3, 'delay_margin': 1e-6, 'certified_delay': 0,
             'certified_decay': 2e-3}
    for name, row in committed['gains'].items():
        new = fresh['gains'][name]
        for key in ('certified_nominal', 'certified_nonfragile'):
            assert row[key] == new[key], (name, key)
        if name in FIXED_ROWS:
            # exact by construction: the paper's printed K, read from config/, not computed
            np.testing.assert_array_equal(row['K'], new['K'], err_msg=name)
            tol, track = exact, 1e-6
        else:
            # K itself is not compared digit by digit (a flat optimum), only its size
            np.testing.assert_allclose(row['K'], new['K'], atol=0.2, err_msg=name)
            tol, track = DESIGNED_TOL, DESIGNED_TRACKING_TOL
        for key, rel in tol.items():
            if name in FLAT_ROWS and key not in ('norm', 'measured_margin', 'certified_margin'):
                assert np.sign(row[key]) == np.sign(new[key]), (name, key)
            else:
                assert close(row[key], new[key], rel), (name, key, row[key], new[key])
        for part in ('tracking', 'tracking_compensated'):
            for key, val in row[part].items():
                got = new[part][key]
                if name in FLAT_ROWS:
                    assert (val is None or math.isfinite(val)) == \
                        (got is None or math.isfinite(got)), (name, part, key)
                else:
                    assert close(val, got, track, 1e-9), (name, part, key, val, got)


@pytest.mark.ros
def test_harder_delay_section_matches(committed, fresh):
    """The certified h_max comes from a bisection on fixed points (the same on every machine
    within its 1e-3 s); the exact margins are of the designed K, which moves by up to
    2e-3 between BLAS kernels (a flat optimum): they moved by 2.2e-3 relative (1.16349
    against 1.16601 s on an AMD EPYC), so they are checked to 1 % and above h_max."""
    a, b = committed['harder'], fresh['harder']
    assert a['theorem1_feasible'] is False and b['theorem1_feasible'] is False
    assert close(a['h_max'], b['h_max'], 0, 2e-3)
    for k, v in a['true_delay_margin'].items():
        assert v > a['h_max'] and b['true_delay_margin'][k] > b['h_max']
        assert close(v, b['true_delay_margin'][k], 1e-2), k


@pytest.mark.ros
def test_fig6_of_a_fresh_ros_run_matches(fresh):
    """Fig. 6's numbers from a fresh lockstep ROS run (and its bag) equal the in-process
    simulation of the same run to round-off (the run is :data:`FRESH_FIG6_DURATION`)."""
    b = fresh['fig6']
    assert b['duration'] == FRESH_FIG6_DURATION
    steps, m = fig6_simulation(b['duration'])
    assert b['steps'] == steps + 1 and m.first_within < b['duration']
    for key, want in (('final_error', m.final_error), ('first_within_1cm', m.first_within),
                      ('rms_error', m.rms_error), ('peak_abs_w', m.peak_abs_w)):
        assert b[key] == pytest.approx(want, rel=1e-9, abs=1e-9), key
    assert 'fig6_xy.png' in fresh['figures']


def test_claims_are_backed_by_the_numbers(committed):
    g = committed['gains']
    # K_normal with Delta_2 is stable (the paper claims it is not), and certified
    assert g['paper K_normal']['abscissa_delta2'] < 0
    assert g['paper K_normal']['certified_nonfragile']
    # both Theorem 1 designs are feasible and certified
    assert g['Theorem 1 K_nf']['certified_nonfragile'] and g['Theorem 1 K_normal']['certified_nominal']
    # the paper's K_nf keeps about 1 cm; compensation removes it
    assert 0.009 < g['paper K_nf']['tracking']['steady_max_error'] < 0.013
    assert g['paper K_nf']['tracking_compensated']['steady_max_error'] < 1e-4


def test_fig6_numbers_equal_the_in_process_simulation(committed):
    """Fig. 6 comes from a ROS run; the lockstep run equals the simulation to round-off."""
    f6 = committed['fig6']
    steps, m = fig6_simulation(f6['duration'])
    assert f6['steps'] == steps + 1
    assert f6['final_error'] == pytest.approx(m.final_error, abs=1e-9)
    assert f6['first_within_1cm'] == pytest.approx(m.first_within, abs=1e-9)
