"""``harness.kernels``: error bounds of the fast exp/log, bit casts, the task counter, the serial
guard and the backend handle."""

from __future__ import annotations

import copy

import numba
import numpy as np
import pytest
from numba import njit

from harness import kernels, load_backend

TINY = np.finfo(np.float32).tiny


# ---------------------------------------------------------------- fast exp and log
# Each is evaluated inside a vectorised fastmath loop, as the filters call them: reassociation
# must not undo the Cody-Waite split or the exponent arithmetic.


@njit(fastmath=True)
def _exp_neg_array(d):
    out = np.empty_like(d)
    for j in range(d.size):
        out[j] = kernels.exp_neg(d[j])
    return out


@njit(fastmath=True)
def _exp2_minus_array(t):
    out = np.empty_like(t)
    for i in range(t.shape[0]):
        out[i] = kernels.exp2_minus(t[i])
    return out


@njit(fastmath=True, error_model="numpy")
def _fast_log_array(x):
    out = np.empty(x.shape[0], np.float64)
    for i in range(x.shape[0]):
        out[i] = kernels.fast_log(x[i])
    return out


def test_exp_neg_error_bound():
    """Within a few float32 ulps of exp(-d) on [0, 87]; clamped at exp(-87) above."""
    d = np.concatenate([np.linspace(0, 87, 200001), [1e-30, 0.5, 40.0, 86.99]]).astype(np.float32)
    exact = np.exp(-d.astype(np.float64))
    assert np.max(np.abs(_exp_neg_array(d) / exact - 1)) < 3e-7
    big = np.array([87.0, 100.0, 1e30, np.float32(3.4e38)], np.float32)
    np.testing.assert_allclose(_exp_neg_array(big), np.exp(-kernels.EXP_NEG_CLAMP), rtol=1e-6)
    assert np.all(_exp_neg_array(big) >= TINY)  # never 0, a normal float


def test_exp2_minus_error_bound():
    t = np.linspace(0.0, kernels.T_MAX, 2_000_001).astype(np.float32)
    got = _exp2_minus_array(t).astype(np.float64)
    assert np.max(np.abs(got / np.exp2(-t.astype(np.float64)) - 1.0)) < 5e-7
    special = _exp2_minus_array(np.array([0.0, 1e-30, kernels.T_MAX + 1e-3, 1e30, 3e38], np.float32))
    assert special[0] == 1.0 and special[1] == 1.0
    assert np.all(special[2:] == 0.0)


def test_exp2_minus_is_a_normal_float_down_to_its_cut():
    """The power of two goes into the exponent bits: right below ``T_MAX`` the result must
    still be the correct (normal) value, not a wrapped exponent."""
    t = np.float32(kernels.T_MAX) - np.linspace(0.0, 1.0, 1001).astype(np.float32)
    got = _exp2_minus_array(t).astype(np.float64)
    assert np.all(got >= TINY)
    assert np.max(np.abs(got / np.exp2(-t.astype(np.float64)) - 1.0)) < 5e-7


def test_fast_log_error_bound():
    rng = np.random.default_rng(0)
    x = np.exp(rng.uniform(-87.0, 88.0, 200_000)).astype(np.float32)
    x = np.concatenate([x, np.float32([1.0, 0.5, 2.0, TINY, 3e38, 0.70710677])])
    assert np.max(np.abs(_fast_log_array(x) - np.log(x.astype(np.float64)))) < 1e-10


# ---------------------------------------------------------------- bit casts


@njit
def _round_trip(x):
    bits = np.empty(x.shape, np.int32)
    back = np.empty_like(x)
    for i in range(x.size):
        bits[i] = kernels.float32_bits_as_int32(x[i])
        back[i] = kernels.int32_bits_as_float32(bits[i])
    return bits, back


def test_bit_casts_reinterpret_the_bits():
    x = np.array([0.0, -0.0, 1.0, -2.5, TINY, 3e38, np.inf, -np.inf, np.nan, 1e-45], np.float32)
    bits, back = _round_trip(x)
    np.testing.assert_array_equal(bits, x.view(np.int32))
    assert back.tobytes() == x.tobytes()  # NaN and -0.0 included


def test_bit_casts_refuse_other_types():
    @njit
    def cast_int64(v):
        return kernels.int32_bits_as_float32(v)

    with pytest.raises(numba.TypingError):
        cast_int64(np.int64(1))


