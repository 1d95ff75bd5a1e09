"""The second BLAS kernel of ``make test`` (test/blas_kernel.py): chosen per architecture,
and really in use in the second pass."""
import os

import pytest

from blas_kernel import REPORTED, current_kernels, second_kernel

pytestmark = pytest.mark.numerical


def test_second_kernel_is_chosen_per_architecture():
    assert second_kernel('x86_64', {'Haswell'}, {'avx', 'avx2'})[0] == 'Sandybridge'
    assert second_kernel('x86_64', {'Zen'}, {'avx'})[0] == 'Sandybridge'
    assert second_kernel('x86_64', {'Sandybridge'}, {'avx'})[0] == 'Prescott'
    assert second_kernel('x86_64', {'Nehalem'}, {'sse4_2'})[0] == 'Prescott'
    assert second_kernel('x86_64', {'Katmai', 'Prescott'}, set())[0] is None
    assert second_kernel('aarch64', {'NEOVERSEN1'}, {'asimd'})[0] == 'ARMV8'
    assert second_kernel('aarch64', {'ARMV8'}, set())[0] is None
    kernel, why = second_kernel('ppc64le', {'POWER9'}, set())
    assert kernel is None and 'ppc64le' in why


def test_this_pass_runs_the_kernel_make_test_asked_for():
    """In make test's second pass (NONFRAGILE_FIRST_KERNEL: the first pass's kernels) numpy's
    and scipy's OpenBLAS run the kernel OPENBLAS_CORETYPE names, not the first pass's."""
    now = current_kernels()
    assert now and 'unknown' not in now, \
        'numpy or scipy does not use OpenBLAS: the kernel cannot be chosen'
    asked = os.environ.get('OPENBLAS_CORETYPE')
    if asked in REPORTED:
        assert now <= REPORTED[asked], (asked, now)
    first = os.environ.get('NONFRAGILE_FIRST_KERNEL')
    if first is None:
        return                                      # not make test's second pass
    if os.environ.get('NONFRAGILE_NO_SECOND_KERNEL'):
        pytest.skip(f'no second BLAS kernel on this machine: both passes ran {sorted(now)}')
    assert not now & set(first.split(',')), f'the second pass ran the first pass\'s {first}'
