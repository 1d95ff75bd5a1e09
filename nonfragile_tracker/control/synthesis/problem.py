"""Synthesis problems (A, B, A_tau, tau, E, F, options): validation and YAML files.

:class:`Problem` holds one problem, validated (every check names the offending field; all
errors are :class:`~nonfragile_tracker.control.synthesis.errors.ProblemError`); problem
files are YAML mappings read and written here.

See doc/cli.md, section "Gain synthesis and analysis" (the problem file).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from ...errors import InputError
from ...files import read_yaml
from .. import validate
from .errors import ProblemError

__all__ = ['ProblemError', 'Problem', 'as_matrix', 'load_problem', 'problem_from_mapping',
           'is_stabilizable']


def as_matrix(value: Any, name: str, shape: tuple[int | None, int | None] | None = None
              ) -> np.ndarray:
    """:func:`.control.validate.as_matrix` raising :class:`.ProblemError` (problem files).

    Parameters
    ----------
    value : array_like
        Nested lists of numbers, an array or a scalar.
    name : str
        What the value is, for the message (a file field).
    shape : (rows, cols), optional
        Required shape; ``None`` entries are free.

    Returns
    -------
    numpy.ndarray
        A finite 2-D float array.
    """
    return validate.as_matrix(value, name, shape, error=ProblemError)


def is_stabilizable(A: np.ndarray, B: np.ndarray, tol: float = 1e-9) -> tuple[bool, list[complex]]:
    """PBH test: return (stabilizable, unstabilizable eigenvalues) for continuous time.

    Parameters
    ----------
    A : numpy.ndarray, shape (n, n)
        State matrix.
    B : numpy.ndarray, shape (n, m)
        Input matrix.
    tol : float, optional
        Eigenvalues with a real part below ``-tol`` count as stable; singular values
        below ``tol`` times the largest (at least 1) count as zero.

    Returns
    -------
    stabilizable : bool
    unstabilizable : list of complex
        The eigenvalues of ``A`` (real part ``>= -tol``) that ``B`` does not reach.
    """
    n = A.shape[0]
    bad = []
    for lam in np.linalg.eigvals(A):
        if lam.real < -tol:
            continue
        pbh = np.hstack([A - lam * np.eye(n), B])
        sv = np.linalg.svd(pbh, compute_uv=False)
        if np.sum(sv > tol * max(1.0, sv[0])) < n:
            bad.append(complex(lam))
    return (not bad, bad)


@dataclass(frozen=True)
class Problem(validate.StateInputShape):
    """Data of Theorem 1: ``xi' = (A + B(K + E D F)) xi + A_tau xi(t - tau)``."""

    A: np.ndarray
    B: np.ndarray
    A_tau: np.ndarray
    tau: float
    E: np.ndarray
    F: np.ndarray
    name: str = 'problem'
    perturbations: Mapping[str, np.ndarray] = field(default_factory=dict)
    options: Mapping[str, Any] = field(default_factory=dict)

    def gain(self, K: Any) -> np.ndarray:
        """``K`` as a float array of this problem's gain shape ``(m, n)``: the one K-shape check.

        Parameters
        ----------
        K : array_like
            A state-feedback gain.

        Returns
        -------
        numpy.ndarray
            ``K`` as a float array (its values are not checked: a certificate check of a
            non-finite gain fails on its own).

        Raises
        ------
        InputError
            (a :class:`ValueError`) when the shape is not ``(m, n)``.
        """
        gain = np.asarray(K, float)
        if gain.shape != (self.m, self.n):
            raise InputError(f'K must have shape {(self.m, self.n)}, got {gain.shape}')
        return gain

    def replace(self, **changes: Any) -> 'Problem':
        """Return a validated copy with some fields changed.

        Parameters
        ----------
        **changes
            New values of fields (``A``, ``B``, ``A_tau``, ``tau``, ``E``, ``F``, ``name``,
            ``perturbations``, ``options``), validated as in a problem file (the
            stabilizability check left out).

        Returns
        -------
        Problem
        """
        data = dict(A=self.A, B=self.B, A_tau=self.A_tau, tau=self.tau, E=self.E, F=self.F,
                    name=self.name, perturbations=dict(self.perturbations),
                    options=dict(self.options))
        data.update(changes)
        return problem_from_mapping(data, check_stabilizable=False)


_KNOWN_KEYS = {'name', 'A', 'B', 'A_tau', 'tau', 'E', 'F', 'perturbations', 'options',
               'description'}


