"""CyclePacer: absolute deadlines, what it records, and the scheduling it reports."""

import ast
import os
import resource
import subprocess
import sys

import pytest

from hil.realtime import CyclePacer, PeriodStatistics, lock_step_cpus, real_time_cpus

PERIOD = 0.001


class FakeTime:
    """A clock that moves only when the loop sleeps or works (and a hair per reading, as the
    pacer's spin reads it until the deadline)."""

    def __init__(self):
        self.now = 100.0
        self.sleeps: list[float] = []

    def clock(self) -> float:
        self.now += 1e-7
        return self.now

    def sleep(self, seconds: float) -> None:
        self.sleeps.append(seconds)
        self.now += seconds

    def work(self, seconds: float) -> None:
        self.now += seconds


@pytest.fixture
def fake():
    return FakeTime()


def pacer_for(fake: FakeTime, statistics: PeriodStatistics) -> CyclePacer:
    return CyclePacer(PERIOD, statistics, priority=0, clock=fake.clock, sleep=fake.sleep)


def test_pacer_releases_on_absolute_deadlines_and_records_period_and_busy(fake):
    statistics = PeriodStatistics(PERIOD)
    pacer = pacer_for(fake, statistics)
    releases = []
    for _ in range(50):
        pacer.release()
        releases.append(fake.now)
        fake.work(0.3 * PERIOD)
    gaps = [b - a for a, b in zip(releases, releases[1:])]
    assert gaps == pytest.approx([PERIOD] * 49, abs=1e-6)
    assert releases[-1] - releases[0] == pytest.approx(49 * PERIOD, abs=1e-6)   # no drift
    assert statistics.count == 49 and statistics.missed == 0
    assert list(statistics.busy) == pytest.approx([0.3 * PERIOD] * 49, abs=1e-6)
    # it sleeps to SPIN before the deadline and spins the rest
    assert fake.sleeps and max(fake.sleeps) <= 0.7 * PERIOD - CyclePacer.SPIN + 1e-6


def test_pacer_counts_an_overrun_as_missed_and_catches_up_on_the_old_schedule(fake):
    statistics = PeriodStatistics(PERIOD)
    pacer = pacer_for(fake, statistics)
    pacer.release()
    start = fake.now
    fake.work(2.5 * PERIOD)                      # one cycle runs long
    pacer.release()
    fake.work(0.1 * PERIOD)
    pacer.release()
    fake.work(0.1 * PERIOD)
    pacer.release()
    assert statistics.missed == 1
    assert statistics.samples[0] == pytest.approx(2.5 * PERIOD, abs=1e-6)
    assert fake.now - start == pytest.approx(3 * PERIOD, abs=1e-6)   # back on its deadlines


def test_pacer_starts_afresh_after_a_stall_longer_than_resync_periods(fake):
    statistics = PeriodStatistics(PERIOD)
    pacer = pacer_for(fake, statistics)
    pacer.release()
    fake.work((CyclePacer.RESYNC + 5) * PERIOD)
    pacer.release()
    stalled = fake.now
    pacer.release()
    assert fake.now - stalled == pytest.approx(PERIOD, abs=1e-6)   # not a burst of cycles


class LateWaker(FakeTime):
    """A host whose sleeps end late: ``usual`` (s) late, and ``rare`` late every ``every``-th."""

    def __init__(self, usual: float, rare: float, every: int):
        super().__init__()
        self.usual, self.rare, self.every = usual, rare, every

    def sleep(self, seconds: float) -> None:
        super().sleep(seconds + (self.rare if len(self.sleeps) % self.every == 0
                                 else self.usual))


def run_cycles(fake: FakeTime, pacer: CyclePacer, cycles: int) -> list[float]:
    releases = []
    for _ in range(cycles):
        pacer.release()
        releases.append(fake.now)
        fake.work(0.3 * PERIOD)
    return releases


def test_pacer_spins_for_the_wake_up_lateness_it_measured_and_keeps_its_deadlines():
    fake = LateWaker(usual=30e-6, rare=80e-6, every=50)    # 2 % of wake-ups 80 us late
    statistics = PeriodStatistics(PERIOD)
    pacer = pacer_for(fake, statistics)
    assert pacer.spin == statistics.spin == CyclePacer.SPIN     # until it has measured
    releases = run_cycles(fake, pacer, 3 * CyclePacer.SPIN_WINDOW)
    assert pacer.spin == pytest.approx(80e-6, abs=1e-6)        # the 99th percentile
    assert statistics.summary().startswith("normal scheduling, spin 80 us;")
    gaps = [b - a for a, b in zip(releases, releases[1:])]
    assert gaps == pytest.approx([PERIOD] * len(gaps), abs=1e-6)      # never late


