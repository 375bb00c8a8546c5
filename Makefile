# freejoint: `make demo` runs the main job, `make test` runs every test.
# Each target sets the workspace up first (tools/setup.sh: idempotent, seconds when done).
SHELL := /bin/bash
.DEFAULT_GOAL := help
# Every target keeps Python's bytecode (and pytest's rewritten test modules) in
# .stamps/pycache, also where the environment sets PYTHONDONTWRITEBYTECODE: else each node
# process of a demo, a soak or a test compiles the packages it imports again (numpy, rclpy,
# the nodes' modules: about 1 CPU-s where the venv holds no bytecode, as uv installs it) and
# each test worker every test module it collects (about 7 CPU-s).
PYCACHE = PYTHONDONTWRITEBYTECODE= PYTHONPYCACHEPREFIX=$$PWD/.stamps/pycache
ENV = . tools/env.sh && $(PYCACHE)
# Test processes (pytest-xdist workers): three per two cores (the node-process tests mostly
# wait; two per core starve the real-time graphs' nodes, which then run longer: on 2 cores,
# 3 workers spent 10-13 % less CPU than 4 at the same wall time, docs/performance.md), at
# most 8; JOBS=1 runs the tests one after the other in one process. The graph tests give
# the simulator a 30-s command deadline and the nodes' collected writers the collector's
# depth, so a slowed machine neither zeroes a command nor loses a message of the test's
# (docs/performance.md, "The test suite").
JOBS ?= $(shell n=$$(nproc 2>/dev/null || echo 1); j=$$(( (3 * n + 1) / 2 )); echo $$(( j > 8 ? 8 : j )))
XDIST = $(if $(filter 1,$(JOBS)),,-n $(JOBS) --dist worksteal)
# make test-fast: one worker per core unless JOBS is given. Its tests compute and never
# wait, so a second worker per core only adds its start, its collection and its imports
# (numba, Pinocchio, MuJoCo, matplotlib: each worker imports what its tests need).
FAST_JOBS = $(if $(filter command line environment,$(origin JOBS)),$(JOBS),$(shell n=$$(nproc 2>/dev/null || echo 1); echo $$(( n > 8 ? 8 : n ))))
FAST_XDIST = $(if $(filter 1,$(FAST_JOBS)),,-n $(FAST_JOBS) --dist worksteal)
# make test and make test-fast: the linters skip the files they found clean before at the
# same path in a checkout with the same bytes, linters and configuration (test/lint_cache.py;
# the marks in the user's cache, shared by checkouts); CI (CI set, as .ci/run runs) lints
# every file.
LINT_CACHE = $(if $(CI),,FREEJOINT_LINT_CACHE=$${FREEJOINT_LINT_CACHE-$${FREEJOINT_CACHE:-$${XDG_CACHE_HOME:-$$HOME/.cache}/freejoint}/lint})
# CPU=avx2: the tests compute as a machine with AVX2 but no AVX-512 does (tools/avx2.sh:
# numpy's and OpenBLAS's AVX-512 kernels off), to see what another user's CPU computes.
AS_CPU = $(if $(filter avx2,$(CPU)),bash tools/avx2.sh ,$(if $(CPU),$(error CPU=$(CPU): expected avx2 or nothing),))

.PHONY: help setup demo test test-fast offline bench soak analyze clean campaign

