"""The singularity map's command line (freejoint_tools.spatial_map): runs and refusals."""

from freejoint_core import spatial_map as sm
from freejoint_tools import spatial_map as cli
import numpy as np
import pytest


def _same(a, b):
    assert (a.samples, a.near, a.kappa_max) == (b.samples, b.near, b.kappa_max)
    for name in ('hist', 'voxels', 'count', 'near_count', 'kappa_low', 'worst'):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name


def test_the_command_writes_the_map_of_its_arguments_and_prints_its_summary(tmp_path, capsys):
    out = str(tmp_path / 'ur5.npz')
    code = cli.main(['--arm', 'ur5', '--free', 'wrist_2_joint', '--samples', '1200', '--chunk',
                     '500', '--voxel', '0.1', '--out', out, '--quiet'])
    assert code == 0
    text = capsys.readouterr().out
    assert text.startswith('singularity map ur5 (free: wrist_2_joint), m = 3, nominal 0.7, '
                           '1200 samples (seed 0, chunks of 500)\n')
    assert 'kappa quantiles (to 1.2 %): 0.1 % ' in text
    assert '1200 samples in ' in text and 'this process' in text and f'map: {out}' in text
    spec = sm.known_spec('ur5', ['wrist_2_joint'], samples=1200, chunk=500, voxel=0.1)
    written = sm.load(out)
    assert written.spec == spec
    _same(written, sm.compute_map(spec))


def test_two_worker_processes_write_the_same_map_as_one(tmp_path, capsys):
    paths = [str(tmp_path / f'{w}.npz') for w in (1, 2)]
    for workers, path in zip((1, 2), paths):
        assert cli.main(['--arm', 'panda', '--free', 'panda_joint7', '--samples', '900',
                         '--chunk', '200', '--workers', str(workers), '--out', path,
                         '--quiet']) == 0
    assert '2 worker process(es)' in capsys.readouterr().out
    _same(sm.load(paths[0]), sm.load(paths[1]))


def test_a_urdf_file_is_mapped_as_the_known_arm_of_the_same_file(tmp_path, capsys):
    spec = sm.known_spec('ur5', [], samples=300, chunk=300, m=6)
    urdf = tmp_path / 'arm.urdf'
    urdf.write_text(spec.urdf)
    out = str(tmp_path / 'arm.npz')
    assert cli.main(['--urdf', str(urdf), '--base-link', 'base_link', '--tip-link', 'tool0',
                     '--samples', '300', '--chunk', '300', '--task-dim', '6', '--out', out,
                     '--quiet']) == 0
    assert 'singularity map arm.urdf (free: none), m = 6' in capsys.readouterr().out
    _same(sm.load(out), sm.compute_map(spec))


@pytest.mark.parametrize('argv,line', [
    (['--samples', '0'], 'spatial_map: samples: expected 1 .. '),
    (['--free', 'nope'], "spatial_map: passive: 'nope' is not a joint of the chain"),
    (['--arm', 'kuka'], "spatial_map: name: expected one of ['panda', 'ur5'], got 'kuka'"),
    (['--voxel', '-1'], 'spatial_map: voxel: must be finite and > 0, got -1.0'),
    (['--workers', '0'], 'spatial_map: workers: expected >= 1, got 0'),
    (['--urdf', 'x.urdf'], 'spatial_map: urdf: --urdf needs --base-link and --tip-link'),
    (['--arm', 'ur5', '--urdf', 'x.urdf'], 'spatial_map: arm: give --arm or --urdf, not both'),
    (['--tip-link', 'tool0'], 'spatial_map: base_link: --base-link and --tip-link go with'),
    (['--out', '/no/such/folder/map.npz'], "spatial_map: out: no folder '/no/such/folder'")])
def test_a_bad_argument_ends_with_one_line_naming_it_exit_2(argv, line, capsys):
    assert cli.main(argv + ['--quiet']) == 2
    err = capsys.readouterr().err
    assert err.startswith(line) and err.count('\n') == 1
