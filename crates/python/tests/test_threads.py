"""A stepping loop on a second thread while the main thread reads positions: the step releases
the GIL, and a read waits for a step to finish instead of seeing half of one."""

from __future__ import annotations

import sys
import threading
import time

import numpy as np

import latent_dynamics as ld
from conftest import tip


def test_main_thread_reads_while_a_thread_steps(pca_path) -> None:
    # Full space on the 8×3×3-cell beam: steps of about a millisecond, long beside the time a
    # waiting thread takes to wake up.
    sim = ld.Simulator(ld.Model.load(pca_path), full_space=True)
    v = tip(sim)
    start = sim.rest_positions[v].copy()
    h = sim.grab(v, 2000.0)
    steps = 60
    frames: list[np.ndarray] = [sim.positions()]
    reads: list[tuple[int, np.ndarray]] = []
    started = threading.Event()
    failure: list[BaseException] = []

    def stepper() -> None:
        try:
            started.set()
            for k in range(1, steps + 1):
                sim.move_handle(h, start + [0.0, 0.1 * np.sin(k / 10), 0.0])
                sim.step()
                frames.append(sim.positions())
        except BaseException as e:  # reported by the main thread
            failure.append(e)

    # With a 100 s switch interval the interpreter never takes the GIL from the thread holding
    # it: the main thread runs Python while the stepper is mid-loop only if step() lets go. It
    # counts how often it ran and now and then reads the state (the read itself waits for a
    # step to end, with the GIL let go, and on a busy machine may wait several steps: the
    # count, not the reads, shows that step() lets go).
    interval = sys.getswitchinterval()
    sys.setswitchinterval(100.0)
    spins = 0
    try:
        thread = threading.Thread(target=stepper)
        thread.start()
        started.wait()
        while thread.is_alive():
            spins += 1
            if spins % 4 == 0:
                reads.append((sim.steps, sim.positions()))
                sim.surface_positions(np.float32)
            # Lets the stepper have the GIL back when its step ends.
            time.sleep(0.0005)
        thread.join()
    finally:
        sys.setswitchinterval(interval)
    assert not failure, failure
    assert sim.steps == steps and len(frames) == steps + 1
    # Holding the GIL through its steps, the stepper would let the main thread run only when it
    # ended (once or twice); letting it go in each step, about once a step.
    assert spins >= 10, f"the main thread ran {spins} times in {steps} steps"
    # And a read does not wait for the whole loop: a step lets the calls that waited for it
    # go before its thread steps again.
    during = [s for s, _ in reads if 0 < s < steps]
    assert len(during) >= 2, f"reads saw steps {[s for s, _ in reads]} only"
    # Every read is the state after a whole step (never a mix of two), no earlier than the step
    # count read just before it.
    for seen_steps, positions in reads:
        matches = [k for k, f in enumerate(frames) if np.array_equal(f, positions)]
        assert matches, "a read matched no state after a whole step"
        assert max(matches) >= seen_steps


def test_two_threads_stepping_one_simulator_take_turns(sim: ld.Simulator) -> None:
    def run() -> None:
        for _ in range(100):
            sim.step()

    threads = [threading.Thread(target=run) for _ in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert sim.steps == 200 and sim.stats.steps == 200
