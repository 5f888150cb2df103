# Thin wrappers around scripts/: each target sets up whatever is missing first.
.PHONY: setup test test-fast demo bench clean study

setup:
	bash scripts/setup.sh

# The test command: every library and node test in one pytest run.
test:
	bash scripts/test.sh

# The development loop: the library tests only (no ROS graph, no node, no subprocess run of the
# graph, nothing marked slow); `make test-fast ARGS=--lf` reruns what failed last.
test-fast:
	bash scripts/test.sh -m "not ros and not slow" src/uam_planner/test src/uam_solvers/test src/uam_sim/test test/test_layering.py test/test_examples.py $(ARGS)

# The main job: a short default scenario through the whole ROS node graph (Singapore, paper rate
# 10 requests per 30 s, 600 s simulated, exact MWIS), recorded to MCAP + Rerun, then analysed.
# DEMO_ARGS: more options for run_fleet.sh (a later option wins), e.g. DEMO_ARGS="--duration 60".
DEMO_ARGS ?=
demo:
	bash scripts/run_fleet.sh --duration 600 --rate 10 --backend exact $(DEMO_ARGS)

# Both studies from scratch (hours on 2 cores; BENCHMARKS.md has the wall times): the paper's
# study and the capacity study, each resumable.
study: setup
	bash -c 'source scripts/env.sh && python -m uam_sim.experiment --config config/experiment.yaml --out results/study --workers 2 && python -m uam_sim.capacity_study --config config/capacity-study.yaml --out results/capacity --workers 2'

clean:
	rm -rf build install log
