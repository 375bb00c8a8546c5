"""The simulator's per-step timing arrays (bench instrumentation) and their file."""
from freejoint_sim.timing import StepTiming
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
