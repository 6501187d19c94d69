"""jflex.tune_allocator: glibc's thresholds set, bad values refused."""

import ctypes

import numpy as np
import pytest

import jflex
from jflex import _allocator


def test_tune_allocator_keeps_freed_blocks_in_the_heap():
    lib = _allocator._libc()
    if lib is None:
        pytest.skip("not glibc")
    # mmapped blocks count in mallinfo2's 'hblkhd'; heap blocks do not
    lib.malloc.restype = ctypes.c_void_p
    lib.malloc.argtypes = [ctypes.c_size_t]
    lib.free.argtypes = [ctypes.c_void_p]

    class MallInfo2(ctypes.Structure):
        _fields_ = [(k, ctypes.c_size_t) for k in
                    ("arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks", "fsmblks", "uordblks", "fordblks", "keepcost")]

    lib.mallinfo2.restype = MallInfo2

    def mapped_growth(nbytes):
        before = lib.mallinfo2().hblkhd
        ptr = lib.malloc(nbytes)
        during = lib.mallinfo2().hblkhd
        lib.free(ptr)
        return during - before

    assert jflex.tune_allocator(mmap_threshold=128 << 10) is True  # glibc's initial threshold
    assert mapped_growth(4 << 20) >= 4 << 20
    assert jflex.tune_allocator() is True
    assert mapped_growth(4 << 20) == 0


@pytest.mark.parametrize("kw", [{"mmap_threshold": 0}, {"mmap_threshold": 64 << 20}, {"trim_threshold": -1}])
def test_tune_allocator_refuses_bad_values(kw):
    with pytest.raises(ValueError, match="tune_allocator"):
        jflex.tune_allocator(**kw)