def problem_from_mapping(data: Mapping[str, Any], *, source: str = 'problem',
                         check_stabilizable: bool = True) -> Problem:
    """Validate a mapping and build a :class:`Problem`; errors name ``source`` and the field.

    Parameters
    ----------
    data : mapping
        The keys of a problem file (see the module docstring).
    source : str, optional
        Where the mapping comes from (a file path), for the messages; its stem is the
        problem's name when ``data`` has none.
    check_stabilizable : bool, optional
        Refuse an ``(A, B)`` that is not stabilizable (:func:`is_stabilizable`).

    Returns
    -------
    Problem

    Raises
    ------
    ProblemError
        Naming ``source`` and the field, for a missing or unknown key, a malformed
        matrix, a bad ``tau`` or option, or an unstabilizable ``(A, B)``.
    """
    if not isinstance(data, Mapping):
        got = 'an empty file' if data is None else f'a {type(data).__name__}'
        raise ProblemError(f'{source}: expected a mapping with keys A, B, A_tau, tau, E, F; '
                           f'got {got}')
    missing = [k for k in ('A', 'B', 'A_tau', 'tau', 'E', 'F') if k not in data]
    if missing:
        raise ProblemError(f'{source}: missing key(s) {", ".join(missing)}; a problem needs '
                           'A, B, A_tau, tau, E and F (see config/paper_problem.yaml)')
    unknown = sorted(set(data) - _KNOWN_KEYS)
    if unknown:
        raise ProblemError(f'{source}: unknown key(s) {", ".join(unknown)}; '
                           f'allowed: {", ".join(sorted(_KNOWN_KEYS))}')
    A = as_matrix(data['A'], f'{source}: A')
    n = A.shape[0]
    if A.shape != (n, n):
        raise ProblemError(f'{source}: A must be square, got shape {A.shape}')
    B = as_matrix(data['B'], f'{source}: B', (n, None))
    m = B.shape[1]
    A_tau = as_matrix(data['A_tau'], f'{source}: A_tau', (n, n))
    E = as_matrix(data['E'], f'{source}: E', (m, None))
    F = as_matrix(data['F'], f'{source}: F', (None, n))
    tau = data['tau']
    if isinstance(tau, bool) or not isinstance(tau, (int, float)) or not math.isfinite(tau) \
            or tau < 0:
        raise ProblemError(f'{source}: tau must be a finite number >= 0 (seconds), got {tau!r}')
    perts = {}
    for key, val in dict(data.get('perturbations') or {}).items():
        perts[str(key)] = as_matrix(val, f'{source}: perturbations.{key}', (E.shape[1], F.shape[0]))
    options = data.get('options') or {}
    if not isinstance(options, Mapping):
        raise ProblemError(f'{source}: options must be a mapping, got {options!r}')
    options = dict(options)
    for key, low, inclusive in (('gain_bound', 0.0, False), ('margin', 0.0, True)):
        if options.get(key) is not None:
            options[key] = validate.as_finite_float(options[key], f'{source}: options.{key}',
                                                    low=low, low_inclusive=inclusive,
                                                    error=ProblemError)
    if 'solver' in options and not isinstance(options['solver'], str):
        raise ProblemError(f'{source}: options.solver must be a solver name such as CLARABEL, '
                           f'got {options["solver"]!r}')
    if check_stabilizable:
        ok, bad = is_stabilizable(A, B)
        if not ok:
            raise ProblemError(
                f'{source}: (A, B) is not stabilizable: eigenvalue(s) '
                f'{", ".join(f"{z.real:.4g}{z.imag:+.4g}j" for z in bad)} of A are not reached '
                'by B; no state feedback can stabilize this model')
    return Problem(A=A, B=B, A_tau=A_tau, tau=float(tau), E=E, F=F,
                   name=str(data.get('name', Path(source).stem if source != 'problem'
                                     else 'problem')),
                   perturbations=perts, options=dict(options))


def load_problem(path: str | Path) -> Problem:
    """Read and validate a problem YAML file.

    Parameters
    ----------
    path : str or pathlib.Path
        The YAML file (see the module docstring).

    Returns
    -------
    Problem
        The validated problem (:func:`problem_from_mapping`).

    Raises
    ------
    ProblemError
        If the file cannot be read or parsed, or its content is malformed.
    """
    data = read_yaml(path, 'problem file', error=ProblemError)
    return problem_from_mapping(data, source=str(path))
