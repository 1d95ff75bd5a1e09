"""What the three LMI certificates share: the numpy check, its record, the result record.

Theorem 1 (:mod:`.lmi`), the delay-dependent design (:mod:`.delay_dependent`) and the
input-delay design (:mod:`.input_delay`) prove stability with different
Lyapunov-Krasovskii functionals, but each certificate is checked the same way, in numpy,
from the returned matrices alone (never from the solver's word): :func:`eigen_figures`
computes the eigenvalues, :func:`passes` decides; :class:`Verification` is the base of the
three verification records, :class:`CertifiedGain` of the three synthesis results.

See doc/theory.md, section "How every certificate is checked" (the rules), and the
derivations (#theorem-1, #delay-dependent-design, #input-delay-command-latency).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from typing import Any, ClassVar, Sequence

import numpy as np

from .sdp import sym

__all__ = ['Verification', 'CertifiedGain', 'from_certificate', 'eigen_figures',
           'min_eigenvalue', 'passes', 'retry_advice', 'signs_hold']


def min_eigenvalue(M: Any) -> float:
    """Smallest eigenvalue of the symmetric part of ``M``.

    Parameters
    ----------
    M : array_like, shape (k, k)
        A matrix of a certificate that must be positive definite.

    Returns
    -------
    float
    """
    return float(np.linalg.eigvalsh(sym(np.asarray(M, float)))[0])


def eigen_figures(matrix: np.ndarray, positive: Sequence[Any] = ()
                  ) -> tuple[float, float, list[float]]:
    """Eigenvalue figures of a certificate: ``(max eig, ||matrix||, min eigs of positive)``.

    Parameters
    ----------
    matrix : numpy.ndarray, shape (k, k)
        The symmetric certificate matrix that must be negative definite.
    positive : sequence of array_like
        The matrices that must be positive definite (their symmetric parts are used).

    Returns
    -------
    top : float
        Largest eigenvalue of ``matrix`` (``inf`` if anything is not finite).
    scale : float
        Its spectral norm, the largest absolute eigenvalue (``inf`` likewise).
    mins : list of float
        The smallest eigenvalue of each of ``positive`` (``-inf`` likewise).
    """
    mats = [np.asarray(M, float) for M in positive]
    if not (np.all(np.isfinite(matrix)) and all(np.all(np.isfinite(M)) for M in mats)):
        return math.inf, math.inf, [-math.inf] * len(mats)
    ev = np.linalg.eigvalsh(matrix)
    return float(ev[-1]), float(np.max(np.abs(ev))), [min_eigenvalue(M) for M in mats]


def signs_hold(mins: Sequence[float], scalar: float | None) -> bool:
    """The sign conditions: every smallest eigenvalue > 0 and the Petersen scalar > 0.

    Parameters
    ----------
    mins : sequence of float
        Smallest eigenvalues of the matrices that must be positive definite.
    scalar : float or None
        The Petersen scalar; ``None``: the nominal condition, none.

    Returns
    -------
    bool
    """
    return bool(all(m > 0 for m in mins) and (scalar is None or scalar > 0))


def passes(top: float, scale: float, mins: Sequence[float], scalar: float | None,
           tol: float) -> bool:
    """The verdict of :func:`eigen_figures`' figures (module docstring).

    Parameters
    ----------
    top, scale : float
        Largest eigenvalue and spectral norm of the certificate matrix.
    mins : sequence of float
        Smallest eigenvalues of the matrices that must be positive definite.
    scalar : float or None
        The Petersen scalar (must be > 0); ``None``: the nominal condition, none.
    tol : float
        Relative slack: ``top < -tol * scale``.

    Returns
    -------
    bool
    """
    return bool(top < -tol * scale and signs_hold(mins, scalar))


def retry_advice(solver: str) -> str:
    """What to try when a solver's point fails the numpy check (the error messages' end).

    Parameters
    ----------
    solver : str
        The cvxpy solver that produced the point.

    Returns
    -------
    str
    """
    return ('Raise the margin (options.margin).' if solver == 'CLARABEL'
            else 'Use CLARABEL or raise the margin (options.margin).')


@dataclass(frozen=True)
class Verification:
    """Base of the numpy verdicts of the LMI modules (module docstring).

    The subclasses add the figures of their certificate as fields; ``tolerance`` and
    ``scale`` are keyword-only here so that the subclasses' own fields keep their place
    after ``ok``.

    Parameters
    ----------
    ok : bool
        Every check passes.
    tolerance : float
        The relative slack demanded: ``max eig < -tolerance * scale``.
    scale : float
        Spectral norm of the certificate matrix.
    """

    ok: bool
    tolerance: float = field(kw_only=True)
    scale: float = field(kw_only=True)

    #: name of the certificate matrix in the reports (``V``, ``Psi``)
    MATRIX: ClassVar[str] = 'V'
    #: the field holding its largest eigenvalue
    WORST: ClassVar[str] = ''
    #: ``(field, name in the reports)`` of the smallest eigenvalues of the positive matrices
    POSITIVE: ClassVar[tuple[tuple[str, str], ...]] = ()

    @property
    def worst_eigenvalue(self) -> float:
        """Largest eigenvalue of the certificate matrix (verified below ``-tolerance * scale``)."""
        return float(getattr(self, self.WORST))

    def describe(self) -> str:
        """The eigenvalue figures on one line, as the reports and error messages print them.

        Returns
        -------
        str
            ``max eig V = ..., min eig P = ..., ...`` (4 significant digits).
        """
        parts = [f'max eig {self.MATRIX} = {self.worst_eigenvalue:.4g}']
        parts += [f'min eig {name} = {float(getattr(self, key)):.4g}'
                  for key, name in self.POSITIVE]
        return ', '.join(parts)

    def as_dict(self) -> dict[str, Any]:
        """Every field by name (numbers, bools, ``None``), e.g. for a JSON record.

        Returns
        -------
        dict
        """
        return {f.name: getattr(self, f.name) for f in fields(self)}


@dataclass(frozen=True, kw_only=True)
class CertifiedGain:
    """Base of the synthesis results: a gain, its verified certificate, the solver's facts.

    Parameters
    ----------
    K : numpy.ndarray, shape (m, n)
        The gain.
    certificate : object
        The module's certificate record.
    margin_required, margin_achieved : float
        Strictness ``t`` asked for and reached (normalised units of the module's LMI).
    status : str
        The solver's status of the chosen point.
    solver : str
        The cvxpy solver used.
    solve_time : float
        Seconds inside the solver (summed over the solves of a search).
    wall_time : float
        Seconds for building, solving and verifying.
    nominal : bool
        The nominal condition (no ``E D F`` terms).
    extra : dict
        Facts of the synthesis route (rules, retries, solve counts, warnings).
    """

    K: np.ndarray
    certificate: Any
    margin_required: float
    margin_achieved: float
    status: str
    solver: str
    solve_time: float
    wall_time: float
    nominal: bool
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def gain_norm(self) -> float:
        """Spectral norm ``||K||_2`` of the gain."""
        return float(np.linalg.norm(self.K, 2))


def from_certificate(name: str, doc: str) -> Any:
    """A read-only property of a result: ``self.certificate.<name>``.

    Parameters
    ----------
    name : str
        The certificate's field.
    doc : str
        The property's docstring.

    Returns
    -------
    property
    """
    def get(self: CertifiedGain) -> Any:
        return getattr(self.certificate, name)

    return property(get, doc=doc)