@njit
def _round_trip64(x):
    bits = np.empty(x.shape, np.int64)
    back = np.empty_like(x)
    for i in range(x.size):
        bits[i] = kernels.float64_bits_as_int64(x[i])
        back[i] = kernels.int64_bits_as_float64(bits[i])
    return bits, back


def test_64_bit_casts_reinterpret_the_bits():
    x = np.array([0.0, -0.0, 1.0, -2.5, 2.0**-1022, 5e-324, 1.7e308, np.inf, -np.inf, np.nan])
    bits, back = _round_trip64(x)
    np.testing.assert_array_equal(bits, x.view(np.int64))
    assert back.tobytes() == x.tobytes()  # NaN and -0.0 included


def test_64_bit_casts_refuse_other_types():
    @njit
    def cast_int32(v):
        return kernels.int64_bits_as_float64(v)

    @njit
    def cast_float32(v):
        return kernels.float64_bits_as_int64(v)

    with pytest.raises(numba.TypingError):
        cast_int32(np.int32(1))
    with pytest.raises(numba.TypingError):
        cast_float32(np.float32(1))


# ---------------------------------------------------------------- the task counter


@njit(parallel=True)
def _take_all(tasks, workers):
    counter = np.zeros(1, np.int64)
    taken = np.zeros(tasks, np.int64)
    for _ in numba.prange(workers):
        while True:
            task = kernels.take(counter)
            if task >= tasks:
                break
            taken[task] += 1
    return taken


@njit(parallel=True)
def _rows_taken(n, size, threads):
    counter = np.zeros(1, np.int64)
    taken = np.zeros(n, np.int64)
    for _ in numba.prange(kernels.thread_count(threads, n, size)):
        while True:
            start, stop = kernels.take_range(counter, n, size)
            if start >= stop:
                break
            for i in range(start, stop):
                taken[i] += 1
    return taken


def test_task_counter_hands_out_every_task_once():
    """Under parallel threads (mutation check: with a plain load and store instead of the atomic
    add, tasks are handed out twice)."""
    for workers in (1, 2, 7):
        assert (_take_all(100_000, workers) == 1).all()


@pytest.mark.parametrize("n,size", [(0, 4), (1, 4), (719, 4), (720, 4), (100_003, 64), (5, 1)])
def test_ranges_cover_every_item_once(n, size):
    for threads in (1, 2, 7):
        assert (_rows_taken(n, size, threads) == 1).all()


def test_thread_count():
    assert kernels.thread_count(2, 720, 4) == 2
    assert kernels.thread_count(8, 9, 4) == 3  # one per range
    assert kernels.thread_count(2, 0, 4) == 1  # at least one


# ---------------------------------------------------------------- the serial guard


def test_serial_below_runs_small_images_on_one_thread():
    threads = numba.get_num_threads()
    if threads < 2:
        pytest.skip("one thread only")
    with kernels.serial_below(100 * 100) as serial:
        assert serial and numba.get_num_threads() == 1
    assert numba.get_num_threads() == threads
    with kernels.serial_below(kernels.SERIAL_MAX_PIXELS) as serial:
        assert not serial and numba.get_num_threads() == threads
    with kernels.serial_below(1, enabled=False) as serial:
        assert not serial and numba.get_num_threads() == threads
    with pytest.raises(RuntimeError), kernels.serial_below(1):
        raise RuntimeError("the thread count comes back after an error too")
    assert numba.get_num_threads() == threads


# ---------------------------------------------------------------- the backend handle


class _Filter:
    def __init__(self):
        self.ops = load_backend("plugins.filters.taa", "cpu", ("cpu", "cuda"), owner="test")
        self.history = [np.zeros(3)]


def test_backend_handle_copies_as_itself():
    import plugins.filters.taa.cpu as module

    f = _Filter()
    assert isinstance(f.ops, kernels.BackendHandle) and f.ops.target is module
    assert f.ops.resolve is module.resolve  # attributes are the module's
    g = copy.deepcopy(f)
    assert g.ops is f.ops and copy.copy(f.ops) is f.ops  # shared, not copied
    assert g.history[0] is not f.history[0]  # the rest is copied as usual
    with pytest.raises(AttributeError):
        _ = f.ops.no_such_kernel
