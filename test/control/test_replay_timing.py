"""
bench/replay_timing.py: a run's timing put through the loop and the plant in one process.

The pattern read from a timing file is checked against hand-made arrays; a pattern with
every state answered at once tracks as the loop does, and a 30-period silence of the loop
(the driver keeping its command) trips the guard, holds and finishes the plan; the saved
pattern of a soak run that lost the arm keeps it now.
"""
import json
import math
import os

from freejoint_tools.harness import load_source
import numpy as np
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
replay_timing = load_source(os.path.join(ROOT, 'bench', 'replay_timing.py'), 'replay_timing')


def test_the_pattern_keeps_which_states_were_taken_how_late_and_which_answer_was_applied():
    # 8 states on a 1-ms grid from 100 s; state 4 published 2 ms late, states 3 and 4
    # never answered (their periods applied the answer of state 2), the others answered
    # 0.5 ms after publication
    stamps = np.array([int(100e9) + j * 1_000_000 for j in range(8)])
    pub = 50.0 + np.arange(8) * 0.001
    pub[4] += 0.002
    rec = pub + 0.0005
    rec[[3, 4]] = np.nan
    applied = np.array([0, 1, 2, 2, 2, 5, 6, 7])
    timing = {'stamp_ns': stamps, 'published': pub, 'received': rec, 'applied': applied}
    pat = replay_timing.pattern(timing, 100.003, before=0.002, after=0.004)
    # from state 1 (3 - 2) to state 6 (3 + 4 - 1): periods 0..5
    assert pat.applied == [0, 1, 1, 1, 4, 5]
    assert sorted(pat.taken) == [0, 1, 4, 5]
    for r in (0, 1, 4, 5):                       # 0.5 ms less the answer's own 0.2 ms
        assert math.isclose(pat.taken[r], 0.0003, abs_tol=1e-9)


def test_every_state_answered_at_once_tracks_within_the_vertical_bound():
    n = 200
    pat = replay_timing.Pattern(dict.fromkeys(range(n), 0.0003), list(range(n)))
    out = replay_timing.run(pat, 1.0, seed=0)
    assert out['done'] and not out['tripped'] and not out['damped']
    assert out['worst'] < 0.0055                 # the soak's vertical bound, 5.51 mm


def test_a_30_period_silence_trips_the_guard_and_the_hold_keeps_the_arm():
    # periods 10..39 not answered, the driver keeping the answer of period 9 (a gap of 30
    # states > readiness_max_gap 10): the guard trips, the law holds, the plan pauses
    # and finishes
    n = 200
    silent = range(10, 40)
    pat = replay_timing.Pattern({r: 0.0003 for r in range(n) if r not in silent},
                                [9 if r in silent else r for r in range(n)])
    out = replay_timing.run(pat, 1.0, seed=0)
    assert out['tripped'] and out['done'] and not out['damped']
    assert out['worst'] < replay_timing.LOST


def test_a_saved_pattern_replays_as_the_timing_file_it_came_from(tmp_path, capsys):
    # a timing file of 400 states, every one answered 0.5 ms after it went out
    n = 400
    timing = tmp_path / 'timing.npz'
    pub = 50.0 + np.arange(n) * 0.001
    np.savez(timing, stamp_ns=np.array([int(100e9) + j * 1_000_000 for j in range(n)]),
             published=pub, received=pub + 0.0005, applied=np.arange(n))
    saved = tmp_path / 'pattern.json'
    args = ['--at', '1.0', '--seeds', '1', '--before', '0.05', '--after', '0.2']
    assert replay_timing.main([str(timing), '100.1', '--save', str(saved)] + args) == 0
    from_file = capsys.readouterr().out
    assert replay_timing.main([str(saved)] + args) == 0
    assert capsys.readouterr().out == from_file
    assert from_file.splitlines()[-1].startswith('as configured: 0 of 1 runs lost the arm; '
                                                 'the others ')


def test_a_made_event_runs_on_either_arm_and_a_bad_one_is_refused(capsys):
    # A 30-ms stall of the loop 1 s into the horizontal circle: the guard trips (a gap of
    # 30 states), the law's hold stops along the path, the plan pauses and finishes.
    assert replay_timing.main(['--event', 'stall', '30', '--case', 'horizontal', '--at', '1.0',
                               '--seeds', '1']) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].startswith('at 1.00 s seed 0: ') and lines[0].endswith('damped hold no')
    assert lines[1].startswith('as configured: 0 of 1 runs lost the arm; ')
    out = replay_timing.run_event('stall', 1.0, 30, case='horizontal')
    assert out['done'] and not out['damped'] and out['worst'] < 0.0017   # the bound
    with pytest.raises(SystemExit):
        replay_timing.main(['--event', 'jolt', '3'])
    assert "--event: expected one of push, reset, starve, stall, got 'jolt'" in \
        capsys.readouterr().err
    with pytest.raises(ValueError, match='^event: expected one of'):
        replay_timing.run_event('jolt', 1.0, 3)


def test_the_lost_soak_run_replayed_keeps_the_arm_by_stopping_along_the_path():
    # The SCHED_FIFO hold-last soak run that lost the vertical arm, 2.5 s into the circle,
    # seed 0: held where the arm was at the gap's trip (readiness_stop_acceleration 0),
    # the law's hold went past 50 mm, the damped joint hold took over and the free link
    # fell (1.28 m); stopped along the circle first it stays on its path (2.4 mm).
    with open(os.path.join(ROOT, 'bench', 'patterns', 'hold_last_vertical_loss.json')) as f:
        saved = json.load(f)
    pat = replay_timing.Pattern({int(r): v for r, v in saved['taken'].items()},
                                saved['applied'])
    held = replay_timing.run(pat, 2.5, seed=0, overrides={'readiness_stop_acceleration': 0.0})
    assert held['damped'] and held['worst'] > replay_timing.LOST
    stopped = replay_timing.run(pat, 2.5, seed=0)
    assert stopped['tripped'] and not stopped['damped'] and stopped['done']
    assert stopped['worst'] < 0.010
