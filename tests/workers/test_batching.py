"""The adaptive batch-size rule as a pure function."""

import math

import pytest

from finaldrive.workers.batching import DRIVER_SHARE, PRIOR_DESIGNS, TARGET_OVERHEAD, BatchSizer, batch_size


def overhead_fraction(b: int, per_design_s: float, overhead_s: float) -> float:
    return overhead_s / (b * per_design_s)


@pytest.mark.parametrize(
    ("per_design_s", "overhead_s"), [(1.6, 0.002), (0.01, 0.002), (0.001, 0.002), (1e-4, 0.0015)]
)
def test_smallest_batch_with_overhead_under_the_target(per_design_s: float, overhead_s: float) -> None:
    b = batch_size(remaining=10**6, num_workers=2, per_design_s=per_design_s, overhead_s=overhead_s)
    assert overhead_fraction(b, per_design_s, overhead_s) <= TARGET_OVERHEAD + 1e-12
    assert b == 1 or overhead_fraction(b - 1, per_design_s, overhead_s) > TARGET_OVERHEAD


def test_slow_simulations_go_one_per_task() -> None:
    assert batch_size(remaining=400, num_workers=2, per_design_s=1.6, overhead_s=0.002) == 1


def test_cap_leaves_four_waves_for_every_worker() -> None:
    # cheap designs would want huge batches; the cap keeps 4 batches per worker
    b = batch_size(remaining=400, num_workers=2, per_design_s=1e-6, overhead_s=0.01)
    assert b == 400 // (2 * 4)