help:
	@echo 'make demo     run the paper'"'"'s two cases through the ROS 2 node graph (main job)'
	@echo '              ARM=four_link: the shipped 4-link example instead (config/four_link)'
	@echo '              ARM=ur5 / ARM=panda: a spatial arm with a free wrist joint, a 3-D'
	@echo '              circle then a 10-s hold (config/ur5, config/panda);'
	@echo '              PLANE="0 0 1": the circle in the plane of that normal'
	@echo '              ARM=DIR: an arm fj arm init wrote (docs/own-arm.md); ARM=file.urdf'
	@echo '              PASSIVE=joint [TIP=link BASE=link]: fj arm init first, into bags/demo/<name>/'
	@echo '              STABILISE=1: internal motion stabilised, both cases'
	@echo '              FAIL=joint3@2.5: all joints driven, joint 3 fails at 2.5 s'
	@echo '              CIRCLES=N REST=S: N revolutions back to back, S s rest between'
	@echo 'make test     run every test (core math, nodes, interfaces, linters), JOBS (3 per 2 cores)'
	@echo '              pytest processes at once; JOBS=1: one'
	@echo 'make test-fast  the tests without DDS or node processes (core math, schemas,'
	@echo '              loop logic, linters), one process per core (JOBS): the edit-run loop'
	@echo '              CPU=avx2 (test, test-fast): numpy and OpenBLAS limited to AVX2, as'
	@echo '              a machine without AVX-512 computes (tools/avx2.sh)'
	@echo 'make setup    only set up: .venv with ROS 2 Jazzy wheels, colcon build'
	@echo 'make offline  offline closed-loop runner (reference table, bags/offline/metrics.json)'
	@echo '              ARM=DIR (or ur5, panda): a spatial arm'"'"'s offline twin, SEEDS (10) seeds;'
	@echo '              ARM=file.urdf PASSIVE=joint [TIP= BASE=]: fj arm init into bags/offline/<name>/'
	@echo 'make bench    benchmarks (figures printed and written to bags/bench/bench.json);'
	@echo '              BENCH="graph echo": only those (bench/run_all.py MODULES)'
	@echo 'make soak     real-time soak, both cases, 5 x 30 s each (bags/soak/soak.json);'
	@echo '              SOAK_ARGS="--runs 2 --seconds 10 --hogs 2 --cases vertical"; "--arm ur5"'
	@echo '              (or panda, or DIR): that spatial arm, judged against its plan'
	@echo 'make analyze BAGS="bags/demo/..."  metrics and plots from recorded bags'
	@echo 'make campaign robustness campaign of the paper'"'"'s arm over the six categories'
	@echo '              (bags/campaigns/paper_six_categories; CAMPAIGN=FILE for another)'

setup:
	@bash tools/setup.sh

demo: setup
	@$(ENV) python tools/demo.py $(if $(VIEW),--view) $(if $(ARM),--arm $(ARM)) $(if $(STABILISE),--stabilise) $(if $(FAIL),--fail $(FAIL)) $(if $(CIRCLES),--circles $(CIRCLES)) $(if $(REST),--rest $(REST)) $(if $(PLANE),--plane-normal $(PLANE)) $(if $(PASSIVE),--passive $(PASSIVE)) $(if $(TIP),--tip $(TIP)) $(if $(BASE),--base $(BASE))

test: setup
	@$(ENV) $(LINT_CACHE) $(AS_CPU)python -m pytest -c pytest.ini $(XDIST)

test-fast: setup
	@$(ENV) $(LINT_CACHE) $(AS_CPU)bash tools/test_fast.sh $(FAST_XDIST)

offline: setup
	@$(ENV) $(if $(ARM),python tools/arm_offline.py $(ARM) --seeds $(or $(SEEDS),10) $(if $(PASSIVE),--passive $(PASSIVE)) $(if $(TIP),--tip $(TIP)) $(if $(BASE),--base $(BASE)),python -m freejoint_core.offline)

bench: setup
	@$(ENV) python bench/run_all.py $(if $(BENCH),--only $(BENCH))

soak: setup
	@$(ENV) python bench/soak.py $(SOAK_ARGS)

analyze: setup
	@$(ENV) python -m freejoint_tools.analyze $(BAGS)

campaign: setup
	@$(ENV) python -m freejoint_tools.campaign run $(or $(CAMPAIGN),config/campaigns/paper_six_categories.yaml) --report

clean:
	rm -rf build install log .stamps
