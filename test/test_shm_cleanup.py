"""
The test session's clean-up of Fast DDS shared memory a killed node left (test/conftest.py).

A participant holds an exclusive flock on its ``_el`` files while it lives; a kill -9 leaves
the files without a holder, and a later participant on the same port loses messages.
"""
import fcntl
import os

from freejoint_tools.harness import clean_stale_fast_dds_shm


def test_files_of_a_dead_owner_go_and_those_of_a_live_one_stay(tmp_path):
    for name in ('fastrtps_port7000', 'fastrtps_port7000_el',     # owner killed
                 'fastrtps_port7002_el',                          # the port file gone too
                 'fastrtps_0123abcd', 'fastrtps_0123abcd_el',     # a live segment
                 'fastrtps_port7004',                             # no lock file: unknown
                 'other_el'):                                     # not Fast DDS's
        (tmp_path / name).write_bytes(b'')
    held = os.open(str(tmp_path / 'fastrtps_0123abcd_el'), os.O_RDWR)
    fcntl.flock(held, fcntl.LOCK_EX | fcntl.LOCK_NB)
    try:
        removed = clean_stale_fast_dds_shm(str(tmp_path))
    finally:
        os.close(held)
    assert sorted(removed) == ['fastrtps_port7000', 'fastrtps_port7000_el',
                               'fastrtps_port7002_el']
    assert sorted(os.listdir(tmp_path)) == ['fastrtps_0123abcd', 'fastrtps_0123abcd_el',
                                            'fastrtps_port7004', 'other_el']


def test_a_missing_directory_removes_nothing(tmp_path):
    assert clean_stale_fast_dds_shm(str(tmp_path / 'absent')) == []
