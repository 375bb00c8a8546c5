"""
tools/avx2.sh (``make test CPU=avx2``) makes numpy and OpenBLAS compute as without AVX-512.

What it sets must take effect with the pinned numpy: a renamed dispatch target would be
refused or ignored, and the suite would then run on AVX-512 while saying AVX2.
"""
import os
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
AVX2 = os.path.join(ROOT, 'tools', 'avx2.sh')

# numpy's dispatch targets on, OpenBLAS's core (OPENBLAS_VERBOSE=2 prints it on stderr)
PROBE = r"""
import numpy as np
from numpy._core._multiarray_umath import __cpu_dispatch__, __cpu_features__
print(' '.join(t for t in __cpu_dispatch__ if __cpu_features__[t]))
a = np.ones((40, 40))
np.linalg.solve(a + 40 * np.eye(40), a[0])
"""


def _probe(*prefix):
    env = dict(os.environ, OPENBLAS_VERBOSE='2')
    for name in ('NPY_DISABLE_CPU_FEATURES', 'NPY_ENABLE_CPU_FEATURES', 'OPENBLAS_CORETYPE'):
        env.pop(name, None)
    out = subprocess.run([*prefix, sys.executable, '-c', PROBE], env=env, capture_output=True,
                         text=True, timeout=60, check=True)
    core = [line for line in out.stderr.splitlines() if line.startswith('Core: ')]
    return out.stdout.split(), core


def test_the_avx2_limit_takes_numpys_avx512_kernels_and_openblas_skylakex_core_off():
    targets, core = _probe('bash', AVX2)
    assert set(targets) <= {'X86_V3'}, targets         # AVX2 (x86-64-v3) at most
    assert core == ['Core: Haswell'], core


def test_without_the_limit_numpy_dispatches_to_what_this_cpu_has():
    # The limit is what changes the kernels: unlimited, this machine's own (on an AVX-512
    # machine X86_V4 among them, on an AVX2 one X86_V3 alone).
    targets, core = _probe()
    assert len(core) == 1, core
    limited, _ = _probe('bash', AVX2)
    assert set(limited) <= set(targets)
    with open('/proc/cpuinfo', encoding='utf-8') as fh:
        avx512 = ' avx512f ' in fh.read()
    assert ('X86_V4' in targets) == avx512, targets


def test_env_sh_runs_openblas_on_one_thread_unless_one_is_chosen():
    # OpenBLAS sizes its thread pool from OPENBLAS_NUM_THREADS when numpy loads it.
    env = {k: v for k, v in os.environ.items() if k != 'OPENBLAS_NUM_THREADS'}
    show = '. tools/env.sh --no-install && echo "$OPENBLAS_NUM_THREADS"'
    out = subprocess.run(['bash', '-c', show], cwd=ROOT, env=env, capture_output=True,
                         text=True, timeout=30).stdout.split()
    assert out == ['1']
    env['OPENBLAS_NUM_THREADS'] = '2'
    out = subprocess.run(['bash', '-c', show], cwd=ROOT, env=env, capture_output=True,
                         text=True, timeout=30).stdout.split()
    assert out == ['2']