def test_pacer_spin_follows_the_host_between_its_least_and_its_most():
    fake = LateWaker(usual=0.0, rare=0.0, every=1)          # wakes on time: the least spin
    pacer = pacer_for(fake, PeriodStatistics(PERIOD))
    run_cycles(fake, pacer, CyclePacer.SPIN_WINDOW + 1)
    assert pacer.spin == CyclePacer.MIN_SPIN
    fake.usual = fake.rare = 0.4e-3                          # then the host gets noisy
    run_cycles(fake, pacer, CyclePacer.SPIN_WINDOW + 1)
    assert pacer.spin == CyclePacer.SPIN                     # capped, however late it wakes


def test_pacer_says_when_real_time_scheduling_is_refused(monkeypatch):
    def refuse(pid, policy, param):
        raise PermissionError(1, "Operation not permitted")

    monkeypatch.setattr(os, "sched_setscheduler", refuse)
    statistics = PeriodStatistics(PERIOD)
    CyclePacer(PERIOD, statistics, priority=50).close()
    assert statistics.scheduling.startswith("normal scheduling (SCHED_FIFO 50 refused: "
                                            "Operation not permitted")
    assert "CAP_SYS_NICE" in statistics.scheduling
    assert statistics.summary().startswith(statistics.scheduling)   # `hil control` prints it


def test_pacer_takes_sched_fifo_and_gives_it_back_on_close(monkeypatch):
    calls = []
    monkeypatch.setattr(os, "sched_setscheduler",
                        lambda pid, policy, param: calls.append((pid, policy,
                                                                 param.sched_priority)))
    statistics = PeriodStatistics(PERIOD)
    pacer = CyclePacer(PERIOD, statistics, priority=50)
    assert statistics.scheduling == "SCHED_FIFO 50"
    pacer.close()
    pacer.close()                                # once only
    assert calls == [(0, os.SCHED_FIFO, 50), (0, os.SCHED_OTHER, 0)]


def test_pacer_priority_zero_keeps_the_normal_scheduler(monkeypatch):
    monkeypatch.setattr(os, "sched_setscheduler",
                        lambda *args: pytest.fail("asked for real-time scheduling"))
    statistics = PeriodStatistics(PERIOD)
    CyclePacer(PERIOD, statistics, priority=0).close()
    assert statistics.scheduling == "normal scheduling"


def test_statistics_keep_the_latest_cycles_in_order_and_count_them_all():
    statistics = PeriodStatistics(PERIOD, keep=4)
    for n in range(1, 7):                        # periods 1..6 ms, busy a tenth of each
        statistics.add(n * PERIOD, n * PERIOD / 10)
    assert statistics.samples == pytest.approx([0.003, 0.004, 0.005, 0.006])
    assert statistics.busy == pytest.approx([0.0003, 0.0004, 0.0005, 0.0006])
    assert (statistics.count, statistics.missed) == (6, 5)       # over 1.5 ms: cycles 2-6
    assert statistics.figures()["error_max_us"] == pytest.approx(5000)
    assert "(the latest 4)" in statistics.summary()
    statistics.clear()
    statistics.add(PERIOD, 0.0)
    assert list(statistics.samples) == [PERIOD] and statistics.count == 1


def test_lock_step_puts_sim_and_controller_on_one_cpu_and_real_time_on_one_each():
    # lock-step: the two take turns, so one CPU for both; the visualiser on the others
    assert lock_step_cpus({0, 1}) == ({1}, {1}, {0})
    assert lock_step_cpus({0, 1, 2, 3}) == ({3}, {3}, {0, 1, 2})
    # real time: a CPU each, the visualiser on the rest (anywhere with two)
    assert real_time_cpus({0, 1, 2, 3}) == ({2}, {3}, {0, 1})
    assert real_time_cpus({0, 1}) == ({0}, {1}, None)
    assert lock_step_cpus({5}) == real_time_cpus({5}) == (None, None, None)


#: a background process with a thread started under SCHED_IDLE leaves it: whether it did,
#: and every thread's policy after
LEAVING_THE_BACKGROUND = """
import os, threading
from hil.realtime import enter_background, leave_background
enter_background()
held = threading.Event()
thread = threading.Thread(target=held.wait)
thread.start()
left = leave_background()
print(left, [os.sched_getscheduler(int(tid)) for tid in os.listdir("/proc/self/task")])
held.set()
"""


def _may_leave_sched_idle() -> bool:
    """Whether Linux lets this user leave SCHED_IDLE at nice 0 (sched(7)): CAP_SYS_NICE, or
    an RLIMIT_NICE of 20."""
    with open("/proc/self/status") as status:
        effective = int(next(line for line in status if line.startswith("CapEff:")).split()[1],
                        16)
    return bool(effective & (1 << 23)) or resource.getrlimit(resource.RLIMIT_NICE)[0] >= 20


def test_a_background_process_leaves_sched_idle_with_every_thread_where_linux_allows():
    done = subprocess.run([sys.executable, "-c", LEAVING_THE_BACKGROUND], capture_output=True,
                          text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    left, policies = done.stdout.split(" ", 1)
    idle = os.SCHED_IDLE in ast.literal_eval(policies)
    if _may_leave_sched_idle():
        assert left == "True" and not idle, done.stdout
    else:           # refused: it says so, and the threads stay where they were
        assert left == "False" and idle, done.stdout