def test_the_work_that_starts_first_spreads_over_every_worker() -> None:
    """23 DE generations of 50 beside a sweep on 256 workers: one wave of 5 designs a task, not
    tasks sized for the sweep; on 2 workers the same generations are not cut for latency."""
    def size(num_workers: int, first: int | None) -> int:
        return batch_size(remaining=46_690, num_workers=num_workers, per_design_s=0.005, overhead_s=0.01,
                          first=first)

    overhead_alone = math.ceil(0.01 / (TARGET_OVERHEAD * 0.005))
    assert size(256, first=1150) == 5
    assert size(256, first=None) == min(overhead_alone, 46_690 // (256 * 4))  # the overhead, or four waves
    assert size(2, first=1150) == overhead_alone


@pytest.mark.parametrize("remaining", [1, 2, 7])
def test_few_designs_still_give_batches_of_one(remaining: int) -> None:
    assert batch_size(remaining=remaining, num_workers=8, per_design_s=1e-6, overhead_s=1.0) == 1


def test_nothing_remaining() -> None:
    assert batch_size(remaining=0, num_workers=2, per_design_s=1.0, overhead_s=0.0) == 0


def test_unknown_compute_time_uses_the_cap() -> None:
    assert batch_size(remaining=80, num_workers=2, per_design_s=0.0, overhead_s=0.01) == 10


def test_sizer_probes_then_sizes_from_measurements() -> None:
    sizer = BatchSizer(num_workers=2)
    assert sizer.next_size(1000) == 1                          # probe
    sizer.observe(1, round_trip_s=1.010, busy_s=1.0, compute_s=0.9)   # cold: 0.1 s warm-up
    assert sizer.overhead_s == pytest.approx(0.010)
    assert sizer.next_size(1000) == math.ceil(0.010 / (TARGET_OVERHEAD * 0.9))
    sizer.observe(1, round_trip_s=0.902, busy_s=0.9, compute_s=0.9)   # warm: smaller overhead wins
    assert sizer.overhead_s == pytest.approx(0.002)
    assert sizer.next_size(1000) == 1


def test_a_source_after_others_starts_from_their_measurements_and_soon_from_its_own() -> None:
    """Rule 1: no probe where the executor was measured; the earlier per-design time counts as
    PRIOR_DESIGNS designs, so the new source's own results outweigh it after a task or two."""
    earlier = BatchSizer(num_workers=256)
    earlier.observe(1000, round_trip_s=0.3, busy_s=0.2, compute_s=1.0, idle_s=0.001)  # 1 ms a design
    later = BatchSizer.after(earlier)
    assert later.next_size(10**5) > BatchSizer(num_workers=256).next_size(10**5) == 1
    assert later.overhead_s == earlier.overhead_s and later.num_workers == 256
    assert later.compute_s / later.designs_done == pytest.approx(1e-3) and later.designs_done == PRIOR_DESIGNS
    later.observe(10 * PRIOR_DESIGNS, round_trip_s=0.1, busy_s=0.05, compute_s=10 * PRIOR_DESIGNS * 5e-3)
    assert later.compute_s / later.designs_done == pytest.approx((1e-3 + 10 * 5e-3) / 11)  # its own 5 ms dominate
    earlier.observe(1, round_trip_s=0.3, busy_s=0.2, compute_s=1.0, idle_s=0.5)
    assert len(later.idle_s) == 1  # a copy, not the earlier source's deque


def test_sizer_takes_the_workers_median_idle_gap_when_it_exceeds_the_smallest_round_trip() -> None:
    """Round trips of queued tasks hide the overhead (their smallest is the least-queued one's); a
    worker's wait between tasks shows it. A few long waits (no work queued) do not move the median."""
    sizer = BatchSizer(num_workers=2)
    sizer.observe(10, round_trip_s=0.104, busy_s=0.1, compute_s=0.1)          # a worker's first task
    assert sizer.overhead_s == pytest.approx(0.004)
    for idle in [0.008] * 7 + [2.0] * 3:
        sizer.observe(10, round_trip_s=0.2, busy_s=0.1, compute_s=0.1, idle_s=idle)
    assert sizer.overhead_s == pytest.approx(0.008)
    assert sizer.next_size(10**6) == math.ceil(0.008 / (TARGET_OVERHEAD * sizer.compute_s / sizer.designs_done))
    for _ in range(64):  # only the recent tasks count
        sizer.observe(10, round_trip_s=0.2, busy_s=0.1, compute_s=0.1, idle_s=0.001)
    assert sizer.overhead_s == pytest.approx(0.004)  # the smallest round trip is the floor


def test_sizer_ignores_negative_overhead_from_clock_noise() -> None:
    sizer = BatchSizer(num_workers=1)
    sizer.observe(4, round_trip_s=0.99, busy_s=1.0, compute_s=1.0)
    assert sizer.overhead_s == 0.0


@pytest.mark.parametrize(("num_workers", "driver_s"), [(256, 2e-4), (64, 7e-4), (1000, 5e-5)])
def test_batches_large_enough_for_the_dispatcher_to_keep_up(num_workers: int, driver_s: float) -> None:
    # a DE generation (50 designs) on a big cluster: waves alone would send one design a task
    per_design_s = 0.05
    b = batch_size(remaining=50, num_workers=num_workers, per_design_s=per_design_s, overhead_s=0.0,
                   driver_s=driver_s)

    def load(size: int) -> float:  # share of the dispatching thread's time the task traffic takes
        return num_workers * driver_s / (size * per_design_s)

    assert load(b) <= DRIVER_SHARE + 1e-12
    assert b == 1 or load(b - 1) > DRIVER_SHARE


def test_keeping_up_never_makes_tasks_longer_than_half_a_second() -> None:
    b = batch_size(remaining=10**6, num_workers=256, per_design_s=0.25, overhead_s=0.0, driver_s=0.01)
    assert b == 2


def test_an_idle_dispatcher_changes_nothing() -> None:
    args = {"remaining": 400, "num_workers": 2, "per_design_s": 0.01, "overhead_s": 0.002}
    assert batch_size(**args, driver_s=3e-4) == batch_size(**args) == math.ceil(0.002 / (TARGET_OVERHEAD * 0.01))


def test_waited_on_work_on_a_wide_cluster_balances_hand_out_against_run_time() -> None:
    # 23 DE generations of 50 designs (1,150) on 256 CPUs, 4 ms a design, 0.65 ms of driver a task:
    # rule 4 alone would put a whole generation in one task; rule 5 finishes the round soonest
    first, c, d = 1150, 0.004, 6.5e-4
    args = {"remaining": 50_000, "num_workers": 256, "per_design_s": c, "overhead_s": 0.001, "driver_s": d}
    bulk = batch_size(**args, first=first)
    waited = batch_size(**args, first=first, waited=True)

    def round_s(b: int) -> float:  # the driver hands the round's tasks out one by one; a task runs b designs
        return math.ceil(first / b) * d + b * c

    assert bulk >= 50 and waited == math.ceil(math.sqrt(first * d / c)) == 14
    assert round_s(waited) < 0.5 * round_s(bulk)
    assert all(round_s(waited) <= round_s(b) * 1.05 for b in range(1, 200))  # the best size, within rounding


def test_waited_on_work_on_a_small_cluster_keeps_one_wave() -> None:
    # the same round on 2 workers: rules 1-4 already run it in one wave of large tasks; rule 5 changes nothing
    args = {"remaining": 50_000, "num_workers": 2, "per_design_s": 0.004, "overhead_s": 0.001, "driver_s": 6.5e-4}
    assert batch_size(**args, first=1150, waited=True) == batch_size(**args, first=1150)


def test_a_wide_task_holds_whole_rounds_of_its_threads_but_a_generation_is_not_cut() -> None:
    """16 threads a task, designs of 4 ms on 256 CPUs: a sweep's task is a multiple of 16 designs (no
    last round part-empty); the last piece of what remains, a size under 16, and a waited-on request
    keep their sizes."""
    args = {"num_workers": 16, "per_design_s": 0.004 / 16, "overhead_s": 0.001, "driver_s": 6.5e-4}
    one_thread = batch_size(remaining=10**6, **args)
    wide = batch_size(remaining=10**6, **args, threads=16)
    assert one_thread % 16 and wide % 16 == 0 and one_thread - 16 < wide < one_thread
    assert batch_size(remaining=wide - 3, **args, threads=16) == wide - 3  # what remains, whole
    assert batch_size(remaining=10, **args, threads=16) == 10
    assert batch_size(remaining=10**6, **args, threads=10**4) == one_thread
    first = {"remaining": 10**6, "first": 1150, "waited": True}
    assert batch_size(**first, **args, threads=16) == batch_size(**first, **args) == math.ceil(1150 / 16) == 72
