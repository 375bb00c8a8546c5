"""The simulator's per-step timing arrays (bench instrumentation) and their file."""
from freejoint_sim.timing import StepObserver, StepTiming, WRITE_DELAY
import numpy as np


def test_a_command_label_maps_to_the_step_whose_state_had_that_stamp():
    timing = StepTiming('unused.npz', 40)
    timing.stamp_ns[:] = 1_000_000_000 + 1_000_000 * np.arange(40)
    assert timing.step_of_stamp(1_000_000_000 + 1_000_000 * 30, 33) == 30
    assert timing.step_of_stamp(1_000_000_000 + 1_000_000 * 34, 33) == -1   # not yet
    assert timing.step_of_stamp(1_000_000_000 + 1_000_000 * 5, 33) == -1    # too old
    assert timing.step_of_stamp(1_000_000_000 + 1_000_000 * 39, 45) == 39   # past the end


def test_the_file_holds_the_arrays_and_is_written_once(tmp_path):
    path = str(tmp_path / 'sub' / 'timing.npz')
    timing = StepTiming(path, 3)
    timing.published[:] = [1.0, 2.0, 3.0]
    timing.received[1] = 2.5
    timing.applied[:] = [0, -1, 2]
    timing.dropped = 4
    assert timing.write('realtime', 0.001) == path and timing.written
    data = np.load(path)
    assert data['published'].tolist() == [1.0, 2.0, 3.0]
    assert np.isnan(data['received'][0]) and data['received'][1] == 2.5
    assert data['applied'].tolist() == [0, -1, 2]
    assert int(data['dropped']) == 4 and str(data['mode']) == 'realtime'
    assert float(data['dt']) == 0.001


def test_as_an_observer_it_notes_the_first_lockstep_answer_and_writes_once_when_the_run_ends(
        tmp_path):
    lines = []
    timing = StepTiming(str(tmp_path / 't.npz'), 3, 'lockstep', 0.001, lines.append)
    for k in range(3):
        timing.state_published(k, k * 1_000_000)
        timing.command_answered(k, 10.0 + k)
        timing.command_answered(k, 99.0)          # a repeat: the first answer counts
    timing.state_published(3, 3_000_000)          # beyond the window: ignored
    timing.run_over()
    timing.run_over()
    data = np.load(str(tmp_path / 't.npz'))
    assert data['received'].tolist() == [10.0, 11.0, 12.0]
    assert data['applied'].tolist() == [0, 1, 2]
    assert data['stamp_ns'].tolist() == [0, 1_000_000, 2_000_000]
    assert str(data['mode']) == 'lockstep' and float(data['dt']) == 0.001
    assert lines == ['timing of steps 0..2 written to %s' % (tmp_path / 't.npz')]


def test_as_an_observer_it_maps_real_time_commands_and_writes_after_the_delay(tmp_path):
    path = str(tmp_path / 'rt.npz')
    timing = StepTiming(path, 4, 'realtime', 0.001)
    for k in range(4):
        timing.state_published(k, 5_000 + k)
    assert timing.command_received(5_002, 3, 7.5) == 2
    assert timing.command_received(None, 3, 7.6) == -1     # no label: unknown step
    timing.command_applied(3, 2)
    timing.steps_dropped(2)
    timing.step_done(4 + WRITE_DELAY - 1)
    assert not timing.written
    timing.step_done(4 + WRITE_DELAY)
    assert timing.written
    data = np.load(path)
    assert data['received'][2] == 7.5 and data['applied'].tolist() == [-1, -1, -1, 2]
    assert int(data['dropped']) == 2 and str(data['mode']) == 'realtime'


def test_the_default_observer_does_nothing_and_answers_no_step():
    observer = StepObserver()
    observer.state_published(0, 0)
    observer.command_answered(0, 1.0)
    assert observer.command_received(0, 0, 1.0) == -1
    observer.command_applied(0, 0)
    observer.steps_dropped(1)
    observer.step_done(0)
    observer.run_over()
