#!/usr/bin/env bash
# Run a command as a machine with AVX2 but without AVX-512 computes (`make test CPU=avx2`):
#   tools/avx2.sh python -m pytest -c pytest.ini -q
# numpy dispatches its loops (sums, products, sin, ...) to the best kernels the CPU has, and
# OpenBLAS (numpy's linalg: solve, lstsq, matrix products) picks a core by the CPU; the
# last bits of a result depend on which. NPY_DISABLE_CPU_FEATURES takes numpy's AVX-512
# kernels out (the names are numpy 2.4's dispatch targets, tools/requirements.txt's pin:
# X86_V4 is AVX-512 F/CD/VL/BW/DQ, the others its later extensions), OPENBLAS_CORETYPE
# makes OpenBLAS use its Haswell (AVX2) kernels. Pinocchio and MuJoCo are compiled for a
# fixed instruction set and compute the same on both. test/workspace/test_avx2_limit.py
# checks the limit takes effect.
export NPY_DISABLE_CPU_FEATURES="X86_V4 AVX512_ICL AVX512_SPR"
export OPENBLAS_CORETYPE=Haswell
exec "$@"
