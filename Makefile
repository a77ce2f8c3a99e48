# The verbs a person types. Each target sets up what it needs itself.
VENV   := .venv
PY     := $(VENV)/bin/python
OUT    := out
EXAMPLE := examples/robot_arm.py

.PHONY: demo test bench bench-acados bench-scaling campaign acados-env generate firmware firmware-report clean setup help

help:
	@echo "make demo      generate, build and run the robot-arm closed loop (DOPUS M=1 vs full RTI); plots in $(OUT)/robot_arm"
	@echo "make test      run the test suite"
	@echo "make bench     run the benchmarks (tables on stdout, JSON in bench/results)"
	@echo "make bench-acados  time our solver against acados on the robot arm (one process, interleaved)"
	@echo "make bench-scaling time per iteration against N = 20, 40, 80, 160 (robot arm), fitted exponent"
	@echo "make campaign  Monte Carlo campaign on the robot arm (CAMPAIGN_RUNS=1000 runs, dask over all cores); $(OUT)/campaign"
	@echo "make generate  regenerate the checked-in generated/ folders"
	@echo "make firmware  build the static library of generated/robot_arm with make only"
	@echo "make firmware-report  run the robot arm on emulated Cortex-M7 (double, float) and M4F (float) cores (QEMU): sizes, instructions, accuracy"
	@echo "make clean     remove build products and outputs"

setup:
	@bash scripts/bootstrap.sh

demo: setup
	mkdir -p $(OUT)/robot_arm/gauss-newton
	$(VENV)/bin/dopus-gen sil $(EXAMPLE) --M 1 --compare full --duration 3.0 \
	    --json $(OUT)/robot_arm/sil.json --plot-dir $(OUT)/robot_arm
	$(VENV)/bin/dopus-gen sil $(EXAMPLE) --M 1 --compare full --duration 3.0 --hessian gauss-newton \
	    --json $(OUT)/robot_arm/gauss-newton/sil.json --plot-dir $(OUT)/robot_arm/gauss-newton
	$(VENV)/bin/dopus-gen converge $(EXAMPLE) --M full,5,1,0 --iters 40 --start warm --lm 0 --cost-hessian stored \
	    --json $(OUT)/robot_arm/converge_stored.json --plot $(OUT)/robot_arm/converge_stored.png
	$(VENV)/bin/dopus-gen converge $(EXAMPLE) --M full,5,1,0 --iters 40 --start warm --lm 0 --cost-hessian fresh \
	    --json $(OUT)/robot_arm/converge_fresh.json --plot $(OUT)/robot_arm/converge_fresh.png
	@echo "plots and JSON in $(abspath $(OUT))/robot_arm (Gauss-Newton runs in gauss-newton/)"

# TEST_JOBS pytest processes (pytest-xdist), each test file whole on one of them so the
# module fixtures (a firmware report, sanitizer builds) are built once; TEST_JOBS=0: one process
TEST_JOBS ?= 2

test: setup
	-@bash scripts/setup_firmware.sh
	$(PY) -m pytest -q -n $(TEST_JOBS) --dist loadfile

bench: setup
	$(PY) bench/runtime_bench.py
	$(PY) bench/qp_bench.py

acados-env:
	@bash scripts/setup_acados.sh >/dev/null

bench-acados: setup acados-env
	$(VENV)/bin/dopus-gen bench $(EXAMPLE) --M 1,5,full --against acados --work build/acados \
	    --json bench/results/bench_robot_arm.json --plot bench/results/bench_robot_arm.png

bench-scaling: setup
	$(VENV)/bin/dopus-gen bench $(EXAMPLE) --scaling 20,40,80,160 \
	    --json bench/results/bench_scaling.json --plot bench/results/bench_scaling.png

CAMPAIGN_RUNS ?= 1000

# Resumable: run it again after an interruption and only the missing runs are computed.
campaign: setup
	mkdir -p $(OUT)/campaign
	$(VENV)/bin/dopus-gen campaign $(EXAMPLE) --runs $(CAMPAIGN_RUNS) --out $(OUT)/campaign/robot_arm.jsonl \
	    --json $(OUT)/campaign/robot_arm.json --plot-dir $(OUT)/campaign

generate: setup
	$(VENV)/bin/dopus-gen generate examples/robot_arm.py -o generated/robot_arm
	$(VENV)/bin/dopus-gen generate examples/unicycle.py -o generated/unicycle

firmware:
	$(MAKE) -C generated/robot_arm

firmware-report: setup
	@bash scripts/setup_firmware.sh
	$(VENV)/bin/dopus-gen firmware-report $(EXAMPLE) -o $(OUT)/firmware --target m7-double,m7-float,m4f-float

clean:
	rm -rf $(OUT) build .pytest_cache
	find . -name __pycache__ -type d -prune -exec rm -rf {} +
