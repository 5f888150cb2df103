# Thin wrappers around scripts/: each target sets up whatever is missing first.
.PHONY: setup test demo bench clean

setup:
	bash scripts/setup.sh

# The test command: every library and node test in one pytest run.
test:
	bash scripts/test.sh

# The main job: a short default scenario through the whole ROS node graph (Singapore, paper rate
# 10 requests per 30 s, 600 s simulated, exact MWIS), recorded to MCAP + Rerun, then analysed.
demo:
	bash scripts/run_fleet.sh --duration 600 --rate 10 --backend exact

clean:
	rm -rf build install log
