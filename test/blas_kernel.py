"""Which OpenBLAS kernel numpy runs, and the second kernel ``make test`` runs the numerical
tests under.

OpenBLAS (numpy's wheels: DYNAMIC_ARCH) picks its kernels by CPU, unless
``OPENBLAS_CORETYPE`` names one: the solver's iterates then differ in the last digits, and
the suite must pass on any CPU.  ``make test`` runs the tests marked ``numerical`` a second
time under another kernel than the machine's (``python test/blas_kernel.py`` prints the
``OPENBLAS_CORETYPE=...`` assignment for it, and says so on stderr when there is none):

* x86-64: ``Sandybridge`` (AVX, older than every AVX2 kernel) when the CPU has AVX and the
  machine's kernel is not Sandybridge already, else ``Prescott`` (SSE3: every x86-64 CPU
  runs it; OpenBLAS reports it as ``Katmai``);
* aarch64: ``ARMV8`` (the generic kernel) unless it is the machine's;
* anything else, or no kernel older than the machine's: none - the pass runs under the
  default kernel and says so (``test/test_blas_kernel.py`` reports it as skipped).

``python test/blas_kernel.py --current`` prints the kernels in use (threadpoolctl: numpy's and
scipy's and cvxpy's OpenBLAS, comma-separated).
"""
from __future__ import annotations

import platform
import sys
from pathlib import Path

#: What OpenBLAS reports (threadpoolctl ``architecture``) for each ``OPENBLAS_CORETYPE``
#: this module sets: numpy's and scipy's OpenBLAS name Prescott's kernels Katmai's, the older
#: OpenBLAS that cvxpy's solvers load (0.3.15) Prescott.
REPORTED = {'Sandybridge': {'Sandybridge'}, 'Prescott': {'Katmai', 'Prescott'},
            'ARMV8': {'ARMV8'}}


def current_kernels() -> set[str]:
    """The OpenBLAS kernels the numerical stack runs (``architecture`` of threadpoolctl, one
    per library: numpy's, scipy's and the older one cvxpy's solvers bring), empty when none
    is OpenBLAS."""
    import numpy  # noqa: F401  (loads the BLAS libraries, which threadpoolctl then finds)
    import scipy.linalg  # noqa: F401
    import cvxpy  # noqa: F401
    from threadpoolctl import threadpool_info
    return {str(lib.get('architecture') or 'unknown') for lib in threadpool_info()
            if lib.get('internal_api') == 'openblas'}


def cpu_flags() -> set[str]:
    """The CPU's feature flags (``/proc/cpuinfo``; empty where there is none)."""
    try:
        text = Path('/proc/cpuinfo').read_text()
    except OSError:
        return set()
    for line in text.splitlines():
        if line.startswith(('flags', 'Features')):
            return set(line.split(':', 1)[1].split())
    return set()


def second_kernel(machine: str, current: set[str], flags: set[str]) -> tuple[str | None, str]:
    """``(OPENBLAS_CORETYPE or None, why)`` for the second pass (module docstring).

    Parameters
    ----------
    machine : str
        ``uname -m``.
    current : set of str
        The kernels in use (:func:`current_kernels`).
    flags : set of str
        The CPU's feature flags (:func:`cpu_flags`).
    """
    now = ', '.join(sorted(current)) or 'none'
    if machine in ('x86_64', 'AMD64'):
        if 'avx' in flags and not current & REPORTED['Sandybridge']:
            return 'Sandybridge', f'x86-64 with AVX, machine kernel {now}'
        if not current & REPORTED['Prescott']:
            return 'Prescott', f'x86-64, machine kernel {now}'
        return None, f'x86-64 already on the oldest kernel ({now})'
    if machine in ('aarch64', 'arm64'):
        if not current & REPORTED['ARMV8']:
            return 'ARMV8', f'aarch64, machine kernel {now}'
        return None, 'aarch64 already on the generic ARMV8 kernel'
    return None, f'no second OpenBLAS kernel chosen for the architecture {machine!r}'


def main(argv: list[str]) -> int:
    """Print the kernel in use (``--current``) or the second pass's assignment."""
    current = current_kernels()
    if argv[1:] == ['--current']:
        print(','.join(sorted(current)) or 'unknown')
        return 0
    kernel, why = second_kernel(platform.machine(), current, cpu_flags())
    if kernel is None:
        print(f'\n*** make test: the numerical tests run a second time under the DEFAULT BLAS '
              f'kernel: {why} ***\n', file=sys.stderr)
        print('NONFRAGILE_NO_SECOND_KERNEL=1')
    else:
        print(f'make test: the numerical tests again under OPENBLAS_CORETYPE={kernel} ({why})',
              file=sys.stderr)
        print(f'OPENBLAS_CORETYPE={kernel}')
    return 0


if __name__ == '__main__':
    sys.exit(main(sys.argv))
