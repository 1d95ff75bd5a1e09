"""The tracking law, defined once: a scalar form and its vectorised form, operation for operation.

:func:`feedback` is the scalar form (the tracker runs it with its limits, timing, delay
compensation and predictor around it); :class:`VectorLaw` is the same operations on arrays
of cases, with the speed limits applied as the tracker applies them, for the batch's loops.
``ordered=True`` sums in the scalar order, so a case equals the scalar law bit for bit;
``ordered=False`` sums ``K e`` first, the same value to round-off with fewer operations.

See doc/theory.md, section "Model" (the law's equations).
"""
from __future__ import annotations

from typing import Any, Sequence

import numpy as np

__all__ = ['feedback', 'VectorLaw']

# ufuncs bound once (the vector law runs some 20 of them a step)
_sub, _mul, _add, _fmax, _fmin = np.subtract, np.multiply, np.add, np.maximum, np.minimum
_einsum, _addred = np.einsum, np.add.reduce


def feedback(x: float, y: float, cth: float, sth: float, v: float,
             xd: Sequence[float], ud: Sequence[float], K: Sequence[Sequence[float]],
             min_speed: float
             ) -> tuple[tuple[float, float, float, float], float, float, float, float, bool]:
    """The law at one pose: error, input, acceleration and turn rate (scalar form).

    Parameters
    ----------
    x, y : float
        Position (m).
    cth, sth : float
        Cosine and sine of the heading.
    v : float
        Compensator speed (m/s).
    xd : sequence of 4 float
        Reference state ``(x, x', y, y')``.
    ud : sequence of 2 float
        Feedforward input ``(x'', y'')``.
    K : 2 x 4 nested sequence of float
        The gain in force.
    min_speed : float
        The speed floor of the division (m/s).

    Returns
    -------
    (e, u1, u2, a, w, floored)
        The error, the input, the unclipped ``a`` and ``w``, and whether ``v`` was floored.
    """
    e = (x - xd[0], v * cth - xd[1], y - xd[2], v * sth - xd[3])
    K0, K1 = K
    u1 = ud[0] + K0[0] * e[0] + K0[1] * e[1] + K0[2] * e[2] + K0[3] * e[3]
    u2 = ud[1] + K1[0] * e[0] + K1[1] * e[1] + K1[2] * e[2] + K1[3] * e[3]
    floored = abs(v) < min_speed
    vf = (min_speed if v >= 0 else -min_speed) if floored else v
    return e, u1, u2, u1 * cth + u2 * sth, (u2 * cth - u1 * sth) / vf, floored


class VectorLaw:
    """:func:`feedback` for ``n`` cases at once, with the speed limits, into given buffers.

    Per call of :meth:`command`: the error ``e`` (``E``, rows ``x, x', y, y'``), the input
    ``u`` (``U``), then ``v_next = clip(v + a h, +-max_linear_speed)`` and
    ``w = clip(w, +-max_angular_speed)`` (``nan`` stays ``nan``) written into ``out``.

    Parameters
    ----------
    n : int
        Number of cases.
    max_linear_speed, max_angular_speed, min_speed : float
        The tracker's limits and speed floor.
    ordered : bool
        Sum ``u`` in the scalar order (bit for bit) instead of ``K e`` first.
    """

    def __init__(self, n: int, max_linear_speed: float, max_angular_speed: float,
                 min_speed: float, ordered: bool):
        c0 = np.array                               # 0-d constants: no conversion per call
        self.vmax, self.nvmax = c0(float(max_linear_speed)), c0(-float(max_linear_speed))
        self.wmax, self.nwmax = c0(float(max_angular_speed)), c0(-float(max_angular_speed))
        self.vmin = float(min_speed)
        self._vmin_n, self._zero = np.full(n, self.vmin), np.zeros(n)
        self.E = np.empty((4, n))                   # e: x, x', y, y'
        self._epos, self._evel = self.E[0::2], self.E[1::2]
        self.U = np.empty((2, n))
        self._uc = np.empty((2, n))
        self._vabs = np.empty(n)
        self._vf = np.empty(n)
        self.ordered = ordered
        if ordered:
            self._prod = np.empty((2, 5, n))        # u* and the four K_j e_j terms

    def floored(self, v: np.ndarray) -> np.ndarray:
        """``v`` floored to ``|v| >= min_speed`` with its sign (``+`` at ``-0.0``; nan stays).

        Parameters
        ----------
        v : numpy.ndarray
            Speeds (n,).

        Returns
        -------
        numpy.ndarray
            A buffer of the law's, overwritten by the next call.
        """
        vabs, vf = self._vabs, self._vf
        np.absolute(v, out=vabs)
        np.maximum(vabs, self._vmin_n, out=vabs)
        np.add(v, self._zero, out=vf)               # -0.0 + 0.0 is +0.0
        np.copysign(vabs, vf, out=vf)
        return vf

    def command(self, Kc: np.ndarray, pos: Any, cs: np.ndarray, v: np.ndarray, xpos: Any,
                xvel: Any, ud: Any, h: Any, out: np.ndarray, floor: bool | None = None
                ) -> None:
        """``(v_next, w)`` of every case into ``out`` (2, n).

        Parameters
        ----------
        Kc : numpy.ndarray
            The gains in force (2, 4, n).
        pos : numpy.ndarray
            Positions (2, n).
        cs : numpy.ndarray
            Cosine and sine of the headings (2, n).
        v : numpy.ndarray
            Compensator speeds (n,).
        xpos, xvel, ud : array_like
            The reference's position, velocity and feedforward, each (2, 1) (shared) or
            (2, n).
        h : float or numpy.ndarray
            The coming interval (s) of the speed ramp.
        out : numpy.ndarray
            Where ``(v_next, w)`` go (2, n).
        floor : bool, optional
            Whether some ``|v| < min_speed`` (default: looked at; a caller that knows it
            from the previous step says so).
        """
        epos, evel, U, uc = self._epos, self._evel, self.U, self._uc
        _sub(pos, xpos, out=epos)
        _mul(cs, v, out=evel)
        _sub(evel, xvel, out=evel)
        if self.ordered:            # u* + K_0 e_0 + ... + K_3 e_3, left to right
            prod = self._prod
            prod[:, 0] = ud
            _mul(Kc, self.E, out=prod[:, 1:])
            _addred(prod, axis=1, out=U)
        else:
            _einsum('ijn,jn->in', Kc, self.E, out=U)
            U += ud
        if floor is None:
            floor = not (np.minimum.reduce(np.absolute(v, out=self._vabs)) >= self.vmin)
        vf = self.floored(v) if floor else v
        cv, w = out
        uc0, uc1 = uc
        _mul(U, cs, out=uc)                         # u1 cos, u2 sin
        _add(uc0, uc1, out=cv)                      # a
        cv *= h
        cv += v                                     # v + a h
        _mul(U, cs[::-1], out=uc)                   # u1 sin, u2 cos
        _sub(uc1, uc0, out=w)
        w /= vf
        _fmax(w, self.nwmax, out=w)                 # nan stays nan
        _fmin(w, self.wmax, out=w)
        _fmax(cv, self.nvmax, out=cv)
        _fmin(cv, self.vmax, out=cv)
