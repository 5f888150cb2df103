# Thin wrappers around scripts/: each target sets up whatever is missing first.
.PHONY: setup test demo bench clean

setup:
	bash scripts/setup.sh

test:
	bash scripts/test.sh

clean:
	rm -rf build install log
