"""Figures quoted in README.md and doc/ agree with their one source.

A quoted figure carries a tag right after it, invisible on GitHub and in Sphinx:
``0.2208 s<!-- fig:gain.lag_certified -->``.  Each tag names a source read here at test
time - the shipped gain files' own ``gain_design`` record, the demo's run recomputed in
process (a lockstep run of the nodes equals it to 1e-9), or a design the docs quote
recomputed in process as its command runs it - and the quoted number must be
that source rounded to the digits quoted (``ms``/``mm`` quote s/m in thousandths).  A gain
file regenerated, or a default changed, fails here until every quote is updated.
"""
from __future__ import annotations

import functools
import re

import numpy as np
import pytest
import yaml

from conftest import CONFIG, ROOT

#: number, optional unit (and a closing bracket), then the tag
TAG = re.compile(r'(?P<num>[-+]?\d+(?:\.\d+)?(?:e[-+]?\d+)?)\s*(?P<unit>ms|mm|1/s|s|m)?\]?'
                 r'<!-- fig:(?P<name>[\w.]+) -->')
PAGES = [ROOT / 'README.md', *sorted((ROOT / 'doc').rglob('*.md'))]


def _design(name: str) -> dict:
    return yaml.safe_load((CONFIG / name).read_text())['gain_design']['ros__parameters']


@functools.lru_cache(maxsize=None)
def _run(gains: str, compensation: bool):
    """The metrics of the paper scenario's 60 s circle as ``make demo`` runs it, in process."""
    from nonfragile_tracker.control.simulation.gains import read_gain_file
    from nonfragile_tracker.control.simulation.tracker import TrackerConfig
    from nonfragile_tracker.control.simulation.reference import circle
    from nonfragile_tracker.control.simulation.simulate import simulate_tracking
    from nonfragile_tracker.interface.scenario import paper_plant_config
    pc = paper_plant_config()
    K = read_gain_file(CONFIG / gains)
    tc = TrackerConfig(K=tuple(map(tuple, np.asarray(K).tolist())), max_angular_speed=2.0,
                       delay_compensation=compensation, A_tau=pc.A_tau, tau=pc.tau)
    run = simulate_tracking(pc, tc, circle(), 6000)
    return run.metrics()


@functools.lru_cache(maxsize=None)
def _latency_design(h_max: float, lag: float):
    """The figures ``latency-design`` records for ``[0, h_max]`` with ``lag``, in process.

    As ``latency-design config/paper_problem.yaml --delay-interval 0 H_MAX --lag LAG
    --gain-bound 8.67`` runs it; its recorded figures settle on a 3-digit grid, the same
    under every BLAS kernel.
    """
    from nonfragile_tracker.control.synthesis.latency_design import design_for_latency
    from nonfragile_tracker.control.synthesis.problem import load_problem
    return design_for_latency(load_problem(CONFIG / 'paper_problem.yaml'), 0.0, h_max,
                              gain_bound=8.67, lag=lag)


SOURCES = {
    'gain.latency_hi': lambda: _design('tracker_gains.yaml')['latency_interval'][1],
    'gain.lag': lambda: _design('tracker_gains.yaml')['actuator_lag'],
    'gain.lag_certified': lambda: _design('tracker_gains.yaml')['lag_certified_h_max'],
    'gain.decay': lambda: _design('tracker_gains.yaml')['certified_decay_rate'],
    'gain.norm': lambda: _design('tracker_gains.yaml')['gain_norm'],
    'gain.margin': lambda: _design('tracker_gains.yaml')['true_delay_margin'],
    'gain.worst_abscissa': lambda: _design('tracker_gains.yaml')['worst_abscissa_on_interval'],
    'gain.bound': lambda: _design('tracker_gains.yaml')['gain_bound'],
    'max_decay.decay': lambda: _design('max_decay_gains.yaml')['certified_value'],
    'max_decay.latency': lambda: _design('max_decay_gains.yaml')['certified_latency'],
    'max_decay.margin': lambda: _design('max_decay_gains.yaml')['true_latency_margin'],
    'design_0_03.decay': lambda: _latency_design(0.03, 0.05).decay_rate,
    'design_0_03.lag_certified': lambda: _latency_design(0.03, 0.05).lag_certified_h_max,
    'demo.settle': lambda: _run('tracker_gains.yaml', True).settling_time,
    'demo.rms': lambda: _run('tracker_gains.yaml', True).rms_error_settled,
    'demo.final': lambda: _run('tracker_gains.yaml', True).final_error,
    'max_decay.settle': lambda: _run('max_decay_gains.yaml', True).settling_time,
    'paper.first': lambda: _run('paper_gains_tracker.yaml', False).first_within,
    'paper.final': lambda: _run('paper_gains_tracker.yaml', False).final_error,
}


def _quotes():
    return [(page.relative_to(ROOT).as_posix(), page.read_text()[:m.start()].count('\n') + 1,
             m['num'], m['unit'] or '', m['name'])
            for page in PAGES for m in TAG.finditer(page.read_text())]


def _rounded(value: float, quoted: str, unit: str) -> float:
    """``value`` (SI) in the unit and to the digits of ``quoted``."""
    x = value * (1000.0 if unit in ('ms', 'mm') else 1.0)
    if 'e' in quoted:
        mantissa = quoted.split('e')[0]
        digits = len(mantissa.split('.')[1]) if '.' in mantissa else 0
        return float(f'{x:.{digits}e}')
    digits = len(quoted.split('.')[1]) if '.' in quoted else 0
    return float(f'{x:.{digits}f}')


def test_every_tag_names_a_source_and_the_main_pages_quote_through_tags():
    quotes = _quotes()
    unknown = [q for q in quotes if q[4] not in SOURCES]
    assert not unknown, unknown
    pages = {q[0] for q in quotes}
    assert {'README.md', 'doc/getting-started.md', 'doc/theory.md'} <= pages, pages
    assert {q[4] for q in quotes} == set(SOURCES)          # no source left unquoted


@pytest.mark.parametrize('page, line, quoted, unit, name', _quotes(),
                         ids=lambda v: str(v) if isinstance(v, (str, int)) else None)
def test_a_quoted_figure_is_its_source_rounded(page, line, quoted, unit, name):
    value = float(SOURCES[name]())
    assert _rounded(value, quoted, unit) == pytest.approx(float(quoted), abs=1e-12), (
        f'{page}:{line}: {name} is quoted as {quoted} {unit}, its source gives {value!r}')


def test_the_check_fails_on_a_stale_figure():
    """A stale demo figure (the old 2.21 s) and a gain figure one digit off are refused."""
    assert _rounded(SOURCES['demo.settle'](), '2.21', 's') != 2.21
    lag = SOURCES['gain.lag_certified']()
    assert _rounded(lag, '0.2209', 's') != pytest.approx(0.2209, abs=1e-12) or \
        _rounded(lag, '0.2207', 's') != pytest.approx(0.2207, abs=1e-12)
    assert TAG.search('[0, 0.15<!-- fig:gain.latency_hi -->] s')['num'] == '0.15'
    assert TAG.search('within 2e-06 m<!-- fig:demo.final -->')['num'] == '2e-06'
